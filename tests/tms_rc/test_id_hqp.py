"""The inverse-dynamics hierarchy (tms_rc.excavator.id_hqp) on the ZX200 description: no ROS, pure core.

(a) all limits slack: the EoM holds and the tip / theta_w accelerations are met; (b) each limit made active in
turn by a demanding reference (pump flow, cylinder force, actuator speed, stroke, ground damper): the limit holds,
the tip position task gives way, the levels above still hold; (c) static hold: the cylinder forces equal the
gravity load worked out by hand (moments of the link weights about each joint axis) within 1 %; (d) a soil force or
wrench at the tip enters the EoM as J^T F.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from tms_model.cylinders import cylinder_length
from tms_model.excavator.kinematics import load_kinematics
from tms_model.machines import load_machine
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.id_hqp import IdReference, IdSettings, InverseDynamicsHQP

#: [N m] EoM residual allowed (the EoM level is eliminated exactly)
EOM_TOL = 1e-6
#: relative tolerance of a binding limit (OSQP eps 1e-6 on rows scaled to O(1), plus the fix tolerance 1e-5)
LIMIT_TOL = 1e-3


@pytest.fixture(scope="module")
def front():
    machine = load_machine("zx200")
    return FrontDynamics(machine), load_kinematics("zx200")


def _hold_reference(kin, q, dyn, qd, extra_accel=(0.0, 0.0, 0.0)) -> IdReference:
    """Keep the present tip velocity and theta_w rate (the reference follows the state), plus ``extra_accel``
    on top of the tip acceleration that constant joint speeds give (J_dot qd)."""
    jac = dyn.tip_jacobian(q)
    return IdReference(
        position=kin.tip_position(q), velocity=jac @ qd,
        acceleration=dyn.tip_jdot_qd(q, qd) + np.asarray(extra_accel), theta_w=kin.theta_w(q),
        theta_w_rate=float(qd[1] + qd[2] + qd[3]),
    )


def _pump_flow(ctl: InverseDynamicsHQP, gains: np.ndarray, qd: np.ndarray) -> float:
    """[m^3/s] sum over the pump's functions of area (by direction) x |cylinder speed|."""
    total = 0.0
    for i in ctl.pump_joints:
        a = ctl.dyn.actuators[i]
        v = gains[i] * qd[i]
        total += (a.area_extend if v > 0 else a.area_retract) * abs(v)
    return total


def _check_eom(res) -> None:
    assert np.abs(res.eom_residual).max() < EOM_TOL, res.eom_residual


def test_slack_limits_eom_and_tasks_met(front):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    qd = np.array([0.02, 0.05, -0.1, 0.1])
    ref = IdReference(position=kin.tip_position(q) + [0.01, 0.0, -0.01], acceleration=np.array([0.1, 0.05, -0.1]),
                      theta_w=kin.theta_w(q) + 0.01, theta_w_accel=0.05)
    res = ctl.solve(q, qd, ref)
    _check_eom(res)
    for name in ("pump_flow", "force_limits", "velocity_limits", "stroke_limits", "collision"):
        assert res.hqp.slack[name] == 0.0, (name, res.hqp.slack)
    np.testing.assert_allclose(res.tip_accel, res.tip_accel_desired, atol=1e-4)
    assert res.qdd[1:].sum() == pytest.approx(res.theta_w_accel_desired, abs=1e-5)
    assert not res.hqp.failed
    # the output forces are the torques through the actuator map
    np.testing.assert_allclose(res.force * dyn.actuator_gains(q), res.tau, rtol=1e-12)


def test_pump_flow_limit(front):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    g = dyn.actuator_gains(q)
    qd = np.array([0.0, -0.1, 0.3, 0.3])
    qd *= 0.95 * ctl.q_max / _pump_flow(ctl, g, qd)  # at 95 % of the pumps
    v = dyn.tip_jacobian(q) @ qd
    res = ctl.solve(q, qd, _hold_reference(kin, q, dyn, qd, 10.0 * v / np.linalg.norm(v)))  # speed up along v
    _check_eom(res)
    flow = _pump_flow(ctl, g, qd + ctl.dt * res.qdd)
    assert flow <= ctl.q_max * (1 + LIMIT_TOL)
    assert flow >= ctl.q_max * 0.99  # it binds: the demand would have gone beyond
    assert res.hqp.slack["pump_flow"] < 1e-6
    assert np.linalg.norm(res.tip_accel - res.tip_accel_desired) > 0.1  # the tip gives way


