"""EKF localisation of a tracked machine in the map frame: track odometry + GNSS position (+ azimuth).

State ``[x, y, yaw, k]`` in ``map`` (REP-105), ``k`` being the odometry scale error (track slip: the
machine moves ``(1 + k)`` times what the tracks report). Odometry is used as a *relative* motion: the pose
change between two consecutive ``odom``-frame poses is expressed in the body frame, scaled by ``1 + k`` and
applied to the estimate, with process noise proportional to the distance driven and the angle turned plus
a small time-based random walk. Learning ``k`` while GNSS is good keeps a GNSS outage's drift small. GNSS fixes (already
projected to the map frame) and azimuths correct the state
through filterpy's :class:`~filterpy.kalman.ExtendedKalmanFilter`; a measurement whose squared Mahalanobis
distance exceeds the chi-square gate is rejected (a 5 m multipath jump), and after ``reinit_after_s`` of
nothing but rejections the filter re-initialises on GNSS (the estimate, not the fix, was wrong).

Gating alone cannot tell a GNSS jump from an estimate that drifted (odometry slipping far beyond its
model): both give a large innovation, and rejecting a correct GNSS stream lets the drift run on. So each
fix is also checked for *continuity*: the step from the previous fix must match the odometry step within
``jump_threshold`` + 50 % of the step. A gated-out fix whose stream has been continuous since the last
accepted fix means the estimate drifted: the position covariance is inflated by the innovation and the
fix is used. A discontinuous step (a jump) keeps the stream rejected until it agrees with the estimate again,
or until it is continuous again and within ``jump_threshold`` of the estimate (after a jump ends, the estimate
may have drifted a few centimetres beyond the gate while dead-reckoning; a 5 m offset never qualifies).

The azimuth has the same trap: a heading estimate a few degrees off lies outside the azimuth's tight gate,
every azimuth is rejected from then on, and nothing but odometry moves the heading again (in the fleet run a
carrier's estimate stood 19.5 degrees off its IMU for 1000 s, and the carrier stopped that far off its loading
heading).
So azimuths rejected for ``azimuth_recover_after_s`` in a row, while their stream turned as the odometry did
(each step within ``azimuth_jump_threshold`` of the odometry's turn: no sensor glitch), mean the estimate
drifted: the heading variance is inflated by the innovation and the azimuth is used.

Latency: a GNSS fix or azimuth stamped at ``t`` may arrive after odometry stamped later than ``t`` (DDS
delivery order, a relay, a loaded CPU). Applied as is, it would pull the estimate back along the track by
speed x delay. So the filter keeps the last ``latency_window_s`` of odometry poses and moves such a
measurement forward to the latest odometry time with the odometry motion since ``t`` (scaled by ``1 + k``,
rotated into map): a delayed measurement then corrects the current state, not a past one.

The map->odom transform (what a TF broadcaster would publish) is ``map_T_base * inv(odom_T_base)``.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from tms_model.geometry import wrap_angle

__all__ = ["EkfParams", "TrackedEkf", "UpdateResult"]

LOGGER = logging.getLogger(__name__)


@dataclass(frozen=True)
class EkfParams:
    """Noise and gating parameters (the nav file's ``localization``)."""

    gnss_sigma: float = 0.02
    azimuth_sigma: float = 0.01
    odom_slip: float = 0.05
    odom_yaw_slip: float = 0.02
    odom_drift_xy: float = 0.002
    scale_sigma: float = 0.1
    scale_walk: float = 0.002
    gate_chi2: float = 13.8
    gate_chi2_yaw: float = 10.8
    reinit_after_s: float = 10.0
    jump_threshold: float = 0.5
    initial_yaw_sigma: float = 0.5
    latency_window_s: float = 2.0
    azimuth_recover_after_s: float = 1.0
    azimuth_jump_threshold: float = 0.05

    def __post_init__(self) -> None:
        for name in (
            "gnss_sigma",
            "azimuth_sigma",
            "gate_chi2",
            "gate_chi2_yaw",
            "initial_yaw_sigma",
            "jump_threshold",
            "azimuth_jump_threshold",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"localization.{name} must be > 0, got {value!r}")
        for name in ("odom_slip", "odom_yaw_slip", "odom_drift_xy", "reinit_after_s", "scale_sigma", "scale_walk",
                     "latency_window_s", "azimuth_recover_after_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"localization.{name} must be >= 0, got {value!r}")

    @classmethod
    def from_dict(cls, d: dict) -> EkfParams:
        """Build from the ``localization`` section; unknown keys (other than geodetic_crs) are an error."""
        known = set(cls.__dataclass_fields__)
        extra = set(d) - known - {"geodetic_crs"}
        if extra:
            raise ValueError(f"localization: unknown keys {sorted(extra)}; known: {sorted(known)}")
        return cls(**{k: float(v) for k, v in d.items() if k in known})


@dataclass
class UpdateResult:
    """Outcome of one measurement: accepted or not, and its squared Mahalanobis distance."""

    accepted: bool
    mahalanobis2: float
    reinitialised: bool = False


@dataclass
class _Stats:
    gnss_accepted: int = 0
    gnss_rejected: int = 0
    yaw_accepted: int = 0
    yaw_rejected: int = 0
    reinits: int = 0
    gnss_drift_recoveries: int = 0
    yaw_drift_recoveries: int = 0
    last: dict = field(default_factory=dict)


class TrackedEkf:
    """The filter. Feed :meth:`odometry`, :meth:`gnss`, :meth:`azimuth`; read :attr:`pose` and :attr:`cov`.

    Times are seconds on any monotonic clock shared by the three inputs (message stamps or sim time).
    """

    def __init__(self, params: EkfParams | None = None) -> None:
        self.params = params or EkfParams()
        self._kf = ExtendedKalmanFilter(dim_x=4, dim_z=2)
        self.initialised = False
        self._last_odom: tuple[float, float, float] | None = None
        self._last_odom_t: float | None = None
        self._yaw_known = False
        self._reject_since: float | None = None
        self._pending_yaw: tuple[float, float] | None = None
        self._last_fix: tuple[float, float, tuple[float, float, float] | None] | None = None
        self._chain_ok = True
        self._yaw_reject_since: float | None = None
        self._last_az: tuple[float, float] | None = None  # (azimuth, odometry yaw when it was measured)
        self._odom_hist: deque[tuple[float, float, float, float]] = deque()  # (t, x, y, yaw) in odom
        self.stats = _Stats()

    # --- state ---------------------------------------------------------------------------------
    @property
    def pose(self) -> tuple[float, float, float]:
        """Estimated (x, y, yaw) in map."""
        x = self._kf.x
        return float(x[0]), float(x[1]), float(x[2])

    @property
    def cov(self) -> np.ndarray:
        """3x3 covariance of (x, y, yaw)."""
        return self._kf.P[:3, :3].copy()

    @property
    def odom_scale(self) -> float:
        """Estimated odometry scale error ``k`` (true distance = (1 + k) x reported)."""
        return float(self._kf.x[3])

    def map_to_odom(self) -> tuple[float, float, float]:
        """Transform map->odom as (x, y, yaw): the correction REP-105 puts between the two frames."""
        if self._last_odom is None:
            return 0.0, 0.0, 0.0
        mx, my, myaw = self.pose
        ox, oy, oyaw = self._last_odom
        yaw = wrap_angle(myaw - oyaw)
        c, s = math.cos(yaw), math.sin(yaw)
        return mx - (c * ox - s * oy), my - (s * ox + c * oy), yaw

    # --- inputs --------------------------------------------------------------------------------
    def odometry(self, t: float, x: float, y: float, yaw: float) -> None:
        """An odom-frame pose of base_link at time ``t``: predicts with the increment since the last one."""
        for name, v in (("t", t), ("x", x), ("y", y), ("yaw", yaw)):
            if not math.isfinite(v):
                raise ValueError(f"odometry {name} is not finite: {v!r}")
        self._remember_odom(t, x, y, yaw)
        if self._last_odom is None or not self.initialised:
            self._last_odom, self._last_odom_t = (x, y, yaw), t
            return
        px, py, pyaw = self._last_odom
        c, s = math.cos(pyaw), math.sin(pyaw)
        dxw, dyw = x - px, y - py
        dx, dy = c * dxw + s * dyw, -s * dxw + c * dyw  # increment in the previous body frame
        dyaw = wrap_angle(yaw - pyaw)
        dt = max(0.0, t - (self._last_odom_t if self._last_odom_t is not None else t))
        self._last_odom, self._last_odom_t = (x, y, yaw), t
        self._predict(dx, dy, dyaw, dt)

    def _remember_odom(self, t: float, x: float, y: float, yaw: float) -> None:
        hist = self._odom_hist
        if hist and t < hist[-1][0]:  # clock went back (restart, sim reset): the old history is meaningless
            hist.clear()
        hist.append((t, x, y, yaw))
        while len(hist) > 2 and hist[0][0] < t - self.params.latency_window_s:
            hist.popleft()

    def _odom_since(self, t: float) -> tuple[float, float, float] | None:
        """Odometry motion (dx, dy in odom axes, dyaw) from time ``t`` to the latest odometry, or None.

        None when ``t`` is not older than the latest odometry (nothing to compensate) or there is no history;
        a ``t`` older than the window uses the oldest pose kept (partial compensation).
        """
        hist = self._odom_hist
        if len(hist) < 2 or self._last_odom is None or t >= hist[-1][0]:
            return None
        ts = [h[0] for h in hist]
        i = bisect.bisect_left(ts, t)
        if i == 0:
            _, x0, y0, a0 = hist[0]
        else:
            (t0, xa, ya, aa), (t1, xb, yb, ab) = hist[i - 1], hist[i]
            f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
            x0, y0, a0 = xa + f * (xb - xa), ya + f * (yb - ya), aa + f * wrap_angle(ab - aa)
        _, x1, y1, a1 = hist[-1]
        return x1 - x0, y1 - y0, wrap_angle(a1 - a0)

    def _predict(self, dx: float, dy: float, dyaw: float, dt: float) -> None:
        p = self.params
        kf = self._kf
        th = float(kf.x[2])
        k = float(kf.x[3])
        c, s = math.cos(th), math.sin(th)
        wx, wy = c * dx - s * dy, s * dx + c * dy  # reported increment in map axes
        kf.x = np.array([kf.x[0] + (1 + k) * wx, kf.x[1] + (1 + k) * wy, wrap_angle(th + dyaw), k])
        jac = np.array([
            [1.0, 0.0, -(1 + k) * wy, wx],
            [0.0, 1.0, (1 + k) * wx, wy],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ])
        dist = math.hypot(dx, dy)
        sig_xy2 = (p.odom_slip * dist) ** 2 + p.odom_drift_xy**2 * dt
        sig_yaw2 = (p.odom_yaw_slip * abs(dyaw)) ** 2 + (0.001 * dist) ** 2 + 1e-8 * dt
        q = np.diag([sig_xy2, sig_xy2, sig_yaw2, (p.scale_walk * dist) ** 2])
        kf.P = jac @ kf.P @ jac.T + q
        kf.P = 0.5 * (kf.P + kf.P.T)

    def gnss(self, t: float, x: float, y: float, sigma: float | None = None) -> UpdateResult:
        """A GNSS fix projected to map (x, y) [m] with 1-sigma ``sigma`` (default ``gnss_sigma``)."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"GNSS fix is not finite: x={x!r} y={y!r}")
        sig = self.params.gnss_sigma if sigma is None or not math.isfinite(sigma) or sigma <= 0 else sigma
        r = np.eye(2) * sig**2
        if not self.initialised:
            self._initialise(x, y, r)
            return UpdateResult(True, 0.0, reinitialised=False)
        moved = self._odom_since(t)
        if moved is not None:  # a delayed fix: carry it forward with the odometry motion since its stamp
            _, _, rot = self.map_to_odom()
            c, s = math.cos(rot), math.sin(rot)
            k = 1.0 + float(self._kf.x[3])
            x, y = x + k * (c * moved[0] - s * moved[1]), y + k * (s * moved[0] + c * moved[1])
        z = np.array([x, y])
        h = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
        innov = z - self._kf.x[:2]
        s_mat = h @ self._kf.P @ h.T + r
        d2 = float(innov @ np.linalg.solve(s_mat, innov))
        continuous = self._fix_continuous(x, y)
        self._last_fix = (x, y, self._last_odom)
        if d2 > self.params.gate_chi2 and continuous and (
                self._chain_ok or math.hypot(*innov) < self.params.jump_threshold):
            # The fixes move as the odometry says (no jump since the last accepted fix), yet disagree with
            # the estimate: the estimate drifted (slip beyond the model, a stalled plant). Inflate P along
            # the innovation so the update is consistent instead of rejecting GNSS for good.
            self._kf.P[:2, :2] += np.outer(innov, innov)
            self.stats.gnss_drift_recoveries += 1
            d2 = float(innov @ np.linalg.solve(h @ self._kf.P @ h.T + r, innov))
        if not continuous:
            self._chain_ok = False
        if d2 > self.params.gate_chi2:
            self.stats.gnss_rejected += 1
            if self._reject_since is None:
                self._reject_since = t
            if self.params.reinit_after_s > 0 and t - self._reject_since >= self.params.reinit_after_s:
                LOGGER.warning("GNSS rejected for %.1f s: re-initialising on the fix", t - self._reject_since)
                self._initialise(x, y, r, keep_yaw=True)
                self.stats.reinits += 1
                return UpdateResult(True, d2, reinitialised=True)
            return UpdateResult(False, d2)
        self._reject_since = None
        self._chain_ok = True
        self._kf.update(z, lambda _x: h, lambda xs: xs[:2], R=r)
        self._kf.x[2] = wrap_angle(float(self._kf.x[2]))
        self.stats.gnss_accepted += 1
        return UpdateResult(True, d2)

    def _fix_continuous(self, x: float, y: float) -> bool:
        """True if the step from the previous fix matches the odometry step (no GNSS jump in between)."""
        if self._last_fix is None or self._last_fix[2] is None or self._last_odom is None:
            return True
        fx, fy, (ox0, oy0, _) = self._last_fix
        ox1, oy1, _ = self._last_odom
        _, _, rot = self.map_to_odom()
        c, s = math.cos(rot), math.sin(rot)
        k = 1.0 + float(self._kf.x[3])
        dxo, dyo = k * (c * (ox1 - ox0) - s * (oy1 - oy0)), k * (s * (ox1 - ox0) + c * (oy1 - oy0))
        mismatch = math.hypot((x - fx) - dxo, (y - fy) - dyo)
        return mismatch <= self.params.jump_threshold + 0.5 * math.hypot(dxo, dyo)

    def azimuth(self, t: float, yaw: float, sigma: float | None = None) -> UpdateResult:
        """An absolute heading (ENU yaw, rad) from the GNSS compass / IMU."""
        if not math.isfinite(yaw):
            raise ValueError(f"azimuth is not finite: {yaw!r}")
        sig = self.params.azimuth_sigma if sigma is None or not math.isfinite(sigma) or sigma <= 0 else sigma
        if not self.initialised:
            self._pending_yaw = (yaw, sig)
            return UpdateResult(True, 0.0)
        if not self._yaw_known:
            self._kf.x[2] = wrap_angle(yaw)
            self._kf.P[2, :] = 0.0
            self._kf.P[:, 2] = 0.0
            self._kf.P[2, 2] = sig**2
            self._yaw_known = True
            return UpdateResult(True, 0.0)
        moved = self._odom_since(t)
        if moved is not None:  # a delayed azimuth: add the turn since its stamp
            yaw = wrap_angle(yaw + moved[2])
        h = np.array([[0.0, 0.0, 1.0, 0.0]])
        r = np.array([[sig**2]])
        innov = wrap_angle(yaw - float(self._kf.x[2]))
        s_val = float((h @ self._kf.P @ h.T + r)[0, 0])
        d2 = innov * innov / s_val
        continuous = self._azimuth_continuous(yaw)
        if d2 > self.params.gate_chi2_yaw:
            if not continuous or self._yaw_reject_since is None:
                self._yaw_reject_since = t
            if continuous and t - self._yaw_reject_since >= self.params.azimuth_recover_after_s:
                LOGGER.warning("azimuth rejected for %.1f s, off the estimate by %.1f deg: the estimate drifted; "
                               "using the azimuth", t - self._yaw_reject_since, math.degrees(innov))
                self._kf.P[2, 2] += innov * innov
                self.stats.yaw_drift_recoveries += 1
                d2 = innov * innov / float((h @ self._kf.P @ h.T + r)[0, 0])
            else:
                self.stats.yaw_rejected += 1
                return UpdateResult(False, d2)
        self._yaw_reject_since = None
        self._kf.update(
            np.array([yaw]), lambda _x: h, lambda xs: np.array([xs[2]]), R=r,
            residual=lambda a, b: np.array([wrap_angle(float(a[0]) - float(b[0]))]),
        )
        self._kf.x[2] = wrap_angle(float(self._kf.x[2]))
        self.stats.yaw_accepted += 1
        return UpdateResult(True, d2)

    def _azimuth_continuous(self, yaw: float) -> bool:
        """True if the azimuth turned as the odometry did since the previous azimuth (no sensor glitch)."""
        last = self._last_az
        if self._last_odom is None:
            self._last_az = None
            return False
        odom_yaw = self._last_odom[2]
        self._last_az = (yaw, odom_yaw)
        if last is None:
            return False
        turned = wrap_angle(odom_yaw - last[1])
        return abs(wrap_angle(yaw - last[0] - turned)) <= self.params.azimuth_jump_threshold

    def _initialise(self, x: float, y: float, r: np.ndarray, *, keep_yaw: bool = False) -> None:
        yaw = float(self._kf.x[2]) if keep_yaw else 0.0
        yaw_var = float(self._kf.P[2, 2]) if keep_yaw else self.params.initial_yaw_sigma**2
        if not keep_yaw:
            self._yaw_known = False
            if self._pending_yaw is not None:
                yaw, sig = self._pending_yaw
                yaw_var = sig**2
                self._yaw_known = True
            elif self._last_odom is not None:
                yaw = self._last_odom[2]  # odometry yaw comes from the machine's azimuth sensor
        k = float(self._kf.x[3]) if keep_yaw else 0.0
        k_var = float(self._kf.P[3, 3]) if keep_yaw else self.params.scale_sigma**2
        self._kf.x = np.array([x, y, wrap_angle(yaw), k])
        self._kf.P = np.diag([r[0, 0], r[1, 1], yaw_var, k_var])
        self.initialised = True
        self._reject_since = None
