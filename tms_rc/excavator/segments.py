"""The segments of one ``arm_controller/move`` goal (tms_msg/msg/Zx200ArmSegment) as controller targets.

Pure Python (no ROS): the node hands over the goal's segment messages, or anything with the same fields.
A malformed segment makes the whole goal invalid before any motion; the error names the segment
(``segment 2 (penetrate): ...``), so a planner bug is found from the controller's answer alone.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from tms_model.excavator.kinematics import JOINTS
from tms_model.excavator.targets import CartesianTarget, JointTarget

__all__ = ["JOINT", "CARTESIAN", "MAX_SPEED_SCALE", "targets_from_segments"]

#: Zx200ArmSegment.kind values (tms_msg/msg/Zx200ArmSegment.msg)
JOINT = 0
CARTESIAN = 1
#: a segment's speed_scale multiplies the configured tip / joint speeds (joint speeds stay capped at their
#: limits); anything above this is a garbled goal, not a plan
MAX_SPEED_SCALE = 10.0


def targets_from_segments(segments: Iterable[Any]) -> list[JointTarget | CartesianTarget]:
    """Segments -> targets; ``ValueError`` naming the first malformed segment, or an empty goal."""
    out: list[JointTarget | CartesianTarget] = []
    for k, seg in enumerate(segments):
        name = f"segment {k + 1} ({seg.label or 'unlabelled'})"
        if not (0.0 <= seg.speed_scale <= MAX_SPEED_SCALE):  # also NaN
            raise ValueError(f"{name}: speed_scale {seg.speed_scale} is outside [0, {MAX_SPEED_SCALE:g}]")
        scale = seg.speed_scale or 1.0
        if seg.kind == JOINT:
            q = np.array(seg.joint_positions, dtype=float)
            if q.shape != (len(JOINTS),) or not np.all(np.isfinite(q)):
                raise ValueError(f"{name}: joint_positions must be {len(JOINTS)} finite angles "
                                 f"({', '.join(JOINTS)}), got {list(seg.joint_positions)}")
            out.append(JointTarget(q, seg.label, speed_scale=scale, via=bool(seg.via), measured=bool(seg.measured)))
        elif seg.kind == CARTESIAN:
            p = np.array([seg.position.x, seg.position.y, seg.position.z], dtype=float)
            if not (np.all(np.isfinite(p)) and math.isfinite(seg.theta_w)):
                raise ValueError(f"{name}: position / theta_w must be finite")
            out.append(CartesianTarget(p, float(seg.theta_w), seg.label, speed_scale=scale, via=bool(seg.via),
                                       measured=bool(seg.measured)))
        else:
            raise ValueError(f"{name}: unknown kind {seg.kind} (JOINT={JOINT}, CARTESIAN={CARTESIAN})")
    if not out:
        raise ValueError("empty goal: no segments")
    return out
