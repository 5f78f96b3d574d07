"""A scripted dig-load-dump: joint targets and a dead-time-aware joint servo.

Used by the tests and the benchmark to drive the plant through the soil cycle: the same pose list is
followed either directly on a :class:`~sim_bridge.plant.Plant` or over COM3 CAN (the servo only needs
the measured joint angles and returns velocity commands). Poses assume the IC120 stands at site point
P1 (vessel centre 6.5 m to the left of the ZX200 swing axis) and the mound ahead of the ZX200.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

__all__ = ["DIG_CYCLE", "servo_velocity", "pose_reached"]

#: One dig-load cycle: each step is a set of joint targets [rad], reached before the next starts.
DIG_CYCLE: tuple[dict[str, float], ...] = (
    {"swing_joint": 0.0, "boom_joint": -0.6, "arm_joint": 1.3, "bucket_joint": 0.3},  # above the mound
    {"boom_joint": -0.12},  # penetrate
    {"arm_joint": 2.3, "bucket_joint": 2.2},  # crowd and curl: the edge sweeps through the soil
    {"boom_joint": -1.0},  # lift
    {"swing_joint": math.pi / 2, "arm_joint": 1.9},  # over the vessel
    {"bucket_joint": -0.6},  # open: the load falls into the vessel
)

#: P gains [1/s] low enough for each joint's dead time (K * T_dead < ~0.5 keeps the loop well damped).
SERVO_GAIN: dict[str, float] = {"swing_joint": 0.4, "boom_joint": 0.6, "arm_joint": 0.9, "bucket_joint": 1.2}


def servo_velocity(q: Mapping[str, float], target: Mapping[str, float], v_max: float = 1.0) -> dict[str, float]:
    """Velocity commands driving the joints named in ``target`` towards it (others get 0)."""
    out = {}
    for name, value in q.items():
        if name in target:
            out[name] = max(-v_max, min(v_max, SERVO_GAIN.get(name, 0.5) * (target[name] - value)))
        else:
            out[name] = 0.0
    return out


def pose_reached(q: Mapping[str, float], target: Mapping[str, float], tol: float = 0.03) -> bool:
    return all(abs(q[name] - value) <= tol for name, value in target.items())
