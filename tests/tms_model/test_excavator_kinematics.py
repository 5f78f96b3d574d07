"""ZX200 kinematics: pinocchio FK/Jacobians against the reference geometry, closed-form IK, rejections."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.excavator.codes import InvalidGoalError, JointLimitError, OutOfReachError
from tms_model.excavator.kinematics import load_kinematics


@pytest.fixture(scope="module")
def kin():
    return load_kinematics()


def random_q(kin, rng, n):
    lo = np.where(np.isfinite(kin.limits.lower), kin.limits.lower, -math.pi)
    hi = np.where(np.isfinite(kin.limits.upper), kin.limits.upper, math.pi)
    return rng.uniform(lo, hi, size=(n, 4))


def test_zero_pose_matches_reference_geometry(kin):
    # zx200_ros2 URDF: at q = 0 the tip is at (10.435, -0.087, 1.957) in base_link.
    np.testing.assert_allclose(kin.tip_position(np.zeros(4)), [10.435, -0.087, 1.957], atol=2e-3)
    assert kin.l_boom == pytest.approx(5.648, abs=1e-3)
    assert kin.l_arm == pytest.approx(2.890, abs=1e-3)
    assert kin.theta_w(np.zeros(4)) == pytest.approx(0.0, abs=1e-5)


def test_ik_round_trip_over_random_joint_angles(kin):
    rng = np.random.default_rng(1)
    for q in random_q(kin, rng, 300):
        p, th = kin.tip_position(q), kin.theta_w(q)
        q_ik = kin.ik_position_with_angle(p, th)
        assert np.allclose(np.cos(q_ik - q), 1.0, atol=1e-9) and np.allclose(q_ik[1:], q[1:], atol=1e-6)
        np.testing.assert_allclose(kin.tip_position(q_ik), p, atol=1e-6)


def test_jacobians_match_finite_differences(kin):
    rng = np.random.default_rng(2)
    for q in random_q(kin, rng, 20):
        tip, jt, pin_p, jp = kin.jacobians(q)
        for i in range(4):
            dq = np.zeros(4)
            dq[i] = 1e-6
            np.testing.assert_allclose((kin.tip_position(q + dq) - tip) / 1e-6, jt[:, i], atol=1e-4)
            th = (kin.theta_w(q + dq) - kin.theta_w(q)) / 1e-6
            assert th == pytest.approx(kin.theta_w_jacobian()[i], abs=1e-6)
        # theta_w is the pin->tip line's angle below the horizontal, in the front's plane
        d = tip - pin_p
        outward = np.array([math.cos(q[0]), math.sin(q[0])])
        geo = math.atan2(-d[2], float(d[:2] @ outward))
        assert math.cos(geo - kin.theta_w(q)) == pytest.approx(1.0, abs=1e-9)


def test_pose_goal_converts_to_theta_w(kin):
    import pinocchio as pin

    q = np.array([0.4, -0.6, 1.5, 0.8])
    pose = kin.tip_pose(q)
    pos, th = kin.pose_to_position_with_angle(pose.translation, pin.Quaternion(pose.rotation).coeffs())
    assert th == pytest.approx(kin.theta_w(q), abs=1e-9)
    rolled = pose.rotation @ pin.rpy.rpyToMatrix(0.3, 0.0, 0.0)
    with pytest.raises(OutOfReachError, match="orientation unreachable"):
        kin.pose_to_position_with_angle(pose.translation, pin.Quaternion(rolled).coeffs())
    with pytest.raises(InvalidGoalError, match="norm"):
        kin.pose_to_position_with_angle(pose.translation, np.zeros(4))


def test_rejections_name_distance_joint_and_nan(kin):
    with pytest.raises(OutOfReachError, match=r"from the boom foot; reachable .* m"):
        kin.ik_position_with_angle(np.array([15.0, 0.0, 1.0]), 0.5)
    with pytest.raises(JointLimitError, match="boom_joint would be"):
        kin.ik_position_with_angle(np.array([7.0, 0.0, -3.5]), 1.0)  # needs the boom below its -0.1 limit
    with pytest.raises(InvalidGoalError, match="finite"):
        kin.ik_position_with_angle(np.array([float("nan"), 0.0, 1.0]), 0.5)


def test_pose_to_theta_w_is_not_wrapped_to_pi() -> None:
    # Regression (bench: a pose goal ended TIMEOUT 7-9 m away): theta_w = boom + arm + bucket reaches
    # past pi (curled bucket); the pose's pitch must map back to the angle the joints can hold.
    import pinocchio as pin

    from tms_model.excavator.kinematics import load_kinematics

    kin = load_kinematics()
    rng = np.random.default_rng(1)
    lo, hi = kin.limits.lower.copy(), kin.limits.upper.copy()
    lo[0], hi[0] = -3.0, 3.0
    for q in [np.array([0.165, -0.348, 1.929, 1.628]), *rng.uniform(lo, hi, size=(300, 4))]:
        m = kin.tip_pose(q)
        _, th = kin.pose_to_position_with_angle(m.translation, pin.Quaternion(m.rotation).coeffs())
        assert abs(th - kin.theta_w(q)) < 1e-9, (q, th, kin.theta_w(q))
