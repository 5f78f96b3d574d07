"""Identification of an excavator's front hydraulics from recorded command / response time series (pure, no ROS).

What the arm controller needs of the machine it drives, estimated from what the machine reports on its bus:

* per joint, from velocity-command steps: the dead time (first response after the step) and first-order lag
  time constant (a first-order-plus-dead-time fit), the steady-state gain (steady joint speed / commanded
  speed), the saturated speed (largest steady speed reached, per direction) and the velocity dead band (the
  command offset below which the joint stays still: ``|v| = K (|u| - d)`` fitted over the unsaturated steps);
* the flow a joint draws per unit joint speed [L/min per rad/s] (the Hydraulic_Flow_Rate_1 flow into the drive:
  the cylinder's bottom side extending, its rod side retracting, the swing motor's inlet port; against the joint
  speed in the steady part of the steps, a fit through the origin, per direction);
* the total pump flow while boom, arm and bucket are commanded at once beyond what the pumps deliver;
* from a chirp, the -3 dB bandwidth (magnitude of the response relative to the steady-state gain).

:mod:`tms_rc.identify` records these over CAN and writes ``config/tms_rc/identified/<machine>.yaml``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "StepRecord",
    "StepFit",
    "JointEstimate",
    "fit_step",
    "estimate_joint",
    "flow_per_speed",
    "saturated_pump_flow",
    "chirp_bandwidth",
    "chirp_phase",
]

#: [rad/s] a joint whose steady speed stays below this did not move (COM3 speed LSB 0.0002 rad/s)
MOVING_SPEED = 0.003
#: fraction of a step's hold taken as its steady part (the end of the hold)
STEADY_FRACTION = 0.2
#: the first response: the speed beyond this fraction of its steady value
FIRST_RESPONSE = 0.02
#: steps at least this fraction of the saturated speed give the dead time and lag
WORKING_FRACTION = 0.2
#: steps whose steady speed is below this fraction of the saturated speed are in the linear range
LINEAR_FRACTION = 0.9


@dataclass(frozen=True)
class StepRecord:
    """One velocity-command step of one joint.

    ``t`` [s] sample times with 0 at the step (the command went from 0 to ``command``), ``speed`` [rad/s] the
    joint speed measured at those times, ``hold_s`` how long the command was held (``t`` may run past it),
    ``flow`` [L/min] the flow into the drive at the same times (None: not recorded).
    """

    joint: str
    command: float
    t: np.ndarray
    speed: np.ndarray
    hold_s: float
    flow: np.ndarray | None = None


@dataclass(frozen=True)
class StepFit:
    """First-order-plus-dead-time fit of one step: ``v(t) = steady (1 - exp(-(t - dead_time) / lag))``."""

    command: float
    moved: bool
    steady: float  # [rad/s] the fit's steady speed (not moved: the speed at the end of the hold)
    dead_time_s: float = math.nan
    lag_s: float = math.nan
    rms: float = math.nan  # [rad/s] residual of the fit


@dataclass(frozen=True)
class JointEstimate:
    """What the steps of one joint say about it."""

    joint: str
    dead_time_s: float
    lag_s: float
    gain: float  # steady speed / command in the linear range
    saturated_speed: tuple[float, float]  # [rad/s] (negative direction, positive direction), magnitudes
    dead_band: tuple[float, float]  # [rad/s] command offset (negative, positive direction)
    still_below: tuple[float, float]  # [rad/s] largest command amplitude tried that did not move it (0: none)
    fits: tuple[StepFit, ...]


def _window(rec: StepRecord) -> tuple[np.ndarray, np.ndarray]:
    keep = (rec.t >= 0.0) & (rec.t <= rec.hold_s + 1e-9)
    return rec.t[keep], rec.speed[keep]


def _steady(t: np.ndarray, y: np.ndarray, hold: float) -> float:
    tail = y[t >= (1.0 - STEADY_FRACTION) * hold]
    return float(np.median(tail)) if tail.size else float("nan")


def fit_step(rec: StepRecord, *, max_lag_s: float = 3.0) -> StepFit:
    """First-order-plus-dead-time fit of the hold part of ``rec`` (grid search, then least squares)."""
    t, y = _window(rec)
    if t.size < 5:
        raise ValueError(f"{rec.joint}: step {rec.command:+.4f} rad/s has {t.size} samples in its hold")
    steady = _steady(t, y, rec.hold_s)
    if not abs(steady) > MOVING_SPEED:
        return StepFit(rec.command, False, steady)
    # For given (dead time L, lag tau) the model is linear in its gain: solve that, search (L, tau) on a grid.
    dt = float(np.median(np.diff(t)))
    dead_grid = np.arange(0.0, rec.hold_s * 0.9, max(dt / 2.0, 1e-3))
    lag_grid = np.geomspace(max(dt / 5.0, 1e-3), max_lag_s, 120)
    best = (math.inf, 0.0, 0.0, 0.0)
    for dead in dead_grid:
        s = np.clip(t - dead, 0.0, None)
        g = 1.0 - np.exp(-s[None, :] / lag_grid[:, None])  # (lags, samples)
        den = np.einsum("ij,ij->i", g, g)
        k = np.where(den > 0, g @ y / np.where(den > 0, den, 1.0), 0.0)
        err = np.einsum("ij,ij->i", y[None, :] - k[:, None] * g, y[None, :] - k[:, None] * g)
        i = int(np.argmin(err))
        if err[i] < best[0]:
            best = (float(err[i]), float(dead), float(lag_grid[i]), float(k[i]))
    _, dead, lag, k = best
    # refine: golden-section-free local least squares on (L, tau, K)
    from scipy.optimize import least_squares

    def resid(p: np.ndarray) -> np.ndarray:
        d, tau, gain = p
        return y - gain * (1.0 - np.exp(-np.clip(t - d, 0.0, None) / max(tau, 1e-4)))

    sol = least_squares(resid, x0=[dead, lag, k], bounds=([0.0, 1e-4, -np.inf], [rec.hold_s, 10 * max_lag_s, np.inf]))
    dead, lag, k = (float(v) for v in sol.x)
    # The dead time is the first response: where the speed first passes FIRST_RESPONSE of the steady speed and stays
    # beyond it (a plant with more than one lag starts later than the fit's dead time says is possible; on a
    # dead-time + lag plant this is 2 % of a lag after the fit's). The lag is then refitted from there.
    thr = max(FIRST_RESPONSE * abs(k), MOVING_SPEED / 3.0)
    beyond = np.sign(k) * y > thr
    run = np.convolve(beyond.astype(int), np.ones(3, dtype=int), "valid") == 3  # three samples in a row
    if np.any(run):
        i = int(np.argmax(run))
        if i > 0:
            y0, y1 = np.sign(k) * y[i - 1], np.sign(k) * y[i]
            first = float(t[i - 1] + (thr - y0) / (y1 - y0) * (t[i] - t[i - 1])) if y1 > y0 else float(t[i])
        else:
            first = float(t[0])
        first = max(0.0, first - lag * math.log(1.0 / (1.0 - FIRST_RESPONSE)))

        def resid2(p: np.ndarray) -> np.ndarray:
            tau, gain = p
            return y - gain * (1.0 - np.exp(-np.clip(t - first, 0.0, None) / max(tau, 1e-4)))

        sol = least_squares(resid2, x0=[lag, k], bounds=([1e-4, -np.inf], [10 * max_lag_s, np.inf]))
        dead, (lag, k) = first, (float(v) for v in sol.x)
    rms = float(np.sqrt(np.mean(sol.fun**2)))
    # the fitted gain, not the tail's mean (a hold of a few lags ends a few per cent short of the steady speed),
    # but never beyond the fastest speed measured: a response the model does not describe (an acceleration-limited
    # swing) can fit a gain it never reaches
    top = float(np.max(np.sign(k) * y))
    return StepFit(rec.command, True, math.copysign(min(abs(k), max(top, 0.0)), k), dead, lag, rms)


def _linear_fit(amp: np.ndarray, speed: np.ndarray) -> tuple[float, float]:
    """(gain K, dead band d) of ``speed = K (amp - d)`` (amplitudes and speeds as magnitudes)."""
    if amp.size == 1:
        return float(speed[0] / amp[0]), 0.0
    a = np.vstack([amp, np.ones_like(amp)]).T
    (k, c), *_ = np.linalg.lstsq(a, speed, rcond=None)
    return float(k), float(-c / k) if k != 0 else 0.0


def estimate_joint(records: Sequence[StepRecord]) -> JointEstimate:
    """Dead time, lag, gain, saturated speeds and dead band of one joint from its steps (both directions).

    Dead time and lag are the medians over the moving steps in the working range: unsaturated (a saturated step's
    rise is clipped, which shortens the apparent lag) and at least WORKING_FRACTION of the saturated speed.
    """
    if not records:
        raise ValueError("estimate_joint: no steps")
    joint = records[0].joint
    fits = tuple(fit_step(r) for r in records)
    sat: list[float] = []
    band: list[float] = []
    still: list[float] = []
    gains: list[float] = []
    linear_fits: list[StepFit] = []
    for sign in (-1.0, 1.0):
        mine = [f for f in fits if f.command * sign > 0]
        moving = [f for f in mine if f.moved and f.steady * sign > 0]
        if not moving:
            raise ValueError(f"{joint}: no step in the {'+' if sign > 0 else '-'} direction moved the joint "
                             f"(commands {[f.command for f in mine]})")
        top = max(abs(f.steady) for f in moving)
        sat.append(top)
        # a step at or beyond the smallest command that saturated is saturated too, even when it came out slower
        # (a bucket curl commanded at 150 % reached 0.52 rad/s against the 100 % step's 0.59: counted as linear,
        # it pulled the fitted gain to 0.64)
        saturating = min((abs(f.command) for f in moving if abs(f.steady) >= LINEAR_FRACTION * top),
                         default=math.inf)
        linear = [f for f in moving if abs(f.command) < saturating] or moving
        linear_fits.extend(linear)
        amp = np.array([abs(f.command) for f in linear])
        spd = np.array([abs(f.steady) for f in linear])
        k, d = _linear_fit(amp, spd)
        lo = max((abs(f.command) for f in mine if not f.moved), default=0.0)
        hi = min(abs(f.command) for f in moving)
        band.append(min(max(d, lo, 0.0), hi))
        still.append(lo)
        gains.append(k)
    # Dead time and lag of the working range: a hydraulic drive starts later on a small command (the chambers
    # take longer to reach the load pressure on a small flow); the small steps serve the dead band only.
    working = [f for f in linear_fits if abs(f.steady) >= WORKING_FRACTION * sat[f.command > 0]] or linear_fits
    # a step the dead-time + lag model does not describe (residual above a tenth of its speed: the joint was not
    # at rest when it began, say) is left out
    working = [f for f in working if f.rms <= 0.1 * abs(f.steady)] or working
    dead = float(np.median([f.dead_time_s for f in working]))
    lag = float(np.median([f.lag_s for f in working]))
    return JointEstimate(joint, dead, lag, float(np.mean(gains)), (sat[0], sat[1]), (band[0], band[1]),
                         (still[0], still[1]), fits)


def flow_per_speed(records: Sequence[StepRecord]) -> float:
    """[L/min per rad/s] the flow a joint draws per unit speed: a fit through the origin of ``|flow|`` on ``|speed|``
    over the steady part of every moving step of ``records`` (0 when no flow was recorded)."""
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    for r in records:
        if r.flow is None:
            continue
        keep = (r.t >= (1.0 - STEADY_FRACTION) * r.hold_s) & (r.t <= r.hold_s) & (np.abs(r.speed) > MOVING_SPEED)
        xs.append(np.abs(r.speed[keep]))
        ys.append(np.abs(r.flow[keep]))
    if not xs:
        return 0.0
    x, y = np.concatenate(xs), np.concatenate(ys)
    den = float(x @ x)
    return float(x @ y / den) if den > 0 else 0.0


def saturated_pump_flow(t: np.ndarray, total_flow: np.ndarray, *, window_s: float = 0.2) -> float:
    """[L/min] the largest total flow held for ``window_s`` (a running median: one bad frame does not count)."""
    t, f = np.asarray(t, float), np.asarray(total_flow, float)
    if t.size < 2:
        raise ValueError("saturated_pump_flow: fewer than two samples")
    dt = float(np.median(np.diff(t)))
    n = max(1, int(round(window_s / dt)))
    if f.size < n:
        return float(np.median(f))
    windows = np.lib.stride_tricks.sliding_window_view(f, n)
    return float(np.max(np.median(windows, axis=1)))


def chirp_phase(t: np.ndarray | float, f0: float, f1: float, duration: float) -> np.ndarray | float:
    """Phase [rad] of a logarithmic chirp from ``f0`` to ``f1`` Hz over ``duration`` s."""
    k = math.log(f1 / f0) / duration
    return 2.0 * math.pi * f0 * (np.exp(k * np.asarray(t)) - 1.0) / k


def chirp_bandwidth(t: np.ndarray, command: np.ndarray, speed: np.ndarray, *, f0: float, f1: float,
                    gain: float = 1.0, bins_per_decade: int = 20) -> tuple[float, np.ndarray]:
    """(-3 dB bandwidth [Hz], response table) of a joint driven with a chirp from ``f0`` to ``f1`` Hz.

    The frequency response is the ratio of the response's and the command's spectra over the whole record
    (the chirp puts energy at every frequency of the sweep), averaged in log-spaced bins; its magnitude over
    ``gain`` (the steady-state gain of the steps) is the gain relative to the steady state. A dead time turns
    the phase only. The table's rows are (frequency [Hz], relative magnitude); the bandwidth is interpolated in
    log frequency where it first drops below 1/sqrt(2), NaN when it never does within the sweep. ``t`` evenly
    spaced; the record should run on after the chirp until the joint rests.
    """
    t, u, y = (np.asarray(a, float) for a in (t, command, speed))
    dt = float(np.median(np.diff(t)))
    freqs = np.fft.rfftfreq(t.size, dt)
    uf, yf = np.fft.rfft(u - np.mean(u)), np.fft.rfft(y - np.mean(y))
    edges = np.geomspace(f0 * 1.1, f1 / 1.1, max(2, int(bins_per_decade * math.log10(f1 / f0 / 1.21)) + 1))
    rows: list[tuple[float, float]] = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (freqs >= lo) & (freqs < hi)
        if not np.any(m):
            continue
        # H = sum(Y U*) / sum(|U|^2) within the bin: the cross spectrum keeps noise uncorrelated with the input out
        h = np.sum(yf[m] * np.conj(uf[m])) / np.sum(np.abs(uf[m]) ** 2)
        rows.append((math.sqrt(lo * hi), abs(h) / gain))
    table = np.array(rows) if rows else np.zeros((0, 2))
    limit = 1.0 / math.sqrt(2.0)
    for i in range(1, len(rows)):
        (fa, ma), (fb, mb) = rows[i - 1], rows[i]
        if ma >= limit > mb:
            w = (ma - limit) / (ma - mb)
            return float(math.exp(math.log(fa) + w * (math.log(fb) - math.log(fa)))), table
    return float("nan"), table
