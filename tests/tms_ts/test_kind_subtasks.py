"""Which kind serves which subtask names, and the rows beyond the IC120's and ZX200's planning (no ROS)."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from tms_model.fleet import load_named
from tms_model.machines import Joint
from tms_ts.errors import SubtaskRecordError, SubtaskStateError
from tms_ts.plans import SamplePlan
from tms_ts.subtask_specs import KIND_SUBTASKS, SUBTASKS, subtasks_for

TRAVEL = [f"{base}{tail}" for base in ("follow_waypoints", "navigate_anywhere", "navigate_through_poses")
          for tail in ("", "_deg")]
JOINTS = {"swing_joint": 0.1, "boom_joint": -0.4, "arm_joint": 1.3, "bucket_joint": 0.6}


def _names(kind: str) -> set[str]:
    return {s.name for s in subtasks_for(kind)}


def test_every_name_the_original_defines_is_served_by_its_kind() -> None:
    for prefix, kind in (("zx200", "zx200"), ("mst2200", "mst2200vd"), ("mst110cr", "mst110cr"), ("d37pxi", "d37pxi"),
                         ("ic120", "ic120")):
        assert {f"st_{prefix}_{t}" for t in TRAVEL} <= _names(kind), kind
    for prefix, kind in (("mst2200", "mst2200vd"), ("mst110cr", "mst110cr")):
        assert {f"st_{prefix}_release_soil", f"st_{prefix}_swing", f"st_{prefix}_swing_align_to_heading"} <= _names(
            kind
        )
    for m in ("zx200", "zx120"):
        assert {f"st_{m}_sample_{j}" for j in ("swing", "boom", "arm", "bucket")} <= _names(m)
    # the original's trees send the IC120's release to /mst2200: its kind serves that name too
    assert "st_ic120_release_soil" in _names("mst2200vd")
    assert {"subtask_zx200_change_pose", "subtask_zx200_excavate_simple", "subtask_zx200_release_simple"} <= _names(
        "zx200"
    )
    assert _names("ic120") == {f"st_ic120_{t}" for t in TRAVEL} | {"st_ic120_release_soil"}
    assert not any(n.startswith(("st_ic120", "st_mst")) for n in _names("zx200"))
    assert _names("d37pxi") == {f"st_d37pxi_{t}" for t in TRAVEL}  # the original builds no D37PXi release


def test_each_row_belongs_to_a_kind_and_an_unknown_kind_names_the_known_ones() -> None:
    served = set().union(*(_names(k) for k in KIND_SUBTASKS))
    assert served == set(SUBTASKS)
    with pytest.raises(ValueError, match=r"unknown machine kind 'pc200'.*d37pxi.*ic120.*zx200"):
        subtasks_for("pc200")


def test_travel_rows_of_every_machine_share_the_ic120_records_and_actions() -> None:
    ic = SUBTASKS["st_ic120_navigate_anywhere_deg"]
    for prefix in ("zx200", "mst2200", "mst110cr", "d37pxi", "zx120"):
        for tail in TRAVEL:
            row, ref = SUBTASKS[f"st_{prefix}_{tail}"], SUBTASKS[f"st_ic120_{tail}"]
            assert (row.planning_action, row.action_type) == (ref.planning_action, ref.action_type)
    zx = SUBTASKS["st_zx200_navigate_anywhere_deg"]
    goal = zx.goal(zx.build({"x": -5.0, "y": 1.0, "yaw": 90.0}, "zx200_goal"))
    assert goal == ic.goal(ic.build({"x": -5.0, "y": 1.0, "yaw": 90.0}, "r"))
    assert goal.pose.header.frame_id == "map" and goal.pose.pose.orientation.z == pytest.approx(2**-0.5)
    with pytest.raises(SubtaskRecordError, match=r"record 'zx200_goal' field 'yaw': missing"):
        zx.build({"x": 1.0, "y": 2.0}, "zx200_goal")
    fw = SUBTASKS["st_mst110cr_follow_waypoints"]
    with pytest.raises(SubtaskRecordError, match=r"record 'route' field 'y': has 1 elements, x has 2"):
        fw.build({"x": [1.0, 2.0], "y": [0.0], "qx": [0], "qy": [0], "qz": [0], "qw": [1.0]}, "route")


def test_mst_release_soil_calls_dump_up_and_swing_sets_the_swing_angle() -> None:
    from com3_msgs.action import SetSwingAngle
    from com3_msgs.srv import DumpUp

    for prefix in ("mst2200", "mst110cr"):
        rel = SUBTASKS[f"st_{prefix}_release_soil"]
        assert (rel.downstream, rel.planning_action, rel.action_type) == ("service", "vessel_target_pos", DumpUp)
        assert rel.goal(rel.build({"target_angle": 0.9}, "release_angle")) == DumpUp.Request(vessel_angle=0.9)
        assert rel.check(DumpUp.Response(result=True))[0] and not rel.check(DumpUp.Response(result=False))[0]
        with pytest.raises(SubtaskRecordError, match=r"record 'release_angle' field 'target_angle': must be a finite"):
            rel.build({"target_angle": "up"}, "release_angle")
        swing = SUBTASKS[f"st_{prefix}_swing"]
        assert (swing.planning_action, swing.action_type) == ("set_swing_angle", SetSwingAngle)
        assert swing.goal(swing.build({"target_angle": -1.2}, "s")).target_angle == -1.2  # rad, passed through
        with pytest.raises(SubtaskRecordError, match=r"record 's' field 'target_angle': missing"):
            swing.build({}, "s")


def test_swing_alignment_reads_no_record_and_turns_to_the_nearer_of_0_and_pi() -> None:
    row = SUBTASKS["st_mst2200_swing_align_to_heading"]
    assert row.reads_record is False
    plan = row.build({}, "")
    for q, target in ((0.3, 0.0), (-1.5, 0.0), (1.7, math.pi), (-2.9, math.pi), (2 * math.pi + 0.1, 0.0)):
        assert row.resolve(plan, {"swing_joint": q}, None).target_angle == target, q
    with pytest.raises(SubtaskStateError, match=r"no swing_joint on joint_states"):
        row.resolve(plan, {"vessel_joint": 0.0}, None)
    # a carrier whose description has a swing joint of another name: that joint is read
    ic = load_named("ic120")
    swinging = replace(ic, joints=(*ic.joints, Joint("rotate_joint", "body_link", "rotate_link", (0.0, 0.0, 0.0),
                                                     (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), None, None, 0.2, 0.2)))
    assert row.resolve(plan, {"rotate_joint": 3.0, "swing_joint": 0.0}, swinging).target_angle == math.pi


def test_sample_subtasks_move_one_joint_to_its_goal_in_degrees_and_keep_the_others() -> None:
    from tms_msg.action import Zx200ArmMove
    from tms_msg.msg import Zx200ArmSegment
    from tms_msg_rp.msg import TmsRpErrorCodes

    row = SUBTASKS["st_zx200_sample_boom"]
    assert (row.planning_action, row.action_type) == ("arm_controller/move", Zx200ArmMove)
    plan = row.resolve(row.build({"zx200_boom_goal_pos": -30.0}, "sample"), JOINTS, None)
    goal = row.goal(plan)
    (seg,) = goal.segments
    assert seg.kind == Zx200ArmSegment.JOINT
    assert list(seg.joint_positions) == pytest.approx([0.1, math.radians(-30.0), 1.3, 0.6])
    ok = Zx200ArmMove.Result()
    ok.error_code.val = TmsRpErrorCodes.SUCCESS
    assert row.check(ok)[0] and not row.check(Zx200ArmMove.Result(message="joint limit"))[0]
    with pytest.raises(SubtaskRecordError, match=r"record 'sample' field 'zx200_boom_goal_pos': missing"):
        row.build({"zx120_boom_goal_pos": -30.0}, "sample")
    with pytest.raises(SubtaskStateError, match=r"no arm_joint"):
        row.resolve(plan, {"swing_joint": 0.0, "boom_joint": 0.0, "bucket_joint": 0.0}, None)
    zx120 = SUBTASKS["st_zx120_sample_swing"]
    assert zx120.build({"zx120_swing_goal_pos": 45.0}, "s") == SamplePlan("swing_joint", pytest.approx(math.pi / 4))
