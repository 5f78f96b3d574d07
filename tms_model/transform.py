"""Rigid transforms in ROS conventions: translation [m] and unit quaternion (x, y, z, w), URDF roll-pitch-yaw.

What ``/tf`` carries, without ROS: a :class:`Transform` maps points of a child frame into its parent,
``p_parent = R p_child + t``, and composes as ``parent_T_child = parent_T_mid * mid_T_child``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Transform", "quaternion_from_axis_angle", "quaternion_from_rpy", "quaternion_multiply"]


def quaternion_multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``a * b`` of quaternions (x, y, z, w): rotate by ``b`` first, then by ``a``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quaternion_from_axis_angle(axis: Sequence[float], angle: float) -> tuple[float, float, float, float]:
    """Rotation by ``angle`` [rad] about the unit vector ``axis``."""
    n = math.sqrt(sum(float(c) * float(c) for c in axis))
    if not n > 0.0:
        raise ValueError(f"rotation axis must be non-zero, got {list(axis)}")
    s = math.sin(0.5 * angle) / n
    return float(axis[0]) * s, float(axis[1]) * s, float(axis[2]) * s, math.cos(0.5 * angle)


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """URDF ``origin rpy``: roll about x, then pitch about y, then yaw about z, all about the fixed axes."""
    qx = quaternion_from_axis_angle((1.0, 0.0, 0.0), roll)
    qy = quaternion_from_axis_angle((0.0, 1.0, 0.0), pitch)
    qz = quaternion_from_axis_angle((0.0, 0.0, 1.0), yaw)
    return quaternion_multiply(qz, quaternion_multiply(qy, qx))


@dataclass(frozen=True)
class Transform:
    """``parent_T_child``: translation (x, y, z) [m] and rotation quaternion (x, y, z, w)."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    @staticmethod
    def from_xyz_rpy(xyz: Sequence[float], rpy: Sequence[float]) -> Transform:
        """A URDF ``<origin xyz rpy>``."""
        return Transform(tuple(float(v) for v in xyz), quaternion_from_rpy(*rpy))  # type: ignore[arg-type]

    @staticmethod
    def from_yaw(x: float, y: float, z: float, yaw: float) -> Transform:
        """A planar pose: position and heading ``yaw`` [rad] about z."""
        return Transform((float(x), float(y), float(z)), quaternion_from_axis_angle((0.0, 0.0, 1.0), yaw))

    def matrix(self) -> np.ndarray:
        """The 3x3 rotation matrix."""
        x, y, z, w = self.rotation
        return np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])

    def apply(self, point: Sequence[float]) -> np.ndarray:
        """A point of the child frame in the parent frame."""
        return self.matrix() @ np.asarray(point, dtype=float) + np.asarray(self.translation)

    def __mul__(self, other: Transform) -> Transform:
        t = self.apply(other.translation)
        return Transform((float(t[0]), float(t[1]), float(t[2])), quaternion_multiply(self.rotation, other.rotation))

    def inverse(self) -> Transform:
        x, y, z, w = self.rotation
        inv = Transform((0.0, 0.0, 0.0), (-x, -y, -z, w))
        t = inv.apply(self.translation)
        return Transform((-float(t[0]), -float(t[1]), -float(t[2])), inv.rotation)
