"""Planar poses and the frame changes the sensing processors need.

Both machines stand on (nearly) flat ground, so a pose is ``(x, y, z, yaw)`` in the map frame. The
ZX200 targets are written in the ZX200 base frame (tms_msg/Zx200PositionWithAngle says so); vessel
points arrive in the vessel frame of the IC120.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Pose2D", "yaw_from_quaternion", "wrap_angle"]


def wrap_angle(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return math.atan2(math.sin(a), math.cos(a))


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Yaw (rotation about z) of a quaternion, ignoring roll and pitch."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


@dataclass(frozen=True)
class Pose2D:
    """A machine pose on the site: position [m] in map, heading ``yaw`` [rad] CCW from map x."""

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
