"""Planner paths of the load pass: joint-space carry for big swings, release with the tip held, via marks."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.excavator.codes import InvalidGoalError, JointLimitError
from tms_model.excavator.kinematics import load_kinematics
from tms_model.excavator.targets import CartesianTarget, JointTarget
from tms_rp.arm.planner import ArmPlanner, load_planner_config

KIN = load_kinematics()
PLAN = ArmPlanner(KIN, load_planner_config(KIN.machine.kind))
#: The seed's release pose over the IC120 at P1 (config/seeds/paper.yaml target_release_pose, 85 deg carry).
RELEASE_TIP = np.array([-0.065, 6.475, 2.726])
CARRY_THETA_W = math.radians(85.0)
#: Bucket tip lifted out of the mound (swing 0).
LIFTED = np.array([4.2, 0.0, 1.6])


def test_big_swing_goes_joint_space_to_the_ik_pose_then_straight_to_the_goal() -> None:
    q_lifted = KIN.ik_position_with_angle(LIFTED, 2.6)
    targets = PLAN.change_pose(positions_with_angle=[(RELEASE_TIP.tolist(), CARRY_THETA_W)], current_q=q_lifted)
    assert [type(t) for t in targets] == [JointTarget, CartesianTarget]
    joint, final = targets
    assert joint.via and not final.via
    np.testing.assert_allclose(KIN.tip_position(joint.q), RELEASE_TIP, atol=1e-6)
    assert KIN.theta_w(joint.q) == pytest.approx(CARRY_THETA_W, abs=1e-6)
    np.testing.assert_allclose(final.position, RELEASE_TIP)
    assert final.theta_w == pytest.approx(CARRY_THETA_W)


def test_small_moves_and_unknown_start_stay_a_straight_tip_line() -> None:
    q0 = KIN.ik_position_with_angle(LIFTED, 1.6)
    near = LIFTED + np.array([-0.5, 0.3, 0.2])  # swing change ~0.07 rad < joint_space_swing
    assert [type(t) for t in PLAN.change_pose(positions_with_angle=[(near.tolist(), 1.6)], current_q=q0)] == [
        CartesianTarget
    ]
    assert [type(t) for t in PLAN.change_pose(positions_with_angle=[(RELEASE_TIP.tolist(), CARRY_THETA_W)])] == [
        CartesianTarget
    ]


def test_release_opens_the_bucket_with_the_tip_held_over_the_release_point() -> None:
    q_carry = KIN.ik_position_with_angle(RELEASE_TIP, CARRY_THETA_W)
    swing = math.atan2(RELEASE_TIP[1] - KIN.swing_origin[1], RELEASE_TIP[0] - KIN.swing_origin[0])
    away = q_carry.copy()
    away[0] -= 0.3  # the arm is not yet over the vessel: swing first, then open
    targets = PLAN.release(swing, away)
    assert [t.label for t in targets] == ["swing", "open"]
    assert all(isinstance(t, JointTarget) and t.via for t in targets)
    swung, opened = targets
    # the tip stays where the swing left it; the edge angle drops below the plant's 1.2 rad spill angle
    np.testing.assert_allclose(KIN.tip_position(opened.q), KIN.tip_position(swung.q), atol=1e-6)
    assert KIN.theta_w(opened.q) < 0.7 < 1.2 < KIN.theta_w(swung.q)
    assert KIN.limits.violation(opened.q) is None


def test_release_from_over_the_vessel_opens_at_once_and_the_open_does_the_small_swing() -> None:
    q_carry = KIN.ik_position_with_angle(RELEASE_TIP, CARRY_THETA_W)
    swing = math.atan2(RELEASE_TIP[1] - KIN.swing_origin[1], RELEASE_TIP[0] - KIN.swing_origin[0])
    nudge = PLAN.cfg.release_swing_in_open / 2
    (opened,) = PLAN.release(swing + nudge, q_carry)
    assert opened.label == "open" and opened.via
    assert opened.q[0] == pytest.approx(math.remainder(swing + nudge, 2 * math.pi))
    assert KIN.theta_w(opened.q) < 0.7
    assert [t.label for t in PLAN.release(swing + 2 * PLAN.cfg.release_swing_in_open, q_carry)] == ["swing", "open"]


def test_excavate_lift_is_a_via_point_and_digging_runs_faster() -> None:
    targets = PLAN.excavate([5.05, 1.25, 0.05], 1.11, 1.1)
    assert [t.label for t in targets] == ["approach", "penetrate", "drag", "curl and lift"]
    assert targets[-1].via
    assert all(t.speed_scale == PLAN.cfg.dig_speed_scale for t in targets[1:])


def test_pass_through_carry_ends_at_a_via_point_and_the_release_plans_from_it() -> None:
    q_lifted = KIN.ik_position_with_angle(LIFTED, 2.6)
    carry = PLAN.change_pose(positions_with_angle=[(RELEASE_TIP.tolist(), CARRY_THETA_W)], current_q=q_lifted,
                             pass_through=True)
    assert [type(t) for t in carry] == [JointTarget], "the joint-space swing ends at the goal: no straight approach"
    assert carry[-1].via, "a pass-through change_pose ends without waiting for rest"
    near = LIFTED + np.array([-0.5, 0.3, 0.2])  # a small move stays one straight tip line, now a via point
    small = PLAN.change_pose(positions_with_angle=[(near.tolist(), 1.6)], current_q=q_lifted, pass_through=True)
    assert [type(t) for t in small] == [CartesianTarget] and small[0].via
    np.testing.assert_allclose(KIN.tip_position(PLAN.end_joints(small)), near, atol=1e-6)
    end = PLAN.pass_through_end(carry)
    assert (
        PLAN.pass_through_end(PLAN.change_pose(positions_with_angle=[(near.tolist(), 1.6)], current_q=q_lifted)) is None
    )
    np.testing.assert_allclose(KIN.tip_position(end), RELEASE_TIP, atol=1e-6)
    # The carry's goal ended on the controller's prediction: the measured swing still lags ~0.25 rad.
    lagging = end - np.array([0.25, 0.05, -0.05, 0.02])
    assert np.array_equal(PLAN.start_state(lagging, end), end)
    from_end = PLAN.release(float(end[0]), PLAN.start_state(lagging, end))
    from_lagging = PLAN.release(float(end[0]), lagging)
    assert [t.label for t in from_end] == ["open"], "over the vessel already: no extra swing"
    assert [t.label for t in from_lagging] == ["swing", "open"]
    np.testing.assert_allclose(KIN.tip_position(from_end[-1].q), RELEASE_TIP, atol=1e-3)
    # Too far from the end point (the arm was moved elsewhere, or never got there): the measurement wins.
    elsewhere = end + np.array([0.0, 0.0, PLAN.cfg.continue_window_rad + 0.01, 0.0])
    assert PLAN.start_state(elsewhere, end) is elsewhere
    # Swing angles compare the short way round (2 pi apart is the same pose).
    wrapped = end + np.array([2 * math.pi - 0.1, 0.0, 0.0, 0.0])
    assert np.array_equal(PLAN.start_state(wrapped, end), end)
    assert PLAN.start_state(None, end) is None
    assert PLAN.start_state(lagging, None) is lagging


def test_theta_w_tolerance_takes_the_nearest_holdable_angle_within_it_and_rejects_beyond() -> None:
    # 0.5 m above the seeded excavation target (config/seeds/paper.yaml): its 1.112 rad edge angle would
    # put the bucket joint below its limit there.
    target, th = np.array([5.05, 1.25, 0.051349]), 1.111833
    above = target + np.array([0.0, 0.0, 0.5])
    q_over_vessel = KIN.ik_position_with_angle(RELEASE_TIP, CARRY_THETA_W)
    with pytest.raises(JointLimitError, match="bucket_joint"):
        PLAN.change_pose(positions_with_angle=[(above.tolist(), th)], current_q=q_over_vessel)
    back = PLAN.change_pose(positions_with_angle=[(above.tolist(), th)], current_q=q_over_vessel,
                            pass_through=True, theta_w_tolerance=0.5)
    end = PLAN.pass_through_end(back)
    np.testing.assert_allclose(KIN.tip_position(end), above, atol=1e-6)
    assert 0 < KIN.theta_w(end) - th < 0.5
    # near the excavate's first point: the return does the swing, the approach is left a bucket trim (the
    # excavate also moves the entry angle inside its dig margin first, so the two angles differ slightly)
    q_above = PLAN.excavate(target.tolist(), th, 1.1)[0].q
    assert abs(end[0] - q_above[0]) < 1e-9 and np.max(np.abs(end - q_above)) < 0.15, (end, q_above)
    with pytest.raises(JointLimitError, match=r"theta_w 1\.112 rad cannot be held.*more than theta_w_tolerance 0\.050"):
        PLAN.change_pose(positions_with_angle=[(above.tolist(), th)], current_q=q_over_vessel, theta_w_tolerance=0.05)
    with pytest.raises(InvalidGoalError, match="negative"):
        PLAN.change_pose(positions_with_angle=[(above.tolist(), th)], theta_w_tolerance=-0.1)
    # a holdable angle is kept as asked
    ok = PLAN.change_pose(positions_with_angle=[(RELEASE_TIP.tolist(), CARRY_THETA_W)], theta_w_tolerance=0.5)
    assert ok[-1].theta_w == CARRY_THETA_W