def test_force_limit(front):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    qd = np.zeros(4)
    res = ctl.solve(q, qd, _hold_reference(kin, q, dyn, qd, (0.0, 0.0, 100.0)))  # 10 g up from rest
    _check_eom(res)
    tmin, tmax = dyn.torque_limits(dyn.actuator_gains(q))
    tol = LIMIT_TOL * ctl.torque_scale
    assert np.all(res.tau <= tmax + tol) and np.all(res.tau >= tmin - tol), (res.tau, tmin, tmax)
    assert np.any(np.isclose(res.tau, tmax, atol=tol) | np.isclose(res.tau, tmin, atol=tol))  # one binds
    assert _pump_flow(ctl, dyn.actuator_gains(q), qd + ctl.dt * res.qdd) <= ctl.q_max * (1 + LIMIT_TOL)
    assert np.linalg.norm(res.tip_accel - res.tip_accel_desired) > 1.0


def test_velocity_limit(front):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    vmax_swing = ctl.speed_limits[0] / dyn.actuator_gains(q)[0]
    qd = np.array([vmax_swing - 0.001, 0.0, 0.0, 0.0])  # the swing (own circuit, not the pumps') near its limit
    v = dyn.tip_jacobian(q) @ qd
    res = ctl.solve(q, qd, _hold_reference(kin, q, dyn, qd, 2.0 * v / np.linalg.norm(v)))  # swing faster
    _check_eom(res)
    assert qd[0] + ctl.dt * res.qdd[0] <= vmax_swing + 1e-6
    assert qd[0] + ctl.dt * res.qdd[0] >= vmax_swing - 1e-4  # it binds
    tmin, tmax = dyn.torque_limits(dyn.actuator_gains(q))
    assert np.all(res.tau <= tmax) and np.all(res.tau >= tmin)  # the force limits (above) hold
    assert np.linalg.norm(res.tip_accel - res.tip_accel_desired) > 0.1


def test_stroke_limit(front):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    t = ctl.settings.stroke_horizon_s
    q = kin.home.copy()
    q[2] = kin.limits.lower[2] + 0.02  # arm 20 mrad from full reach (tip far from the body: no damper acts)
    qd = np.array([0.0, 0.0, -0.4, 0.0])  # opening on: 40 mrad in the horizon at constant speed
    g = dyn.actuator_gains(q)
    assert _pump_flow(ctl, g, qd) < ctl.q_max  # the pumps are not what binds
    res = ctl.solve(q, qd, _hold_reference(kin, q, dyn, qd))  # keep the speed
    _check_eom(res)
    pred = q[2] + t * qd[2] + 0.5 * t * t * res.qdd[2]
    assert pred >= kin.limits.lower[2] - 1e-4
    assert pred <= kin.limits.lower[2] + 1e-3  # it binds
    tmin, tmax = dyn.torque_limits(g)
    assert np.all(res.tau <= tmax) and np.all(res.tau >= tmin)
    assert np.all(np.abs(qd + ctl.dt * res.qdd) <= ctl.speed_limits / np.abs(g) + 1e-6)
    assert np.linalg.norm(res.tip_accel - res.tip_accel_desired) > 0.1


