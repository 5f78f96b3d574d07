"""A second excavator kind, the Hitachi ZX120, through the generic kinematics: spec-sheet envelope and FK/IK."""

from __future__ import annotations

import numpy as np
import pytest

from tms_model.excavator.kinematics import ExcavatorKinematics, load_kinematics
from tms_model.machines import load_machine

# Hitachi ZX120-6 spec sheet (4.68 m boom, 2.52 m arm), as cited in config/machines/zx120.yaml.
SPEC = {"max_reach": 8.67, "max_depth": 5.98, "max_height": 9.20}
TOLERANCE_M = 0.10  # the envelope is sampled on a grid; the geometry was fitted to these figures


@pytest.fixture(scope="module")
def kin() -> ExcavatorKinematics:
    return load_kinematics("zx120")


def test_zx120_envelope_matches_spec_sheet(kin: ExcavatorKinematics) -> None:
    env = kin.envelope()
    for key, spec in SPEC.items():
        assert env[key] == pytest.approx(spec, abs=TOLERANCE_M), key


def test_zx120_is_smaller_than_zx200(kin: ExcavatorKinematics) -> None:
    zx200 = load_kinematics("zx200")
    assert kin.kind == "zx120" and zx200.kind == "zx200"
    assert kin.envelope()["max_reach"] < zx200.envelope()["max_reach"] - 1.0
    assert load_machine("zx120").bucket.capacity == pytest.approx(0.5)  # type: ignore[union-attr]


def test_zx120_fk_ik_round_trip(kin: ExcavatorKinematics) -> None:
    rng = np.random.default_rng(3)
    lo, hi = kin.limits.lower.copy(), kin.limits.upper.copy()
    lo[0], hi[0] = -np.pi, np.pi
    checked = 0
    for _ in range(300):
        q = rng.uniform(lo + 0.02, hi - 0.02)
        tip = kin.tip_position(q)
        # with the ZX120's deep boom range the tip can pass behind the swing axis; IK then answers the
        # mirrored swing (same tip, other q): compare joints only for tips in front of the axis
        forward = np.cos(q[0]) * (tip[0] - kin.swing_origin[0]) + np.sin(q[0]) * (tip[1] - kin.swing_origin[1])
        if forward < 0.5:
            continue
        q2 = kin.ik_position_with_angle(tip, kin.theta_w(q))
        assert np.allclose(kin.tip_position(q2), tip, atol=1e-6)
        assert np.allclose(q2, q, atol=1e-6)
        checked += 1
    assert checked > 200


def test_zx120_pose_round_trip(kin: ExcavatorKinematics) -> None:
    q = np.array([0.4, -0.3, 1.5, 0.8])
    pose = kin.tip_pose(q)
    import pinocchio as pin

    qx = pin.Quaternion(pose.rotation)
    pos, theta_w = kin.pose_to_position_with_angle(pose.translation, np.array([qx.x, qx.y, qx.z, qx.w]))
    assert theta_w == pytest.approx(kin.theta_w(q), abs=1e-9)
    assert np.allclose(kin.ik_position_with_angle(pos, theta_w), q, atol=1e-6)
