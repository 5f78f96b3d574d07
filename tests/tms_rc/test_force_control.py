"""The force loop around the ID (tms_rc.excavator.force_control): statics by hand, the estimate, the pilot choices.

Fast, no ROS, no plant: a static pose of the ZX200's front, synthetic look-up tables.
"""

from __future__ import annotations

import numpy as np
import pytest

from tms_model.excavator.kinematics import load_kinematics
from tms_model.machines import load_machine
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.force_control import (
    DRAG_ROLES,
    ForceLoop,
    ForceLoopSettings,
    contact_force_estimate,
    default_id_settings,
)
from tms_rc.excavator.id_hqp import IdReference, InverseDynamicsHQP
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    DirectionLut,
    PistonLut,
    cylinder_of,
    extend_sign,
    load_piston_settings,
)

#: the bench's flat-ground pose: boom low, arm reached out, the edge near the ground
Q = np.array([0.0, -0.23, 1.14, -0.24])
LUT = PistonLut(DirectionLut((0.76, 1.5, 3.0), (0.0, 0.17, 0.49)), DirectionLut((0.74, 1.5, 3.0), (0.0, 0.32, 0.96)))
P_MAX = 5.0


@pytest.fixture(scope="module")
def front():
    machine = load_machine("zx200")
    return FrontDynamics(machine), load_kinematics("zx200")


def _hold(dyn, kin, q) -> IdReference:
    return IdReference(position=dyn.tip_position(q), theta_w=float(q[1] + q[2] + q[3]) + kin.c_bucket)


def _statics_by_hand(dyn, q, force_d) -> np.ndarray:
    """Cylinder forces [N] (boom, arm, bucket) that hold the front still pressing ``force_d`` on the soil: virtual
    work, tau = g(q) + J^T force_d, f_i = tau_i / (dl_i/dq_i) with dl/dq by a finite difference of the lengths."""
    from tms_rc.excavator.piston import piston_length

    tau = dyn.gravity(q) + dyn.tip_jacobian(q).T @ force_d
    out = []
    for i, fn in enumerate(CYLINDER_FUNCTIONS, start=1):
        h = 1e-6
        dl = (piston_length(dyn.machine, fn, q[i] + h) - piston_length(dyn.machine, fn, q[i] - h)) / (2 * h)
        out.append(tau[i] / dl)
    return np.array(out)


@pytest.mark.parametrize("force_d", [(0.0, 0.0, -40e3), (-15e3, 0.0, -60e3), (0.0, 0.0, 0.0)])
def test_id_cylinder_forces_with_a_wrench_match_statics_by_hand(front, force_d) -> None:
    dyn, kin = front
    force_d = np.array(force_d)
    ctl = InverseDynamicsHQP(dyn, kin, default_id_settings())
    res = ctl.solve(Q, np.zeros(4), _hold(dyn, kin, Q), f_ext=-force_d)
    want = _statics_by_hand(dyn, Q, force_d)
    assert np.allclose(res.qdd, 0.0, atol=1e-6)
    assert np.allclose(res.force[1:], want, rtol=1e-3, atol=50.0), (res.force[1:], want)
    # pressing adds to the arm's and the bucket's push (their cylinders extend to crowd and curl)
    if force_d[2] < 0:
        base = _statics_by_hand(dyn, Q, np.zeros(3))
        assert want[1] > base[1] and want[2] > base[2]


def test_contact_estimate_inverts_the_statics(front) -> None:
    dyn, _ = front
    for force_d in ((0.0, 0.0, -50e3), (-20e3, 0.0, -30e3)):
        force_d = np.array(force_d)
        est = contact_force_estimate(dyn, Q, _statics_by_hand(dyn, Q, force_d))
        assert np.allclose(est, force_d, atol=200.0), (est, force_d)


def _loop(front, **kw) -> ForceLoop:
    dyn, kin = front
    luts = dict.fromkeys(CYLINDER_FUNCTIONS, LUT)
    return ForceLoop(dyn, kin, luts, load_piston_settings(), P_MAX, settings=ForceLoopSettings(**kw))


def _pressures(machine, forces: np.ndarray) -> dict[str, tuple[float, float]]:
    """(cap, rod) [MPa] that give each cylinder the force [N]: the low side at 0."""
    out = {}
    for fn, f in zip(CYLINDER_FUNCTIONS, forces, strict=True):
        c = cylinder_of(machine, fn)
        out[fn] = (f / c.cap_area / 1e6, 0.0) if f >= 0 else (0.0, -f / c.rod_area / 1e6)
    return out