def test_ground_damper(front):
    dyn, kin = front
    q = kin.home.copy()
    tip = kin.tip_position(q)
    settings = IdSettings(ground_min_z=float(tip[2]) - 0.1)  # the tip 0.1 m above the ground limit
    ctl = InverseDynamicsHQP(dyn, kin, settings)
    jac = dyn.tip_jacobian(q)
    task = np.vstack([jac, [0.0, 1.0, 1.0, 1.0]])
    qd = np.linalg.lstsq(task, [0.0, 0.0, -0.5, 0.0], rcond=None)[0]  # tip straight down at 0.5 m/s
    res = ctl.solve(q, qd, _hold_reference(kin, q, dyn, qd))  # and keep going
    _check_eom(res)
    s = settings
    d, d_dot = 0.1, -0.5
    beta = -(s.damper_xi / s.damper_horizon_s) * d / s.damper_influence - d_dot / s.damper_horizon_s
    assert res.tip_accel[2] >= beta - 1e-3 * abs(beta)
    assert res.tip_accel[2] <= beta + 1e-2 * abs(beta)  # it binds
    tmin, tmax = dyn.torque_limits(dyn.actuator_gains(q))
    assert np.all(res.tau <= tmax) and np.all(res.tau >= tmin)
    assert np.linalg.norm(res.tip_accel - res.tip_accel_desired) > 1.0


def _gravity_by_hand(dyn: FrontDynamics, q: np.ndarray) -> np.ndarray:
    """Hold torques from the link weights' moments about each joint axis (placements from forward kinematics)."""
    model, data = dyn.model, dyn.data
    pin.forwardKinematics(model, data, q)
    weights = []
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        com = data.oMi[j].act(inertia.lever)  # the link's centre of mass in base_link
        weights.append((com, np.array([0.0, 0.0, -9.81 * inertia.mass])))
    tau = np.zeros(4)
    for i in range(4):
        o, axis = data.oMi[i + 1].translation, data.oMi[i + 1].rotation[:, 2 if i == 0 else 1]
        moment = sum(np.cross(com - o, w) for com, w in weights[i:])
        tau[i] = -float(axis @ moment)  # the actuator balances the weights' moment
    return tau


@pytest.mark.parametrize("pose", [(0.3, -0.5, 1.65806, 0.5), (0.0, -1.0, 1.2, 0.0), (-1.0, -0.3, 1.5, 1.0)])
def test_static_hold_forces_match_gravity_load(front, pose):
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = np.array(pose)
    qd = np.zeros(4)
    res = ctl.solve(q, qd, IdReference(position=kin.tip_position(q), theta_w=kin.theta_w(q)))
    _check_eom(res)
    np.testing.assert_allclose(res.qdd, 0.0, atol=1e-6)
    tau = _gravity_by_hand(dyn, q)
    np.testing.assert_allclose(tau, pin.rnea(dyn.model, dyn.data, q, qd, qd), rtol=1e-9, atol=1e-6)
    machine = dyn.machine
    for i, cyl in enumerate(machine.cylinders.all, start=1):
        joint = machine.joints[i]
        plane = (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]
        dl_dq = (cylinder_length(cyl, *plane, q[i] + 1e-4) - cylinder_length(cyl, *plane, q[i] - 1e-4)) / 2e-4
        force = tau[i] / dl_dq
        assert res.force[i] == pytest.approx(force, rel=0.01), (joint.name, res.force[i], force)
    assert abs(res.tau[0]) < 1e-6  # swing: no gravity load on a level machine


def test_external_wrench_enters_the_eom(front):
    """Held still against a soil force (3-vector) and a wrench (force + moment at the tip): tau = g(q) - J^T F."""
    dyn, kin = front
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    qd = np.zeros(4)
    ref = IdReference(position=kin.tip_position(q), theta_w=kin.theta_w(q))
    dyn.update(q, qd)
    jac = dyn.tip()[1].copy()
    for f_ext in (np.array([-20e3, 0.0, 30e3]), np.array([-20e3, 1e3, 30e3, 0.0, 5e3, 0.0])):
        res = ctl.solve(q, qd, ref, f_ext)
        _check_eom(res)
        np.testing.assert_allclose(res.qdd, 0.0, atol=1e-6)
        np.testing.assert_allclose(res.tau, dyn.gravity(q) - jac[: f_ext.size].T @ f_ext, rtol=1e-6, atol=1e-3)
