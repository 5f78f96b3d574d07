"""Subtask record -> planning goal data (tms_ts.subtask_specs), no ROS."""

from __future__ import annotations

import pytest

from tms_ts.errors import SubtaskRecordError
from tms_ts.subtask_specs import build_change_pose


def test_change_pose_pass_through_is_an_optional_record_flag_and_garbage_names_the_field() -> None:
    doc = {"position_with_angle": 1, "x": 1.0, "y": 6.0, "z": 2.7, "theta_w": 1.48}
    assert build_change_pose(doc, "target_release_pose").pass_through is False
    assert build_change_pose({**doc, "pass_through": 1}, "target_release_pose").pass_through is True
    assert build_change_pose({**doc, "pass_through": False}, "target_release_pose").pass_through is False
    with pytest.raises(SubtaskRecordError, match=r"target_release_pose.*pass_through.*'yes'"):
        build_change_pose({**doc, "pass_through": "yes"}, "target_release_pose")


def test_change_pose_theta_w_tolerance_is_optional_non_negative_and_not_for_joint_targets() -> None:
    doc = {"position_with_angle": 1, "x": 5.0, "y": 1.0, "z": 0.5, "theta_w": 1.1}
    assert build_change_pose(doc, "target_excavate_approach_pose").theta_w_tolerance == 0.0
    assert build_change_pose({**doc, "theta_w_tolerance": 0.5}, "approach").theta_w_tolerance == 0.5
    with pytest.raises(SubtaskRecordError, match=r"approach.*theta_w_tolerance.*>= 0"):
        build_change_pose({**doc, "theta_w_tolerance": -0.1}, "approach")
    with pytest.raises(SubtaskRecordError, match=r"approach.*theta_w_tolerance.*finite number"):
        build_change_pose({**doc, "theta_w_tolerance": "wide"}, "approach")
    joints = {"trajectory": 1, "swing_joint": 0.0, "boom_joint": -0.8, "arm_joint": 1.3, "bucket_joint": 1.2}
    with pytest.raises(SubtaskRecordError, match=r"pending.*theta_w_tolerance.*not joints"):
        build_change_pose({**joints, "theta_w_tolerance": 0.2}, "pending")
