#!/usr/bin/env bash
# Creates .venv, installs ROS 2 Jazzy from PyPI wheels, builds the interface packages (tms_msg and the
# peers' packages; scripts/build_interfaces.sh) with rosidl + CMake into the venv prefix, installs this
# project editable and registers its nodes in the ament index.
# Each step leaves a stamp in .venv/.stamps so a second run with nothing changed does nothing.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
VENV="$ROOT/.venv"
STAMPS="$VENV/.stamps"
PY=${PYTHON:-python3.11}

# One bootstrap at a time (parallel `make` targets or shells share the venv).
exec 9>"$ROOT/.bootstrap.lock"
flock 9

say() { printf '[bootstrap] %s\n' "$*"; }
fail() { printf '[bootstrap] ERROR: %s\n' "$*" >&2; exit 1; }

command -v "$PY" >/dev/null || fail "$PY not found: CPython 3.11 is required (the ROS 2 Jazzy wheels are cp311 only)"
command -v cmake >/dev/null || fail "cmake not found: install it (Debian: apt-get install cmake g++ make)"
command -v g++ >/dev/null || fail "g++ not found: install it (Debian: apt-get install g++)"

# A stamp is fresh when it exists and is newer than every file it depends on.
fresh() { local stamp=$1; shift; [ -f "$stamp" ] || return 1; [ -z "$(find "$@" -newer "$stamp" -print -quit 2>/dev/null)" ]; }

if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV with $PY"
  "$PY" -m venv "$VENV"
fi
mkdir -p "$STAMPS"
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)

if ! fresh "$STAMPS/deps" constraints.txt requirements-ros.txt pyproject.toml; then
  say "installing pinned dependencies (ROS 2 Jazzy wheels, python libraries); first run takes a few minutes"
  "${PIP[@]}" install -c constraints.txt pip setuptools wheel
  "${PIP[@]}" install -c constraints.txt -r requirements-ros.txt
  touch "$STAMPS/deps"
fi

if ! fresh "$STAMPS/cmake-fix" "$STAMPS/deps" scripts/fix_ros_cmake.py; then
  say "pointing the ROS wheels' exported CMake files at this venv"
  "$VENV/bin/python" scripts/fix_ros_cmake.py "$VENV"
  touch "$STAMPS/cmake-fix"
fi

# Interface packages in dependency order, each with its own stamp: a package is rebuilt when its files,
# the build script or any package before it in the list changed (a later package may use an earlier one).
PREV_STAMP="$STAMPS/cmake-fix"
for PKG in $(bash scripts/build_interfaces.sh --list); do
  if ! fresh "$STAMPS/iface-$PKG" "$PKG" scripts/build_interfaces.sh "$PREV_STAMP"; then
    say "building $PKG (rosidl + CMake) into $VENV"
    bash scripts/build_interfaces.sh "$PKG"
    touch "$STAMPS/iface-$PKG"
  fi
  PREV_STAMP="$STAMPS/iface-$PKG"
done

# The editable install maps the top-level packages it found at install time: a new package needs a reinstall.
PACKAGES=$(find . -maxdepth 2 -name __init__.py -path './*/__init__.py' -not -path './.venv/*' | sort | tr '\n' ' ')
if ! fresh "$STAMPS/project" pyproject.toml constraints.txt "$STAMPS/deps" \
    || [ "$(cat "$STAMPS/project.packages" 2>/dev/null)" != "$PACKAGES" ]; then
  say "installing the project (editable)"
  "${PIP[@]}" install -c constraints.txt --no-build-isolation -e ".[test]"
  printf '%s' "$PACKAGES" > "$STAMPS/project.packages"
  touch "$STAMPS/project"
fi

if ! fresh "$STAMPS/ament" pyproject.toml scripts/register_ament.py "$STAMPS/project"; then
  say "registering nodes in the ament index"
  "$VENV/bin/python" scripts/register_ament.py "$VENV"
  touch "$STAMPS/ament"
fi

# The panel's 3-D view (tms_ur/web3d): three.js and urdf-loader from the npm registry at the versions of the
# committed package-lock.json; the panel serves them from node_modules (nothing fetched at run time).
if ! fresh "$STAMPS/web3d" tms_ur/web3d/package.json tms_ur/web3d/package-lock.json \
    || [ ! -d tms_ur/web3d/node_modules/three ]; then
  command -v npm >/dev/null || fail "npm not found: the panel's 3-D view needs Node.js and npm (Debian: apt-get install nodejs npm)"
  say "installing the 3-D view's JavaScript packages (npm ci in tms_ur/web3d)"
  (cd tms_ur/web3d && npm ci --no-audit --no-fund --ignore-scripts) || fail "npm ci in tms_ur/web3d failed"
  touch "$STAMPS/web3d"
fi

if [ ! -x /usr/bin/chromium ]; then
  # Browser tests of the web panel (tms_ur) need Debian's chromium; failure here is reported, and the
  # browser tests then skip naming the missing /usr/bin/chromium.
  bash scripts/install_browser.sh || say "WARNING: chromium could not be installed; web panel browser tests will skip"
fi
