"""tms_rc.excavator.segments: an arm_controller/move goal's segments -> controller targets (no ROS)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tms_model.excavator.targets import CartesianTarget, JointTarget
from tms_rc.excavator.segments import CARTESIAN, JOINT, targets_from_segments


def seg(kind=JOINT, label="approach", q=(0.0, -0.8, 1.3, 1.2), p=(5.0, 0.0, 0.5), theta_w=1.0, scale=0.0, via=False,
        measured=False):
    return SimpleNamespace(
        kind=kind,
        label=label,
        joint_positions=list(q),
        position=SimpleNamespace(x=p[0], y=p[1], z=p[2]),
        theta_w=theta_w,
        speed_scale=scale,
        via=via,
        measured=measured,
    )


def test_joint_and_cartesian_segments_become_targets_in_order():
    j, c = targets_from_segments([seg(via=True), seg(CARTESIAN, "penetrate", scale=2.0, measured=True)])
    assert isinstance(j, JointTarget) and j.via and j.speed_scale == 1.0  # 0 = the configured speeds
    assert not j.measured and c.measured
    np.testing.assert_allclose(j.q, [0.0, -0.8, 1.3, 1.2])
    assert isinstance(c, CartesianTarget) and c.label == "penetrate" and not c.via and c.speed_scale == 2.0
    np.testing.assert_allclose(c.position, [5.0, 0.0, 0.5])


@pytest.mark.parametrize("segments,message", [
    ([], "empty goal: no segments"),
    ([seg(), seg(q=(0.0, 1.0, 2.0))], "segment 2 (approach): joint_positions must be 4 finite angles"),
    ([seg(q=(0.0, math.nan, 1.0, 1.0))], "segment 1 (approach): joint_positions must be 4 finite angles"),
    ([seg(CARTESIAN, "drag", p=(5.0, math.inf, 0.0))], "segment 1 (drag): position / theta_w must be finite"),
    ([seg(CARTESIAN, "", theta_w=math.nan)], "segment 1 (unlabelled): position / theta_w must be finite"),
    ([seg(kind=7)], "segment 1 (approach): unknown kind 7"),
    ([seg(scale=-1.0)], "segment 1 (approach): speed_scale -1.0 is outside [0, 10]"),
    ([seg(scale=11.0)], "speed_scale 11.0 is outside"),
    ([seg(scale=math.nan)], "speed_scale nan is outside"),
])
def test_a_malformed_segment_names_itself(segments, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        targets_from_segments(segments)


def test_kind_constants_match_the_message():
    from tms_msg.msg import Zx200ArmSegment

    assert (Zx200ArmSegment.JOINT, Zx200ArmSegment.CARTESIAN) == (JOINT, CARTESIAN)
