"""What the converter produces: frames to send and the contents of the ROS messages it publishes.

Plain values shared by :mod:`com3_can.bridge_core` and the profiles (:mod:`com3_can.profiles`), kept apart from
both so that neither imports the other for them. :func:`finite` is the number check every command path uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from com3_can.errors import Com3CommandError

__all__ = ["Tx", "JointStateOut", "OdomOut", "ImuOut", "FixOut", "DiagSnapshot", "finite"]


@dataclass(frozen=True)
class Tx:
    """One frame to put on the bus."""

    name: str
    arbitration_id: int
    data: bytes


@dataclass(frozen=True)
class JointStateOut:
    """Content of a sensor_msgs/JointState (empty ``position`` means velocities only)."""

    name: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]


@dataclass(frozen=True)
class OdomOut:
    """Content of a nav_msgs/Odometry: planar pose in ``frame_id`` and body twist."""

    x: float
    y: float
    z: float
    yaw: float
    v: float
    yaw_rate: float
    frame_id: str = "odom"


@dataclass(frozen=True)
class ImuOut:
    """Orientation (roll, pitch, yaw [rad], ROS conventions) and yaw rate if the frame carries it."""

    roll: float
    pitch: float
    yaw: float
    yaw_rate: float | None


@dataclass(frozen=True)
class FixOut:
    """Content of a sensor_msgs/NavSatFix (status in NavSatStatus numbering: -1 no fix .. 2 GBAS)."""

    latitude: float
    longitude: float
    altitude: float
    status: int
    horizontal_accuracy: float | None


@dataclass(frozen=True)
class DiagSnapshot:
    """One diagnostic status: level (0 OK, 1 WARN, 2 ERROR), message and key/values."""

    level: int
    message: str
    values: tuple[tuple[str, str], ...]


def finite(topic: str, what: str, value: float) -> float:
    """``value`` as a finite float; else :class:`Com3CommandError` naming ``topic`` and ``what``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise Com3CommandError(f"{topic}: {what}: expected a number, got {value!r}") from None
    if not math.isfinite(v):
        raise Com3CommandError(f"{topic}: {what}: value {v} is not finite")
    return v
