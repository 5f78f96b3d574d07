#!/usr/bin/env bash
# Generates and installs the interface packages with rosidl + CMake into the venv prefix, so
# `from com3_msgs.msg import JointCmd` works with no further environment (rclpy's bootstrapper adds
# <venv>/lib to LD_LIBRARY_PATH).
#
#   scripts/build_interfaces.sh --list   the packages, in build order (one a line)
#   scripts/build_interfaces.sh PKG...   build and install these packages
#
# INTERFACE_PACKAGES is the one list: dependency order (a package after every package it uses).
# The peers' packages keep the peer's package name (none of them is in the ROS wheels); tms_msg holds
# only what has no peer definition.
set -euo pipefail
INTERFACE_PACKAGES=(tf2_msgs com3_msgs nav2_msgs tms_msg_ts tms_msg_rp tms_msg_db tms_msg_ur sensing_msgs tms_msg)

# The import each package must answer after install (one type is enough to prove the generated code loads).
probe() {
  case $1 in
    tf2_msgs) echo 'from tf2_msgs.msg import TFMessage' ;;
    com3_msgs) echo 'from com3_msgs.msg import JointCmd; from com3_msgs.action import SetDumpAngle' ;;
    nav2_msgs) echo 'from nav2_msgs.action import NavigateToPose' ;;
    tms_msg_ts) echo 'from tms_msg_ts.action import LeafNodeBase' ;;
    tms_msg_rp) echo 'from tms_msg_rp.action import TmsRpZx200ChangePose' ;;
    tms_msg_db) echo 'from tms_msg_db.srv import TmsdbGetTask; from tms_msg_db.action import TmsdbTerrainImage' ;;
    tms_msg_ur) echo 'from tms_msg_ur.srv import TmsdbTerrainDBPoseWriteSrv' ;;
    sensing_msgs) echo 'from sensing_msgs.msg import Flgs' ;;
    tms_msg) echo 'from tms_msg.msg import SubtaskOutcome' ;;
    *) echo "build_interfaces: no import probe for $1" >&2; return 1 ;;
  esac
}

if [ "${1:-}" = "--list" ]; then printf '%s\n' "${INTERFACE_PACKAGES[@]}"; exit 0; fi
[ $# -gt 0 ] || { echo "usage: $0 --list | PKG..." >&2; exit 2; }

cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
export PATH="$VENV/bin:$PATH"
export CMAKE_PREFIX_PATH="$VENV"
export AMENT_PREFIX_PATH="$VENV"
export PYTHONPATH="$SITE"

for PKG in "$@"; do
  printf '%s\n' "${INTERFACE_PACKAGES[@]}" | grep -qx "$PKG" \
    || { echo "build_interfaces: '$PKG' is not in INTERFACE_PACKAGES (${INTERFACE_PACKAGES[*]})" >&2; exit 2; }
  [ -f "$PKG/package.xml" ] || { echo "build_interfaces: $ROOT/$PKG/package.xml missing" >&2; exit 1; }
  BUILD="$ROOT/build/$PKG"
  rm -rf "$BUILD"
  mkdir -p "$BUILD"
  cmake -S "$PKG" -B "$BUILD" \
    -DCMAKE_INSTALL_PREFIX="$VENV" \
    -DCMAKE_BUILD_TYPE=Release \
    -DBUILD_TESTING=OFF \
    -DPython3_EXECUTABLE="$VENV/bin/python" \
    -DPYTHON_EXECUTABLE="$VENV/bin/python" \
    -DPYTHON_INSTALL_DIR="lib/python3.11/site-packages" \
    > "$BUILD/configure.log" 2>&1 || { tail -40 "$BUILD/configure.log"; echo "$PKG: CMake configure failed, full log: $BUILD/configure.log" >&2; exit 1; }
  cmake --build "$BUILD" -j"$(nproc)" > "$BUILD/build.log" 2>&1 || { tail -40 "$BUILD/build.log"; echo "$PKG: build failed, full log: $BUILD/build.log" >&2; exit 1; }
  cmake --install "$BUILD" > "$BUILD/install.log" 2>&1 || { tail -20 "$BUILD/install.log"; exit 1; }
  "$VENV/bin/python" -c "$(probe "$PKG")" \
    || { echo "$PKG: installed but cannot be imported from $VENV" >&2; exit 1; }
  echo "$PKG: built and installed into $VENV"
done
