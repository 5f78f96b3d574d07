#!/usr/bin/env bash
# Runs a command in its own network namespace with only loopback (multicast routed to lo), so DDS
# discovery and the udp_multicast CAN buses of tests and demos never leave this host. Falls back to
# running the command directly, saying so, where unprivileged (no `unshare -n`).
# Usage: scripts/isolated.sh CMD [ARGS...]
set -euo pipefail
if [ "${TMS_ISOLATED:-}" = "1" ]; then exec "$@"; fi
setup='ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo'
if command -v unshare >/dev/null && unshare -n true 2>/dev/null; then
  export TMS_ISOLATED=1
  exec unshare -n bash -c "$setup && exec \"\$@\"" isolated "$@"
fi
echo "[isolated] no network namespace available (needs root and unshare); running on the host network" >&2
exec "$@"