def test_loop_pilots_push_towards_the_id_force_and_hold_the_rest(front) -> None:
    dyn, kin = front
    loop = _loop(front, force_ki=0.0)
    force_d = np.array([0.0, 0.0, -40e3])
    want = _statics_by_hand(dyn, Q, force_d)
    for k, fn in enumerate(("arm_joint", "bucket_joint"), start=1):
        # the cylinder 30 kN short of the ID's force: more push = extend; 30 kN over: retract
        for short, direction in ((30e3, 1), (-30e3, -1)):
            loop.reset()
            measured = want.copy()
            measured[k] -= short
            out = loop.step(Q, np.zeros(4), _pressures(dyn.machine, measured), _hold(dyn, kin, Q), force_d)
            pair = out.pairs[fn]
            ext = extend_sign(dyn.machine, fn)
            # the pair is named by joint direction: extending the cylinder = the joint's ext direction
            assert np.sign(pair.difference) == direction * ext, (fn, short, pair)
            # dead-zone compensation: the pilot starts at the direction's crack
            crack = LUT.crack(direction)
            assert abs(pair.difference) >= crack
            # the boom is not under force control by default: no pilot, its oil holds it
            assert out.pairs["boom_joint"].difference == 0.0
    # at the ID's forces the error is 0: inside the zero band, no command on any line
    loop.reset()
    out = loop.step(Q, np.zeros(4), _pressures(dyn.machine, want), _hold(dyn, kin, Q), force_d)
    assert all(p.plus == 0.0 and p.minus == 0.0 for p in out.pairs.values()), out.pairs
    assert np.allclose(-out.pressed[2], 40e3, rtol=0.01)


def test_outer_integral_adds_press_when_short(front) -> None:
    dyn, kin = front
    loop = _loop(front, force_ki=0.5)
    force_d = np.array([0.0, 0.0, -40e3])
    short = _pressures(dyn.machine, _statics_by_hand(dyn, Q, np.array([0.0, 0.0, -30e3])))
    for _ in range(10):
        out = loop.step(Q, np.zeros(4), short, _hold(dyn, kin, Q), force_d)
    assert loop.correction == pytest.approx(10 * 0.5 * 10e3 * loop.dt, rel=0.05)
    assert out.f_ext[2] == pytest.approx(40e3 + loop.correction)
    # no press wanted: a free motion, the integral cleared
    loop.step(Q, np.zeros(4), short, _hold(dyn, kin, Q), np.zeros(3))
    assert loop.correction == 0.0


def test_drag_roles_move_along_the_path_not_into_the_ground(front) -> None:
    dyn, kin = front
    loop = _loop(front, **DRAG_ROLES)
    ref = _hold(dyn, kin, Q)
    back = np.array([-0.15, 0.0, 0.0])  # towards the machine along flat ground
    ref.velocity = back
    rates = loop.path_rates(Q, ref, np.array([0.0, 0.0, 1.0]))
    qd = np.zeros(4)
    for fn, r in rates.items():
        qd[CYLINDER_FUNCTIONS.index(fn) + 1] = r
    v = dyn.tip_jacobian(Q) @ qd
    assert v[0] == pytest.approx(-0.15, abs=1e-6) and abs(v[2]) < 1e-6


def test_settings_refuse_bad_roles(front) -> None:
    with pytest.raises(ValueError, match="both under force and velocity control"):
        ForceLoopSettings(functions=("arm_joint",), velocity_functions=("arm_joint",))
    with pytest.raises(ValueError, match="not cylinder functions"):
        ForceLoopSettings(functions=("swing_joint",))
    dyn, kin = front
    with pytest.raises(ValueError, match="no identified look-up table for bucket_joint"):
        ForceLoop(dyn, kin, {"boom_joint": LUT, "arm_joint": LUT}, load_piston_settings(), P_MAX)
    with pytest.raises(ValueError, match="normal must be a unit vector"):
        _loop(front).step(Q, np.zeros(4), _pressures(dyn.machine, np.zeros(3)), _hold(dyn, kin, Q),
                          np.array([0.0, 0.0, -1e3]), normal=np.array([0.0, 0.0, 2.0]))
