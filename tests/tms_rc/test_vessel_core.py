"""VesselController (no ROS): success band, settle time, timeout, cancel, bad targets."""

from __future__ import annotations

import dataclasses
import math

import pytest

from tms_model.machines import load_machine
from tms_model.nav_files import load_nav_files
from tms_rc.carrier.vessel import VesselController, VesselError, VesselParams, VesselTuning

IC = load_machine("ic120")


def _params(**changes) -> VesselParams:
    """The IC120's vessel (65 deg, 0.3 rad/s) with its nav file's tuning."""
    tuning = load_nav_files(IC.kind).section(VesselTuning, "vessel")
    return dataclasses.replace(VesselParams.from_config(IC.vessel, tuning, f"{IC.source} vessel.max_angle"), **changes)


def _run(ctl, angle, target_rate=0.3, t_end=20.0, dt=0.05, cancel_at=None):
    t = 0.0
    while t < t_end:
        if cancel_at is not None and abs(t - cancel_at) < dt / 2:
            ctl.cancel(angle)
        step = ctl.step(angle, target_rate if step_moving(ctl, angle) else 0.0, t)
        if step.status != "RUNNING":
            return step, angle, t
        # first-order machine response towards the command, limited to the vessel rate
        delta = max(-target_rate * dt, min(target_rate * dt, step.command - angle))
        angle += delta
        t += dt
    return step, angle, t


def step_moving(ctl, angle):
    return ctl.target is not None and abs(ctl.target - angle) > 1e-3


def test_raise_within_two_degrees():
    ctl = VesselController(_params())
    ctl.start(math.radians(60), 0.0, 0.0)
    step, angle, t = _run(ctl, 0.0)
    assert step.status == "SUCCEEDED"
    assert abs(angle - math.radians(60)) < math.radians(2)
    assert t > math.radians(60) / 0.3 - 0.5  # could not finish before the vessel got there


def test_timeout_when_vessel_does_not_move():
    ctl = VesselController(_params(timeout_margin=1.0))
    ctl.start(1.0, 0.0, 0.0)
    t = 0.0
    while True:
        step = ctl.step(0.0, 0.0, t)
        if step.status != "RUNNING":
            break
        t += 0.1
    assert step.status == "FAILED" and "timeout" in step.message
    assert t == pytest.approx(1.0 / 0.3 + 1.0, abs=0.2)


def test_cancel_holds_current_angle():
    ctl = VesselController(_params())
    ctl.start(1.0, 0.0, 0.0)
    step, angle, _ = _run(ctl, 0.0, cancel_at=1.0)
    assert step.status == "CANCELED"
    assert ctl.target == pytest.approx(angle, abs=0.02)
    assert angle < 0.5


@pytest.mark.parametrize("bad", [-0.1, 1.2, float("nan")])
def test_bad_targets_name_value_and_range(bad):
    ctl = VesselController(_params())
    with pytest.raises(VesselError, match="target_angle"):
        ctl.start(bad, 0.0, 0.0)
    assert ctl.target is None
