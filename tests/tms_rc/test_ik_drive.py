"""IkDrive (tms_rc.excavator.ik_drive): the cylinder-space IK over piston velocity control, the pure core."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.excavator.kinematics import JOINTS, load_kinematics
from tms_rc.excavator.hermite import HermiteReference
from tms_rc.excavator.ik_drive import SWING, IkDrive, IkDriveSettings
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    DirectionLut,
    PistonLut,
    extend_sign,
    load_piston_luts,
    load_piston_settings,
    pilot_range,
)

DELAYS = np.array([1.89, 1.10, 0.78, 0.58])  # [s] dead time + lag per joint, the ZX200's identified figures


@pytest.fixture(scope="module")
def kin():
    return load_kinematics("zx200")


@pytest.fixture(scope="module")
def parts(kin):
    return load_piston_luts("zx200"), load_piston_settings(), pilot_range(kin.machine.dbc)[0]


@pytest.fixture(scope="module")
def q0(kin):
    y = float(kin.tip_position(kin.home)[1])
    return kin.ik_position_with_angle(np.array([7.0, y, 1.0]), 1.2)


def still(position, theta_w: float) -> HermiteReference:
    """A reference that holds ``position`` and ``theta_w``."""
    p = [*np.asarray(position, dtype=float), theta_w]
    return HermiteReference.through([0.0, 1.0], [p, p])


def make(kin, parts, settings=None, delays=None, luts=None) -> IkDrive:
    lut, piston, p_max = parts
    return IkDrive(kin, luts or lut, piston, p_max, settings=settings or IkDriveSettings(), delays_s=delays)


def joint_signs(out) -> np.ndarray:
    """The joint direction each function's pilot pair commands (+1, -1, 0): ``plus`` turns the joint +."""
    return np.array([np.sign(out.pairs[fn].difference) for fn in JOINTS])


@pytest.mark.parametrize("delays", [None, DELAYS])
def test_zero_error_gives_no_pilots(kin, parts, q0, delays):
    drive = make(kin, parts, delays=delays)
    drive.start(still(kin.tip_position(q0), kin.theta_w(q0)))
    for k in range(20):
        out = drive.step(k * drive.dt, q0, np.zeros(4))
        assert all(p.plus == 0.0 and p.minus == 0.0 for p in out.pairs.values()), out.pairs
        assert all(v == 0.0 for v in out.piston_cmd.values())


def test_tip_error_in_x_moves_the_tip_in_x(kin, parts, q0):
    drive = make(kin, parts, settings=IkDriveSettings(smith_predictor=False))
    tip, th = kin.tip_position(q0), kin.theta_w(q0)
    drive.start(still(tip + np.array([0.1, 0.0, 0.0]), th))
    out = drive.step(0.0, q0, np.zeros(4))
    lut, _, p_max = parts
    gains, _ = drive.ik.actuator_state(q0)
    qd = np.zeros(4)
    for fn in CYLINDER_FUNCTIONS:
        i = JOINTS.index(fn)
        pair, v = out.pairs[fn], out.piston_cmd[fn]
        if v == 0.0:
            assert pair.plus == pair.minus == 0.0
            continue
        # the pair turns the joint the way the piston speed implies (dl/dq's sign, the description's geometry)
        assert np.sign(pair.difference) == np.sign(v * extend_sign(kin.machine, fn)) == np.sign(v / gains[i])
        # dead-zone compensation: at least the crack of that direction, at most the DBC's maximum
        assert lut[fn].crack(v) <= max(pair.plus, pair.minus) <= p_max
        qd[i] = v / gains[i]
    assert out.pairs[SWING].plus == out.pairs[SWING].minus == 0.0  # no swing table: spool centred
    # the commanded joint motion moves the tip toward +x (HEAP eq. 36: Kp x 0.1 m), not up or down much
    v_tip = kin.jacobians(q0)[1] @ qd
    assert v_tip[0] == pytest.approx(drive.settings.ik.kp_position * 0.1, rel=0.05)
    assert abs(v_tip[2]) < 0.1 * v_tip[0]
    # the pilots' joint directions are the joint velocities'
    assert np.array_equal(joint_signs(out)[1:], np.sign(qd[1:]))


