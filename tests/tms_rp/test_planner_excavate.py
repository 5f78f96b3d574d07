"""excavate_simple planning: tms_sp's target (penetration point, entry angle, drag offset) as intended."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.excavator.codes import InvalidGoalError, OutOfReachError
from tms_model.excavator.kinematics import load_kinematics
from tms_rp.arm.planner import ArmPlanner, load_planner_config

KIN = load_kinematics()
PLAN = ArmPlanner(KIN, load_planner_config(KIN.machine.kind))


def test_seed_target_penetrates_at_the_point_drags_offset_and_keeps_soil() -> None:
    cfg = PLAN.cfg
    # config/seeds/paper.yaml target_excavate_pose (tms_sp output): 45 deg is not holdable there,
    # so the entry angle is the nearest holdable one; the tip still goes exactly to the point.
    targets = PLAN.excavate([5.85, -0.05, 1.15], math.radians(45.0), 1.5)
    labels = [t.label for t in targets]
    assert labels == ["approach", "penetrate", "drag", "curl and lift"]  # config: curl_during_lift
    pen, drag, lift = targets[1:]
    assert np.allclose(pen.position, [5.85, -0.05, 1.15 - cfg.penetrate_depth])
    assert math.radians(45.0) < pen.theta_w < math.radians(45.0) + 0.3
    r0 = np.linalg.norm(pen.position[:2] - KIN.swing_origin[:2])
    r1 = np.linalg.norm(drag.position[:2] - KIN.swing_origin[:2])
    assert r0 - r1 == pytest.approx(1.5, abs=1e-6)  # offset = drag length towards the machine
    assert drag.theta_w >= cfg.drag_end_theta_w - 1e-9 and lift.theta_w >= drag.theta_w
    assert lift.position[2] == pytest.approx(drag.position[2] + cfg.lift_height)
    for t in (pen, drag, lift):  # every phase reachable with the joints inside their margins
        q = KIN.ik_position_with_angle(t.position, t.theta_w)
        assert KIN.limits.violation(q, margin=-cfg.dig_joint_margin + 1e-6) is None
    # a holdable entry angle is kept as given
    assert PLAN.excavate([5.85, -0.05, 1.15], 1.2, 1.5)[1].theta_w == pytest.approx(1.2)


def test_curl_in_place_then_lift_when_not_curling_during_the_lift() -> None:
    plan = ArmPlanner(KIN, dataclasses.replace(PLAN.cfg, curl_during_lift=0.0))
    targets = plan.excavate([5.85, -0.05, 1.15], math.radians(45.0), 1.5)
    assert [t.label for t in targets] == ["approach", "penetrate", "drag", "curl", "lift"]
    drag, curl, lift = targets[2:]
    assert np.allclose(curl.position, drag.position) and curl.theta_w > drag.theta_w
    assert lift.position[2] == pytest.approx(drag.position[2] + plan.cfg.lift_height)
    assert lift.theta_w == pytest.approx(curl.theta_w) and lift.via and not curl.via
    # curling during the lift ends at the same point and angle
    merged = PLAN.excavate([5.85, -0.05, 1.15], math.radians(45.0), 1.5)[-1]
    assert np.allclose(merged.position, lift.position) and merged.theta_w == pytest.approx(lift.theta_w)


def test_bad_excavate_goals_are_rejected_with_the_reason() -> None:
    with pytest.raises(InvalidGoalError, match="NaN"):
        PLAN.excavate([5.85, float("nan"), 1.15], 1.0, 1.5)
    with pytest.raises(InvalidGoalError, match="negative"):
        PLAN.excavate([5.85, 0.0, 1.15], 1.0, -1.0)
    with pytest.raises(OutOfReachError, match="boom foot"):
        PLAN.excavate([15.0, 0.0, 1.0], 1.0, 1.0)


def test_dig_measured_marks_the_approach_penetrate_and_drag_not_the_lift() -> None:
    assert not any(t.measured for t in PLAN.excavate([5.85, -0.05, 1.15], 1.2, 1.5))  # the kind's file: off
    design = load_planner_config(KIN.machine.kind, config_path("tms_rp", "zx200_planner_design.yaml"))
    marked = ArmPlanner(KIN, design).excavate([5.85, -0.05, 1.15], 1.2, 1.5)
    assert [t.label for t in marked if t.measured] == ["approach", "penetrate", "drag"]


def test_release_measured_marks_the_open_only() -> None:
    q = np.array([0.0, -0.6, 1.2, 1.5])  # a loaded bucket carried over the dump place
    assert not any(t.measured for t in PLAN.release(1.0, q))  # the kind's file: off
    design = load_planner_config(KIN.machine.kind, config_path("tms_rp", "zx200_planner_design.yaml"))
    targets = ArmPlanner(KIN, design).release(1.0, q)
    assert [t.label for t in targets] == ["swing", "open"] and [t.measured for t in targets] == [False, True]


def test_a_planner_file_with_a_base_changes_only_its_own_keys(tmp_path) -> None:
    base = load_planner_config(KIN.machine.kind)
    design = load_planner_config(KIN.machine.kind, config_path("tms_rp", "zx200_planner_design.yaml"))
    assert dataclasses.replace(design, dig_measured=base.dig_measured, release_measured=base.release_measured) == base
    assert design.dig_measured and design.release_measured
    (tmp_path / "kind.yaml").write_text(config_path("tms_rp", "zx200_planner.yaml").read_text())
    bad = tmp_path / "bad.yaml"
    bad.write_text("base: kind.yaml\nlift_height: 1.0\ndig_measured: 1\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml:3: dig_measured: expected true or false"):
        load_planner_config(KIN.machine.kind, bad)
    bad.write_text("base: kind.yaml\nlift_hieght: 1.0\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml:2: lift_hieght: unknown key"):
        load_planner_config(KIN.machine.kind, bad)
    (tmp_path / "middle.yaml").write_text("base: kind.yaml\n")
    bad.write_text("base: middle.yaml\nlift_height: 1.0\n")
    with pytest.raises(ConfigError, match="has a base of its own"):
        load_planner_config(KIN.machine.kind, bad)
    bad.write_text("base: kind.yaml\nlift_height: 1.0\n")
    assert load_planner_config(KIN.machine.kind, bad) == dataclasses.replace(base, lift_height=1.0)
