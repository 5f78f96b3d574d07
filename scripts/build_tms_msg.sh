#!/usr/bin/env bash
# Generates and installs the tms_msg interfaces with rosidl + CMake into the venv prefix, so
# `from tms_msg.action import Subtask` works with no further environment (rclpy's bootstrapper
# adds <venv>/lib to LD_LIBRARY_PATH).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
BUILD="$ROOT/build/tms_msg"
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
export PATH="$VENV/bin:$PATH"
export CMAKE_PREFIX_PATH="$VENV"
export AMENT_PREFIX_PATH="$VENV"
export PYTHONPATH="$SITE"
rm -rf "$BUILD"
mkdir -p "$BUILD"
cmake -S tms_msg -B "$BUILD" \
  -DCMAKE_INSTALL_PREFIX="$VENV" \
  -DCMAKE_BUILD_TYPE=Release \
  -DBUILD_TESTING=OFF \
  -DPython3_EXECUTABLE="$VENV/bin/python" \
  -DPYTHON_EXECUTABLE="$VENV/bin/python" \
  -DPYTHON_INSTALL_DIR="lib/python3.11/site-packages" \
  > "$BUILD/configure.log" 2>&1 || { tail -40 "$BUILD/configure.log"; echo "tms_msg: CMake configure failed, full log: $BUILD/configure.log" >&2; exit 1; }
cmake --build "$BUILD" -j"$(nproc)" > "$BUILD/build.log" 2>&1 || { tail -40 "$BUILD/build.log"; echo "tms_msg: build failed, full log: $BUILD/build.log" >&2; exit 1; }
cmake --install "$BUILD" > "$BUILD/install.log" 2>&1 || { tail -20 "$BUILD/install.log"; exit 1; }
"$VENV/bin/python" -c 'from tms_msg.msg import SubtaskOutcome, JointCmd' \
  || { echo "tms_msg: installed but cannot be imported from $VENV" >&2; exit 1; }
echo "tms_msg: built and installed into $VENV"