def test_limits_binding_keep_pilots_finite_and_in_range(kin, parts, q0):
    _, _, p_max = parts
    lim = kin.limits
    # the arm at its upper limit (stroke level) and a tip reference 5 m away (pumps and speed limits bind)
    q = q0.copy()
    q[2] = float(lim.upper[2]) - 1e-3
    drive = make(kin, parts, settings=IkDriveSettings(smith_predictor=False))
    tip = kin.tip_position(q)
    drive.start(still(tip + np.array([-5.0, 0.0, -3.0]), kin.theta_w(q) + 1.0))
    out = drive.step(0.0, q, np.zeros(4))
    bound = [n for n in ("pump_flow", "velocity_limits", "stroke_limits") if out.ik.hqp.solved.get(n, False)]
    assert bound, out.ik.hqp.solved
    assert out.ik.gave_way
    for fn, pair in out.pairs.items():
        assert math.isfinite(pair.plus) and math.isfinite(pair.minus), fn
        assert 0.0 <= pair.plus <= p_max and 0.0 <= pair.minus <= p_max, (fn, pair)
        assert pair.plus == 0.0 or pair.minus == 0.0, (fn, pair)
    # the arm is not driven further into its upper limit (joint +)
    assert out.pairs["arm_joint"].plus == 0.0


def test_predictor_equalises_and_predicts(kin, parts, q0):
    drive = make(kin, parts, delays=DELAYS)
    assert drive.horizon_s == pytest.approx(1.10)  # the slowest driven function (the swing has no table)
    hold = {fn: round((1.10 - DELAYS[JOINTS.index(fn)]) / drive.dt) for fn in CYLINDER_FUNCTIONS}
    assert hold == {"boom_joint": 0, "arm_joint": 32, "bucket_joint": 52}
    tip = kin.tip_position(q0)
    drive.start(still(tip + np.array([0.1, 0.0, 0.0]), kin.theta_w(q0)))
    first = None
    for k in range(60):
        out = drive.step(k * drive.dt, q0, np.zeros(4))  # the plant has not moved yet (dead time)
        if k == 0:
            first = out
            assert out.piston_cmd["boom_joint"] != 0.0
            assert out.piston_cmd["arm_joint"] == 0.0 and out.piston_cmd["bucket_joint"] == 0.0
        if k == hold["arm_joint"]:
            # the arm now gets the command the IK gave at step 0 (through dl/dq at the same pose)
            assert out.piston_cmd["arm_joint"] == pytest.approx(float(first.ik.v[2]), rel=1e-9)
        if k == hold["bucket_joint"]:
            assert out.piston_cmd["bucket_joint"] == pytest.approx(float(first.ik.v[3]), rel=1e-9)
    # the pose solved at is the measured one plus what is in flight: it approaches the target though q does not
    pred_tip = kin.tip_position(out.q_solved)
    assert 0.0 < pred_tip[0] - tip[0] <= 0.1 + 1e-3


def test_swing_driven_only_with_its_table(kin, parts, q0):
    lut, piston, p_max = parts
    tip, th = kin.tip_position(q0), kin.theta_w(q0)
    ref = still(tip + np.array([0.0, 0.3, 0.0]), th)  # sideways: the swing must turn
    drive = make(kin, parts, settings=IkDriveSettings(smith_predictor=False))
    drive.start(ref)
    out = drive.step(0.0, q0, np.zeros(4))
    assert abs(out.swing_speed_cmd) > 0.01
    assert out.pairs[SWING].plus == out.pairs[SWING].minus == 0.0
    side = DirectionLut((0.7, 2.0, 3.0), (0.0, 0.4, 0.6))  # [MPa] -> [rad/s], a made-up swing table
    swing_lut = PistonLut(side, side)
    drive = IkDrive(kin, {**lut, SWING: swing_lut}, piston, p_max, settings=IkDriveSettings(smith_predictor=False))
    drive.start(ref)
    out = drive.step(0.0, q0, np.zeros(4))
    assert np.sign(out.pairs[SWING].difference) == np.sign(out.swing_speed_cmd) != 0.0


def test_refuses_bad_inputs(kin, parts):
    lut, piston, p_max = parts
    with pytest.raises(ValueError, match="bucket_joint"):
        IkDrive(kin, {k: v for k, v in lut.items() if k != "bucket_joint"}, piston, p_max)
    with pytest.raises(ValueError, match="delays_s"):
        IkDrive(kin, lut, piston, p_max, delays_s=[1.0, 1.0])
    drive = IkDrive(kin, lut, piston, p_max)
    with pytest.raises(ValueError, match="4 columns"):
        drive.start(HermiteReference.through([0.0, 1.0], [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]))
    with pytest.raises(RuntimeError, match="no reference"):
        drive.step(0.0, kin.home, np.zeros(4))


def test_for_machine_reads_the_identification(kin):
    drive = IkDrive.for_machine(kin)
    # the identified file's boom dead time + lag (the slowest driven function) is the predictor's horizon
    assert 0.5 < drive.horizon_s < 2.0
    assert set(drive.movers) == set(CYLINDER_FUNCTIONS)
    assert all(m.pi is None for m in drive.movers.values())  # the default: table feed-forward, no piston PI
