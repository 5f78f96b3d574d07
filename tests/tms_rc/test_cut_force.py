"""The cut-force drag (tms_rc.excavator.cut_force): the depth law's sign, bounds and normal-force limit, the step,
the settings.

Fast, no ROS, no plant: a static pose of the ZX200's front, synthetic look-up tables.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.tms_rc.test_admittance import LUT, Q  # the force_dig bench's flat-ground pose, a piston table
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_model.machines import load_machine
from tms_rc.excavator.admittance import load_force_control_settings
from tms_rc.excavator.cut_force import CutForceDrag, CutForceSettings, cut_depth_update, load_cut_force_settings
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.force_control import contact_force_estimate
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    cylinder_of,
    load_piston_settings,
)

DT = 0.01


@pytest.fixture(scope="module")
def settings() -> CutForceSettings:
    return load_cut_force_settings()


@pytest.fixture
def pure(settings) -> CutForceSettings:
    """The integral alone (no feed-forward), a limit far away."""
    return dataclasses.replace(settings, ff_slope=0.0, normal_limit=1e6)


def test_shipped_settings_load_beside_the_admittance_section(settings) -> None:
    assert settings.force_ki > 0.0 and settings.max_depth_rate > 0.0
    assert settings.depth_min < 0.0 < settings.depth_max
    assert load_force_control_settings().admittance.admittance > 0.0  # the file's other section still loads


def test_too_little_tangential_force_deepens_too_much_lifts(pure) -> None:
    d, trim, rate = cut_depth_update(0.05, 0.05, 5e3, 3e3, 0.0, pure, DT)
    assert rate > 0.0 and d > 0.05 and trim > 0.05  # deeper
    assert rate == pytest.approx(pure.force_ki * 2.0)
    d, _, rate = cut_depth_update(0.05, 0.05, 3e3, 5e3, 0.0, pure, DT)
    assert rate < 0.0 and d < 0.05  # shallower
    assert cut_depth_update(0.05, 0.05, 4e3, 4e3, 0.0, pure, DT)[0] == pytest.approx(0.05)


def test_still_path_does_not_integrate(pure) -> None:
    assert cut_depth_update(0.05, 0.05, 5e3, 0.0, 0.0, pure, DT, moving=False) == (0.05, 0.05, 0.0)


def test_rate_and_depth_bounds_hold(pure) -> None:
    d, trim, rate = cut_depth_update(0.0, 0.0, 1e7, 0.0, 0.0, pure, DT)
    assert rate == pytest.approx(pure.max_depth_rate)
    d, trim, rate = cut_depth_update(0.0, 0.0, 0.0, 1e7, 0.0, pure, DT)
    assert rate == pytest.approx(-pure.max_depth_rate)
    d, trim = pure.depth_max, pure.depth_max
    for _ in range(100):
        d, trim, rate = cut_depth_update(d, trim, 1e7, 0.0, 0.0, pure, DT)
    assert d == pytest.approx(pure.depth_max) and trim == pytest.approx(pure.depth_max)  # no wind-up past it
    d, trim = pure.depth_min, pure.depth_min
    for _ in range(100):
        d, trim, rate = cut_depth_update(d, trim, 0.0, 1e7, 0.0, pure, DT)
    assert d == pytest.approx(pure.depth_min)
    # out of wind-up: one step of too little force moves it back at once
    d, trim, rate = cut_depth_update(d, trim, 1e7, 0.0, 0.0, pure, DT)
    assert rate == pytest.approx(pure.max_depth_rate)


def test_feed_forward_aims_at_the_depth_the_slope_implies(settings) -> None:
    s = dataclasses.replace(settings, ff_slope=0.2, force_ki=0.0, normal_limit=1e6)
    d, trim = 0.0, 0.0
    for _ in range(1000):
        d, trim, rate = cut_depth_update(d, trim, 2e3, 2e3, 0.0, s, DT)  # 2 kN at 0.2 kN/cm: 10 cm
        assert abs(rate) <= s.max_depth_rate + 1e-9
    assert d == pytest.approx(0.10)


def test_normal_limit_backs_off(settings) -> None:
    s = dataclasses.replace(settings, ff_slope=0.0)
    over = (s.normal_limit + 10.0) * 1e3
    d, trim, rate = cut_depth_update(0.1, 0.1, 1e7, 0.0, over, s, DT)  # much too little F_t, but pressing too hard
    assert rate == pytest.approx(-s.backoff_rate) and d < 0.1
    d, trim, rate = cut_depth_update(0.1, 0.1, 1e7, 0.0, over, s, DT, moving=False)
    assert rate == pytest.approx(-s.backoff_rate)
    d2, _, rate = cut_depth_update(d, trim, 1e7, 0.0, 0.0, s, DT)  # below the limit again: deeper
    assert rate > 0.0 and d2 > d


def test_step_estimates_along_the_cut_and_goes_deeper_on_too_little(settings) -> None:
    machine = load_machine("zx200")
    dyn, kin = FrontDynamics(machine), load_kinematics("zx200")
    piston = load_piston_settings()
    ctl = CutForceDrag(dyn, kin, dict.fromkeys(CYLINDER_FUNCTIONS, LUT), piston, 3.0,
                       dataclasses.replace(settings, ff_slope=0.0, filter_s=0.0))
    # cylinder forces holding the front against the soil pushing the bucket back towards the boom by 8 kN (the
    # resistance of a drag towards the machine: the bucket exerts +8 kN towards the machine)
    f_soil = np.array([8e3, 0.0, 0.0])  # the soil on the tip, outwards (+x at swing 0)
    torque = dyn.gravity(Q) - dyn.tip_jacobian(Q).T @ f_soil
    forces = torque[1:] / dyn.actuator_gains(Q)[1:]
    pressures = {}
    for k, fn in enumerate(CYLINDER_FUNCTIONS):
        cyl = cylinder_of(machine, fn)
        pressures[fn] = (max(forces[k], 0.0) / cyl.cap_area / 1e6, max(-forces[k], 0.0) / cyl.rod_area / 1e6)
    assert np.allclose(contact_force_estimate(dyn, Q, forces), -f_soil, atol=1.0)  # the statics it inverts
    tip = dyn.tip_position(Q)
    ref = IdReference(position=tip, velocity=np.array([-0.15, 0.0, 0.0]), theta_w=float(Q[1:].sum()) + kin.c_bucket)
    ctl.reset(0.0)
    out = ctl.step(Q, np.zeros(4), pressures, ref, 12e3)
    assert out.f_t == pytest.approx(8e3, rel=0.02)  # the bucket's force along its motion, from the pressures
    assert out.depth_rate > 0.0 and out.depth > 0.0  # 4 kN too little: deeper
    ctl.reset(0.0)
    out = ctl.step(Q, np.zeros(4), pressures, ref, 4e3)
    assert out.depth_rate < 0.0  # 4 kN too much: shallower


def test_bad_settings_refused_with_file_and_line(tmp_path, settings) -> None:
    with pytest.raises(ValueError, match="depth_min"):
        dataclasses.replace(settings, depth_min=0.2, depth_max=0.1)
    bad = tmp_path / "force_control.yaml"
    bad.write_text("cut_force:\n  force_ki: 0.005\n  max_depth_ratee: 0.05\n")
    with pytest.raises(ConfigError, match=r"force_control.yaml:3: cut_force.max_depth_ratee: unknown key"):
        load_cut_force_settings(bad)
    bad.write_text("cut_force:\n  force_ki: -1.0\n")
    with pytest.raises(ConfigError, match=r"force_control.yaml:2: cut_force.force_ki"):
        load_cut_force_settings(bad)
