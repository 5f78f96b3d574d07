"""Planar geometry shared by every package: angle wrap, yaw <-> quaternion, planar poses.

Quaternions are (x, y, z, w) as in ROS messages; the functions take either a sequence in that order or
any object with ``x, y, z, w`` attributes (``geometry_msgs/Quaternion``), so no caller converts first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

__all__ = ["Pose2D", "QuaternionLike", "quaternion_from_yaw", "wrap_angle", "yaw_from_quaternion", "yaw_from_wxyz"]

TWO_PI = 2.0 * math.pi


class QuaternionLike(Protocol):
    x: float
    y: float
    z: float
    w: float


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi] (IEEE remainder: exact, no sin/cos round trip)."""
    return math.remainder(a, TWO_PI)


def _xyzw(q: QuaternionLike | Sequence[float] | np.ndarray) -> tuple[float, float, float, float]:
    if hasattr(q, "w"):
        return float(q.x), float(q.y), float(q.z), float(q.w)  # type: ignore[union-attr]
    seq: Any = q
    if len(seq) != 4:
        raise ValueError(f"quaternion must have 4 components (x, y, z, w), got {len(seq)}: {q!r}")
    return float(seq[0]), float(seq[1]), float(seq[2]), float(seq[3])


def yaw_from_quaternion(q: QuaternionLike | Sequence[float] | np.ndarray) -> float:
    """Yaw (rotation about z, ZYX convention) of a quaternion (x, y, z, w) or message; roll/pitch ignored."""
    x, y, z, w = _xyzw(q)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_from_wxyz(q: Sequence[float] | np.ndarray) -> float:
    """Yaw of a scalar-first quaternion (w, x, y, z), the order MuJoCo and pinocchio's coeffs use."""
    return yaw_from_quaternion((q[1], q[2], q[3], q[0]))


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a pure rotation ``yaw`` [rad] about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)


@dataclass(frozen=True)
class Pose2D:
    """A pose on the (flat) site: position [m] in map, heading ``yaw`` [rad] CCW from map x."""

    x: float
    y: float
    yaw: float
    z: float = 0.0

    def to_map(self, local: np.ndarray) -> np.ndarray:
        """Points ``(N, 3)`` (or one ``(3,)``) from this pose's frame to map."""
        p = np.asarray(local, dtype=float)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        out = np.empty_like(p)
        out[..., 0] = self.x + c * p[..., 0] - s * p[..., 1]
        out[..., 1] = self.y + s * p[..., 0] + c * p[..., 1]
        out[..., 2] = self.z + p[..., 2]
        return out

    def from_map(self, world: np.ndarray) -> np.ndarray:
        """Points ``(N, 3)`` (or one ``(3,)``) from map to this pose's frame."""
        p = np.asarray(world, dtype=float)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = p[..., 0] - self.x, p[..., 1] - self.y
        out = np.empty_like(p)
        out[..., 0] = c * dx + s * dy
        out[..., 1] = -s * dx + c * dy
        out[..., 2] = p[..., 2] - self.z
        return out
