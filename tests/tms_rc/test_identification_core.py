"""The identification core on synthetic signals with known answers (no ROS, no plant)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_rc.identification import (
    StepRecord,
    chirp_bandwidth,
    chirp_phase,
    estimate_joint,
    fit_step,
    flow_per_speed,
    saturated_pump_flow,
)

DT = 0.01


def _simulate(u: np.ndarray, *, dead: float, tau: float, gain: float = 1.0, band: float = 0.0,
              limit: float = math.inf, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """A valve with a dead band and a gain, a velocity limit, a dead time and a first-order lag, per 10 ms step."""
    rng = np.random.default_rng(seed)
    n_dead = round(dead / DT)
    alpha = 1.0 - math.exp(-DT / tau)
    v, out = 0.0, []
    eff = np.sign(u) * np.clip(np.abs(u) - band, 0.0, None) * gain
    eff = np.clip(eff, -limit, limit)
    for k in range(len(u)):
        delayed = eff[k - n_dead] if k >= n_dead else 0.0
        v += (delayed - v) * alpha
        out.append(v)
    return np.array(out) + rng.normal(0.0, noise, len(u))


def _step(joint: str, cmd: float, hold: float = 3.0, **plant) -> StepRecord:
    n = int(round((hold + 1.0) / DT))
    t = np.arange(n) * DT
    u = np.where(t < hold, cmd, 0.0)
    return StepRecord(joint, cmd, t, _simulate(u, **plant), hold)


def test_a_step_gives_the_dead_time_and_lag_it_was_made_with():
    fit = fit_step(_step("boom_joint", 0.2, dead=0.65, tau=0.25, noise=0.001))
    assert fit.moved
    assert fit.dead_time_s == pytest.approx(0.65, abs=0.011)
    assert fit.lag_s == pytest.approx(0.25, rel=0.05)
    assert fit.steady == pytest.approx(0.2, rel=0.01)


def test_a_step_inside_the_dead_band_does_not_move_the_joint():
    fit = fit_step(_step("arm_joint", 0.02, dead=0.4, tau=0.2, band=0.05))
    assert not fit.moved


def test_joint_estimate_gain_saturation_and_dead_band():
    plant = {"dead": 0.43, "tau": 0.2, "gain": 0.9, "band": 0.04, "limit": 0.8}
    amps = [0.02, 0.06, 0.1, 0.3, 0.5, 1.2]
    recs = [_step("arm_joint", s * a, **plant, noise=0.0005, seed=i) for i, a in enumerate(amps) for s in (1, -1)]
    est = estimate_joint(recs)
    assert est.dead_time_s == pytest.approx(0.43, abs=0.015)
    assert est.lag_s == pytest.approx(0.2, rel=0.08)
    assert est.gain == pytest.approx(0.9, rel=0.03)
    assert est.saturated_speed == pytest.approx((0.8, 0.8), rel=0.01)
    assert est.dead_band == pytest.approx((0.04, 0.04), abs=0.005)
    assert est.still_below == (0.02, 0.02)  # the smallest step stayed inside the band


def test_a_step_beyond_saturation_that_came_out_slower_does_not_enter_the_gain():
    plant = {"dead": 0.31, "tau": 0.15, "limit": 0.58}
    amps = (0.05, 0.1, 0.3, 0.87)
    recs = [_step("bucket_joint", s * a, **plant, seed=i) for i, a in enumerate(amps) for s in (1, -1)]
    # the 150 % step met more load than the 100 % one and ran slower than the saturated speed
    recs += [_step("bucket_joint", s * 1.32, dead=0.31, tau=0.15, limit=0.52) for s in (1, -1)]
    est = estimate_joint(recs)
    assert est.gain == pytest.approx(1.0, rel=0.02)
    assert est.saturated_speed == pytest.approx((0.58, 0.58), rel=0.01)


def test_no_dead_band_gives_zero():
    recs = [_step("bucket_joint", s * a, dead=0.31, tau=0.15) for a in (0.02, 0.1, 0.5) for s in (1, -1)]
    est = estimate_joint(recs)
    assert est.dead_band == pytest.approx((0.0, 0.0), abs=1e-3)
    assert est.gain == pytest.approx(1.0, rel=0.01)


def test_a_joint_that_never_moves_is_an_error_naming_it():
    recs = [_step("swing_joint", s * 0.01, dead=0.9, tau=0.35, band=0.1) for s in (1, -1)]
    with pytest.raises(ValueError, match="swing_joint: no step in the - direction moved"):
        estimate_joint(recs)


def test_flow_per_speed_from_the_drive_flow_quantised_to_8_l_per_min():
    coef = 300.0 / 0.45  # L/min per rad/s
    recs = []
    for a in (0.1, 0.2, 0.3, 0.45):
        r = _step("boom_joint", a, dead=0.65, tau=0.25)
        flow = np.round(coef * np.abs(r.speed) / 8.0) * 8.0  # the COM3 frame's 8 L/min resolution
        recs.append(StepRecord(r.joint, r.command, r.t, r.speed, r.hold_s, flow))
    assert flow_per_speed(recs) == pytest.approx(coef, rel=0.02)
    assert flow_per_speed([_step("swing_joint", 0.3, dead=0.9, tau=0.35)]) == 0.0  # no flow recorded


def test_saturated_pump_flow_ignores_a_single_bad_frame():
    t = np.arange(400) * DT
    flow = np.where(t > 1.0, 424.0, 200.0)
    flow[300] = 900.0
    assert saturated_pump_flow(t, flow) == pytest.approx(424.0)


@pytest.mark.parametrize("tau", [0.15, 0.35])
def test_chirp_bandwidth_of_a_first_order_lag_is_its_corner_frequency(tau):
    f0, f1, dur, amp, dead = 0.1, 4.0, 30.0, 0.3, 0.6
    t = np.arange(int((dur + dead + 1) / DT)) * DT
    u = np.where(t < dur, amp * np.sin(chirp_phase(np.minimum(t, dur), f0, f1, dur)), 0.0)
    y = _simulate(u, dead=dead, tau=tau, gain=0.95, noise=0.001)
    bw, table = chirp_bandwidth(t, u, y, f0=f0, f1=f1, gain=0.95)
    # 1/(2 pi tau) for the continuous lag; the 10 ms discretisation shifts it by < 1 %
    assert bw == pytest.approx(1.0 / (2.0 * math.pi * tau), rel=0.06)
    assert table[0, 1] == pytest.approx(1.0, abs=0.05)  # low frequencies pass at the steady-state gain
