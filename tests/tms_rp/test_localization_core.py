"""EKF + GNSS projection on synthetic trajectories (no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.tms_rp.synth import simulate
from tms_model.geometry import wrap_angle
from tms_rp.tracked.ekf import EkfParams, TrackedEkf


def _run(samples, *, outage=None, jump=None):
    ekf = TrackedEkf(EkfParams())
    errors, traces, results = [], [], []
    for s in samples:
        ekf.odometry(s.t, *s.odom)
        in_outage = outage is not None and outage[0] <= s.t < outage[1]
        if not in_outage:
            gx, gy = s.gnss
            if jump is not None and jump[0] <= s.t < jump[1]:
                gx += 5.0
            r = ekf.gnss(s.t, gx, gy)
            if jump is not None and jump[0] <= s.t < jump[1]:
                results.append(r)
        ekf.azimuth(s.t, s.azimuth)
        x, y, yaw = ekf.pose
        errors.append(math.hypot(x - s.truth[0], y - s.truth[1]))
        traces.append(float(np.trace(ekf.cov[:2, :2])))
    return ekf, np.array(errors), np.array(traces), results


def test_rms_under_5cm_with_2cm_gnss_noise_and_slip():
    samples = simulate(120.0, gnss_sigma=0.02, slip=0.04)
    _, errors, _, _ = _run(samples)
    rms = math.sqrt(float(np.mean(errors[10:] ** 2)))
    assert rms < 0.05, f"RMS {rms:.4f} m"


def test_outage_10s_error_bounded_and_covariance_grows():
    samples = simulate(60.0, gnss_sigma=0.02, slip=0.04)
    ekf, errors, traces, _ = _run(samples, outage=(20.0, 30.0))
    i0, i1 = 200, 299  # t = 20.0 s .. 29.9 s
    assert errors[i0:i1].max() < 0.5, f"max error during outage {errors[i0:i1].max():.3f} m"
    assert traces[i1 - 1] > 5.0 * traces[i0 - 1], "covariance did not grow during the outage"
    assert np.all(np.diff(traces[i0:i1]) >= -1e-12), "covariance must not shrink without GNSS"
    assert errors[i1 + 20:].max() < 0.1, "no recovery after the outage"


def test_5m_jump_is_rejected():
    samples = simulate(60.0)
    ekf, errors, _, results = _run(samples, jump=(30.0, 33.0))
    assert results and not any(r.accepted for r in results)
    assert min(r.mahalanobis2 for r in results) > ekf.params.gate_chi2
    assert errors[300:330].max() < 0.1
    assert ekf.stats.gnss_rejected == len(results)


def test_persistent_offset_reinitialises_after_timeout():
    samples = simulate(60.0)
    ekf, errors, _, _ = _run(samples, jump=(10.0, 60.0))
    assert ekf.stats.reinits >= 1
    assert errors[-1] > 4.0  # it now follows the (shifted) GNSS, as designed


def test_yaw_wraps_across_pi():
    ekf = TrackedEkf()
    ekf.azimuth(0.0, math.pi - 0.01)
    ekf.gnss(0.0, 0.0, 0.0)
    ekf.odometry(0.0, 0.0, 0.0, 0.0)
    r = ekf.azimuth(0.1, -math.pi + 0.01)
    assert r.accepted
    assert abs(wrap_angle(ekf.pose[2] - math.pi)) < 0.02


def test_map_to_odom_composes_back_to_pose():
    ekf = TrackedEkf()
    ekf.azimuth(0.0, 0.5)
    ekf.gnss(0.0, 10.0, 20.0)
    ekf.odometry(0.0, 1.0, 2.0, 0.2)
    ekf.odometry(0.1, 1.1, 2.05, 0.21)
    tx, ty, tyaw = ekf.map_to_odom()
    ox, oy, oyaw = 1.1, 2.05, 0.21
    c, s = math.cos(tyaw), math.sin(tyaw)
    x, y, yaw = ekf.pose
    assert (tx + c * ox - s * oy, ty + s * ox + c * oy) == pytest.approx((x, y), abs=1e-9)
    assert wrap_angle(tyaw + oyaw - yaw) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_inputs_raise(bad):
    ekf = TrackedEkf()
    with pytest.raises(ValueError, match="not finite"):
        ekf.gnss(0.0, bad, 0.0)
    with pytest.raises(ValueError, match="odometry x"):
        ekf.odometry(0.0, bad, 0.0, 0.0)


def test_bad_params_name_the_key():
    with pytest.raises(ValueError, match="gnss_sigma"):
        EkfParams(gnss_sigma=0.0)
    with pytest.raises(ValueError, match="unknown keys"):
        EkfParams.from_dict({"gnss_sigmaa": 0.1})


def test_estimate_drift_is_recovered_not_gated_forever():
    # The odometry over-reports motion by 40 % for 5 s (a stalled plant, heavy slip): the estimate runs
    # ahead; the GNSS stream stays continuous, so the filter must follow it back instead of rejecting it.
    samples = simulate(40.0)
    ekf = TrackedEkf(EkfParams())
    ox = oy = 0.0
    prev = None
    errors = []
    for s in samples:
        if prev is not None:
            dx, dy = s.odom[0] - prev[0], s.odom[1] - prev[1]
            f = 1.4 if 10.0 <= s.t < 15.0 else 1.0
            ox, oy = ox + f * dx, oy + f * dy
        prev = s.odom
        ekf.odometry(s.t, ox, oy, s.odom[2])
        ekf.gnss(s.t, *s.gnss)
        ekf.azimuth(s.t, s.azimuth)
        errors.append(math.hypot(ekf.pose[0] - s.truth[0], ekf.pose[1] - s.truth[1]))
    errors = np.array(errors)
    assert errors[160:].max() < 0.1, f"max error after the stall {errors[160:].max():.3f} m"
    assert ekf.stats.reinits == 0


@pytest.mark.parametrize("window", [2.0, 0.0])
def test_delayed_gnss_and_azimuth_are_carried_forward(window):
    """GNSS/azimuth stamped at t but delivered 0.4 s later (after newer odometry), as under CPU load or a relay.

    With the odometry history (``latency_window_s`` 2 s) the estimate stays on the truth; without it
    (window 0) the delayed fixes pull it back along the track by about speed x delay -- the case that the
    plant campaign showed before the history existed.
    """
    samples = simulate(120.0, gnss_sigma=0.02, slip=0.04)
    ekf = TrackedEkf(EkfParams(latency_window_s=window))
    delay = 4  # samples of 0.1 s
    errors = []
    for i, s in enumerate(samples):
        ekf.odometry(s.t, *s.odom)
        if i >= delay:
            old = samples[i - delay]
            ekf.gnss(old.t, *old.gnss)
            ekf.azimuth(old.t, old.azimuth)
        if not ekf.initialised:
            continue
        x, y, _ = ekf.pose
        errors.append(math.hypot(x - s.truth[0], y - s.truth[1]))
    rms = math.sqrt(float(np.mean(np.square(errors[20:]))))
    if window > 0:
        assert rms < 0.05, f"RMS {rms:.4f} m with 0.4 s delayed measurements"
    else:
        assert rms > 0.1, f"RMS {rms:.4f} m: the uncompensated case should show the delay"


def test_delayed_gnss_with_jump_recovers_after_the_jump():
    """GNSS delivered 0-0.4 s late (a starved relay) with a 5 m jump for 3 s: the jump is rejected and the
    good fixes after it are used again at once (no 10 s of dead reckoning until a re-initialisation)."""
    rng = np.random.default_rng(3)
    samples = simulate(60.0, dt=0.02, gnss_sigma=0.02, slip=0.05)
    ekf = TrackedEkf(EkfParams())
    pending, after = [], []
    for i, s in enumerate(samples):
        ekf.odometry(s.t, *s.odom)
        if i % 5 == 0:
            pending.append((s.t + rng.uniform(0.0, 0.4), s))
        for item in [p for p in pending if p[0] <= s.t]:
            pending.remove(item)
            old = item[1]
            gx, gy = old.gnss
            ekf.gnss(old.t, gx, gy + (5.0 if 36.0 <= old.t < 39.0 else 0.0))
        ekf.azimuth(s.t, s.azimuth)
        if 39.5 <= s.t < 45.0:
            x, y, _ = ekf.pose
            after.append(math.hypot(x - s.truth[0], y - s.truth[1]))
    assert max(after) < 0.1, f"after the jump: max error {max(after):.3f} m"
    assert ekf.stats.reinits == 0
    assert ekf.stats.gnss_rejected >= 25  # the 30 jumped fixes (10 Hz for 3 s), give or take the delay


def _heading_errors(params: EkfParams, *, odom_extra_turn: float, dropout=(10.0, 12.0), glitch=None):
    """Heading error [rad] per sample: during an azimuth dropout the odometry turns ``odom_extra_turn`` more than
    the machine (ramped in), so the estimate leaves the azimuth's gate; ``glitch`` = (t0, t1, rad) offsets the
    azimuth stream itself."""
    ekf = TrackedEkf(params)
    errors = []
    for s in simulate(30.0):
        extra = odom_extra_turn * min(max((s.t - dropout[0]) / (dropout[1] - dropout[0]), 0.0), 1.0)
        ox, oy, oyaw = s.odom
        ekf.odometry(s.t, ox, oy, wrap_angle(oyaw + extra))
        ekf.gnss(s.t, *s.gnss)
        if not dropout[0] <= s.t < dropout[1]:
            az = s.azimuth + (glitch[2] if glitch and glitch[0] <= s.t < glitch[1] else 0.0)
            ekf.azimuth(s.t, wrap_angle(az))
        errors.append(abs(wrap_angle(ekf.pose[2] - s.truth[2])))
    return ekf, np.array(errors)


def test_a_heading_off_the_azimuth_gate_is_recovered_not_gated_forever():
    """The fleet's stall: the estimate 0.34 rad (19.5 deg) off, every azimuth rejected from then on. With the
    recovery the azimuth stream (continuous: it turns as the odometry) is used again after 1 s."""
    trapped, err_trapped = _heading_errors(EkfParams(azimuth_recover_after_s=1e9), odom_extra_turn=0.34)
    assert err_trapped[-1] > 0.3 and trapped.stats.yaw_rejected > 100  # the trap, without the recovery
    ekf, errors = _heading_errors(EkfParams(), odom_extra_turn=0.34)
    assert ekf.stats.yaw_drift_recoveries >= 1
    i = 135  # t = 13.5 s: 1.5 s after the azimuth came back
    worst = math.degrees(errors[i:].max())
    assert worst < 1.0, f"heading error after the recovery {worst:.2f} deg"


def test_an_azimuth_glitch_is_rejected_not_taken_for_drift():
    """A 0.3 rad offset in the azimuth stream for 0.8 s (a compass glitch, shorter than azimuth_recover_after_s):
    rejected throughout, the estimate stays. (A steady offset held longer is taken for the estimate's drift.)"""
    ekf, errors = _heading_errors(EkfParams(), odom_extra_turn=0.0, glitch=(15.0, 15.8, 0.3))
    assert ekf.stats.yaw_drift_recoveries == 0 and ekf.stats.yaw_rejected >= 8
    assert errors[100:].max() < math.radians(1.0)
