"""The admittance drag (tms_rc.excavator.admittance): the law's sign and bounds, the resolved rates, the settings.

Fast, no ROS, no plant: a static pose of the ZX200's front, synthetic look-up tables.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_model.machines import load_machine
from tms_rc.excavator.admittance import (
    AdmittanceDrag,
    AdmittanceSettings,
    admittance_update,
    cut_axes,
    limit_blocked,
    load_force_control_settings,
    resolved_rates,
)
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    DirectionLut,
    PistonLut,
    cylinder_of,
    load_piston_settings,
)

Q = np.array([0.0, -0.23, 1.14, -0.24])  # the force_dig bench's flat-ground pose
LUT = PistonLut(DirectionLut((0.76, 1.5, 3.0), (0.0, 0.17, 0.49)), DirectionLut((0.74, 1.5, 3.0), (0.0, 0.32, 0.96)))
UP = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def front():
    return FrontDynamics(load_machine("zx200")), load_kinematics("zx200")


@pytest.fixture(scope="module")
def settings() -> AdmittanceSettings:
    return load_force_control_settings().admittance


def test_shipped_settings_load(settings) -> None:
    assert settings.admittance > 0.0 and settings.max_normal_speed > 0.0
    assert settings.depth_min < 0.0 < settings.depth_max


def test_too_little_force_goes_deeper_too_much_lifts(settings) -> None:
    dt = 0.01
    d, rate = admittance_update(0.0, 40e3, 20e3, settings, dt)
    assert rate > 0.0 and d > 0.0  # deeper
    assert rate == pytest.approx(settings.admittance * 20.0)
    d, rate = admittance_update(0.0, 20e3, 40e3, settings, dt)
    assert rate < 0.0 and d < 0.0  # lifts
    assert admittance_update(0.05, 30e3, 30e3, settings, dt) == (0.05, 0.0)


def test_admittance_saturates_in_speed_depth_and_deadband(settings) -> None:
    s = dataclasses.replace(settings, force_deadband=5.0)
    dt = 0.01
    _, rate = admittance_update(0.0, 1e7, 0.0, s, dt)
    assert rate == pytest.approx(s.max_normal_speed)
    _, rate = admittance_update(0.0, 0.0, 1e7, s, dt)
    assert rate == pytest.approx(-s.max_normal_speed)
    d, rate = admittance_update(s.depth_max, 1e7, 0.0, s, dt)
    assert d == s.depth_max and rate == 0.0  # held at the bound, no speed
    d, _ = admittance_update(s.depth_min + 1e-5, 0.0, 1e7, s, dt)
    assert d == s.depth_min
    assert admittance_update(0.0, 34e3, 30e3, s, dt) == (0.0, 0.0)  # within the deadband
    _, rate = admittance_update(0.0, 36e3, 30e3, s, dt)
    assert rate == pytest.approx(s.admittance * 1.0)  # the error beyond the band


def test_resolved_rates_meet_the_tip_velocity_and_theta_rate(front) -> None:
    dyn, _ = front
    jac = dyn.tip_jacobian(Q)[:, 1:]
    t = cut_axes(float(Q[0]), UP)
    v = -0.15 * t + np.array([0.0, 0.0, -0.02])
    rates = resolved_rates(jac, t, UP, v, 0.01)
    assert np.allclose(jac @ rates, v, atol=1e-9)
    assert float(np.sum(rates)) == pytest.approx(0.01)
    # a joint blocked: rate 0, the other two keep the tip's velocity (two rows, two unknowns), theta_w gives way
    blocked = resolved_rates(jac, t, UP, v, 0.01, theta_weight=1e-4, blocked=(2,))
    assert blocked[2] == 0.0
    assert np.allclose(jac @ blocked, v, atol=1e-5)
    # theta_w's weight trades its rate against the tip's: more weight, theta_w's rate nearer its reference
    light, heavy = (resolved_rates(jac, t, UP, v, 0.01, theta_weight=w, blocked=(2,)) for w in (0.1, 3.0))
    assert abs(np.sum(heavy) - 0.01) < abs(np.sum(light) - 0.01)


def test_limit_blocked_only_into_the_limit() -> None:
    lower, upper = np.array([-1.0, 0.5, -0.6]), np.array([-0.1, 2.7, 2.4])
    q = np.array([-0.12, 1.0, -0.59])
    assert limit_blocked(q, np.array([0.1, 0.1, -0.1]), lower, upper, 0.03) == (0, 2)
    assert limit_blocked(q, np.array([-0.1, 0.1, 0.1]), lower, upper, 0.03) == ()


def _drag(front, settings) -> AdmittanceDrag:
    dyn, kin = front
    luts = dict.fromkeys(CYLINDER_FUNCTIONS, LUT)
    s = dataclasses.replace(settings, filter_s=0.0, velocity_deadband=0.0)
    return AdmittanceDrag(dyn, kin, luts, load_piston_settings(), 5.0, s)


def _pressures(dyn, q, pressed_down: float) -> dict[str, tuple[float, float]]:
    """Chamber pressures [MPa] (cap, rod) whose cylinder forces hold the front pressing ``pressed_down`` [N]."""
    tau = dyn.gravity(q) + dyn.tip_jacobian(q).T @ np.array([0.0, 0.0, -pressed_down])
    gains = dyn.actuator_gains(q)
    out = {}
    for i, fn in enumerate(CYLINDER_FUNCTIONS, start=1):
        f = tau[i] / gains[i]
        c = cylinder_of(dyn.machine, fn)
        out[fn] = (f / c.cap_area / 1e6, 0.0) if f >= 0 else (0.0, -f / c.rod_area / 1e6)
    return out


def test_step_too_little_force_commands_the_edge_down(front, settings) -> None:
    dyn, kin = front
    ctl = _drag(front, settings)
    p = _pressures(dyn, Q, 10e3)
    ref = IdReference(position=dyn.tip_position(Q), theta_w=float(Q[1] + Q[2] + Q[3]) + kin.c_bucket)
    out = ctl.step(Q, np.zeros(4), p, ref, 40e3)
    assert out.f_est == pytest.approx(10e3, abs=300.0)  # the statics invert the pressures
    assert out.depth > 0.0 and out.v_tip[2] < 0.0  # deeper: the tip commanded down
    ctl.reset()
    out = ctl.step(Q, np.zeros(4), _pressures(dyn, Q, 60e3), ref, 40e3)
    assert out.depth < 0.0 and out.v_tip[2] > 0.0  # too much: up
    # the commanded piston speeds are the resolved rates through dl/dq
    gains = dyn.actuator_gains(Q)
    jac = dyn.tip_jacobian(Q)[:, 1:]
    rates = np.array([out.piston_speeds[fn] / gains[i] for i, fn in enumerate(CYLINDER_FUNCTIONS, start=1)])
    assert np.allclose(jac @ rates, out.v_tip, atol=2e-3)


def test_normal_gain_zero_is_damping_control(front, settings) -> None:
    """With no P along the normal the commanded normal speed is the admittance's alone, however far the tip is from
    its reference; along the cut the P acts."""
    dyn, kin = front
    ctl = _drag(front, dataclasses.replace(settings, normal_gain=0.0, path_gain=0.5))
    tip = dyn.tip_position(Q)
    t = cut_axes(float(Q[0]), UP)
    ref = IdReference(position=tip + 0.3 * UP + 0.1 * t, theta_w=float(Q[1] + Q[2] + Q[3]) + kin.c_bucket)
    out = ctl.step(Q, np.zeros(4), _pressures(dyn, Q, 10e3), ref, 40e3)
    assert float(out.v_tip @ UP) == pytest.approx(-out.depth_rate, abs=1e-6)
    assert float(out.v_tip @ t) == pytest.approx(0.05, abs=1e-6)


def test_refused_settings(tmp_path) -> None:
    good = load_force_control_settings()
    with pytest.raises(ValueError):
        dataclasses.replace(good.admittance, depth_min=0.2, depth_max=0.1)
    bad = tmp_path / "force_control.yaml"
    bad.write_text("admittance:\n  admittance: 0.0005\n  max_normal_speedd: 0.05\n")
    with pytest.raises(ConfigError, match=r"force_control.yaml:\d+"):
        load_force_control_settings(bad)
