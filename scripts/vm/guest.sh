#!/bin/sh
# Runs INSIDE the VM (as root, over the host's filesystem; the repo is an overlay, writable in the guest only).
# Usage: guest.sh OUTDIR   -- OUTDIR (shared read/write with the host) holds job.env and pytest_args
# written by run_vcan_vm.py; this script writes progress, pytest.log and junit.xml there.
# Brings up loopback (DDS discovery on LOCALHOST) and the vcan interface, then runs pytest on socketcan.
# Exit codes: pytest's (0 passed, 1 failed, ...), or 90 module load failed, 91 interface setup failed,
# 92 loopback failed, 93 bad job.
OUT=$1
[ -d "$OUT" ] || { echo "guest.sh: no output directory $OUT" >&2; exit 93; }
progress() { echo "$1 $(cut -d' ' -f1 /proc/uptime) ${2:-}" >> "$OUT/progress"; }
fail() { progress fail "$2"; echo "guest: $2" >&2; exit "$1"; }
progress guest-started
. "$OUT/job.env" || fail 93 "cannot read $OUT/job.env"
cd "$REPO" || fail 93 "no repository at $REPO"

ip link set lo up 2>"$OUT/setup.err" || fail 92 "loopback up failed: $(cat "$OUT/setup.err")"
modprobe "$MODULE" 2>"$OUT/setup.err" || fail 90 "modprobe $MODULE failed: $(tr '\n' ' ' < "$OUT/setup.err")"
{ ip link add dev "$IFACE" type vcan && ip link set up "$IFACE"; } 2>"$OUT/setup.err" \
  || fail 91 "creating $IFACE failed: $(tr '\n' ' ' < "$OUT/setup.err")"
progress interface-up "$(ip -brief link show "$IFACE" | tr -s ' ')"

# Writable places for tools that write under $HOME (ROS logs) or next to the code (bytecode).
export HOME=/tmp/vmhome ROS_LOG_DIR=/tmp/vmhome/roslog PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST AMENT_PREFIX_PATH="$REPO/.venv"
export TMS_CAN_TEST_BACKEND=socketcan TMS_CAN_TEST_CHANNEL="$IFACE" TMS_IN_VCAN_VM=1 TMS_TEST_TIME_SCALE="$TIME_SCALE"
mkdir -p "$HOME"

set --
while IFS= read -r arg; do set -- "$@" "$arg"; done < "$OUT/pytest_args"
progress tests-started
"$REPO/.venv/bin/python" -m pytest "$@" -o junit_family=xunit1 --junitxml="$OUT/junit.xml" > "$OUT/pytest.log" 2>&1
rc=$?
progress tests-done "$rc"
exit "$rc"
