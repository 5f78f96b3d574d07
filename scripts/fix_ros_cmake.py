"""Point the ROS 2 wheels' exported CMake targets at this venv's Python and numpy headers.

The ros-jazzy wheels were built on a manylinux host whose Python lived in /opt/python/cp311-cp311;
their exported `*Export.cmake` files name that host's include directories, and CMake refuses to
configure a package (tms_msg) that depends on them while those paths do not exist. We rewrite them
to this interpreter's include directory and numpy's, inside the venv only.

Usage: python scripts/fix_ros_cmake.py <venv>
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_HOST_PREFIX = "/opt/python/cp311-cp311"
_PATTERN = re.compile(re.escape(BUILD_HOST_PREFIX) + r"[^;\"\s]*")


def replacement_for(path: str) -> str:
    """Map one build-host path to its equivalent on this machine."""
    if path.endswith("/numpy/_core/include") or path.endswith("/numpy/core/include"):
        return numpy.get_include()
    if path.endswith("include/python3.11"):
        return sysconfig.get_paths()["include"]
    raise SystemExit(f"fix_ros_cmake: no known replacement for build-host path {path!r}")


def main(venv: str) -> int:
    changed = 0
    for cmake_file in Path(venv, "share").rglob("*.cmake"):
        text = cmake_file.read_text()
        if BUILD_HOST_PREFIX not in text:
            continue
        cmake_file.write_text(_PATTERN.sub(lambda m: replacement_for(m.group(0)), text))
        changed += 1
    print(f"fix_ros_cmake: rewrote {changed} exported CMake files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
