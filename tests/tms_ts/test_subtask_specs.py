"""Subtask record -> planning goal data (tms_ts.subtask_specs), no ROS."""

from __future__ import annotations

import pytest

from tms_ts.errors import SubtaskRecordError
from tms_ts.subtask_specs import build_change_pose


def test_change_pose_pass_through_is_an_optional_record_flag_and_garbage_names_the_field() -> None:
    doc = {"position_with_angle": 1, "x": 1.0, "y": 6.0, "z": 2.7, "theta_w": 1.48}
    assert build_change_pose(doc, "target_release_pose")["pass_through"] is False
    assert build_change_pose({**doc, "pass_through": 1}, "target_release_pose")["pass_through"] is True
    assert build_change_pose({**doc, "pass_through": False}, "target_release_pose")["pass_through"] is False
    with pytest.raises(SubtaskRecordError, match=r"target_release_pose.*pass_through.*'yes'"):
        build_change_pose({**doc, "pass_through": "yes"}, "target_release_pose")
