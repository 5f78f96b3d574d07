#!/usr/bin/env bash
# Installs what the SocketCAN VM (scripts/vm/run_vcan_vm.py) needs, idempotently:
#   Debian: linux-image-amd64 (a kernel + its vcan module), qemu-system-x86 (software emulation), busybox-static
#           (virtme-ng's initramfs);  PyPI: virtme-ng (pinned in constraints.txt) into .venv.
# Each piece is skipped when already present, so a second run costs a few milliseconds. Run by `make test`
# (target vm-setup) after scripts/bootstrap.sh.
#
# Never fails the build: where a piece cannot be installed (not root, no apt-get, registry unreachable) it
# says which and goes on; the VM test then skips naming what is missing (it fails instead only when
# TMS_VM_REQUIRED=1 is set). TMS_VM=0 turns the whole thing off (the VM test then skips saying so).
set -uo pipefail
cd "$(dirname "$0")/../.."
VENV="$PWD/.venv"

say() { printf '[vm-setup] %s\n' "$*"; }

if [ "${TMS_VM:-1}" = "0" ]; then
  say "TMS_VM=0: not installing the VM tools"
  exit 0
fi

# One setup at a time (parallel make targets or shells); the lock lives outside the work tree.
exec 8>"${TMPDIR:-/tmp}/tms-vm-setup.lock"
flock 8

# A kernel image under /boot whose modules directory has vcan (the running kernel is not needed).
have_kernel() {
  local img ver
  for img in /boot/vmlinuz-*; do
    [ -e "$img" ] || continue
    ver=${img#/boot/vmlinuz-}
    if compgen -G "/lib/modules/$ver/kernel/drivers/net/can/vcan.ko*" >/dev/null; then
      return 0
    fi
  done
  return 1
}

missing=()
command -v qemu-system-x86_64 >/dev/null || missing+=(qemu-system-x86)
have_kernel || missing+=(linux-image-amd64)
# virtme-ng looks for busybox on PATH and needs a static one (it runs in the initramfs).
if ! { command -v busybox >/dev/null && ! ldd "$(command -v busybox)" >/dev/null 2>&1; }; then
  missing+=(busybox-static)
fi

if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" != "0" ]; then
    say "missing Debian packages: ${missing[*]} (not root: install them with sudo apt-get install ${missing[*]})"
  elif ! command -v apt-get >/dev/null; then
    say "missing packages: ${missing[*]} (no apt-get on this machine: install their equivalents by hand)"
  else
    say "installing Debian packages: ${missing[*]} (first run only; about a minute)"
    export DEBIAN_FRONTEND=noninteractive
    if ! { apt-get update -q >/dev/null && apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null; }; then
      say "apt-get install ${missing[*]} failed; the VM test will name what is missing"
    fi
  fi
fi

if [ -x "$VENV/bin/python" ]; then
  if [ ! -x "$VENV/bin/vng" ]; then
    say "installing virtme-ng into $VENV (pinned in constraints.txt)"
    "$VENV/bin/python" -m pip --disable-pip-version-check -q install -c constraints.txt virtme-ng \
      || say "pip install virtme-ng failed; the VM test will name what is missing"
  fi
else
  say "no $VENV yet (run scripts/bootstrap.sh first); virtme-ng not installed"
fi
exit 0
