"""Cut-force drag: the force ALONG the cut regulated through the depth of cut (HEAP-style force-controlled digging
with the COM3 pilot valves' dead times).

Why not the normal force: the ground carries ~12 kN per mm of edge depth in bearing, while the tip follows its
reference only to 2.5-3.1 cm RMS through the valves' 0.3-0.65 s dead times (bench ``force_dig``, README). The
cutting resistance along the cut grows with the depth of cut by a few kN per cm (the soil's wedge): a depth
reference moved slowly by that force's error is a loop the valves can follow.

Per 100 Hz step :meth:`CutForceDrag.step` takes the measured joint state, the boom's, arm's and bucket's chamber
pressures, a path reference ON the sensed surface (the point, its velocity along the drag, theta_w) and the
tangential force reference ``force_ref`` [N, the force the bucket exerts on the soil along its motion], and

1. estimates the pressed force from the pressures by the controller's own statics
   (:func:`~tms_rc.excavator.force_control.contact_force_estimate`, the estimate ForceLoop and AdmittanceDrag use):
   its part along the drag ``t`` (the tangential force ``F_t``, low-passed ``filter_s``) and into the ground along
   ``-n`` (``F_n``, the same filter);
2. moves the depth reference ``d`` below the surface (:func:`cut_depth_update`) towards ``F_ref / ff_slope`` (the
   feed-forward: the depth the soil's slope implies) plus a trim integrating ``force_ki (F_ref - F_t)``, both at most
   ``max_depth_rate``, the trim only while the path moves along the cut faster than ``integrate_speed`` (a still edge
   meets no cutting resistance); while ``F_n`` exceeds ``normal_limit`` the depth backs off at ``backoff_rate``
   whatever the tangential error; ``d`` within ``[depth_min, depth_max]``. Too little tangential force -> deeper;
3. the tip follows ``ref.position - n d`` (velocity ``ref.velocity - n d_dot``) through the admittance design's
   position follower (:class:`~tms_rc.excavator.admittance.AdmittanceDrag` with its own admittance off: resolved
   rates of boom, arm and bucket, joint-limit stop, piston velocity control): a position/path loop, as the IK path.

``ff_slope`` is the cutting resistance's slope with the depth [kN per cm], identified on the machine (bench
``force_dig`` measures it on the plant; 0: no feed-forward, the integral alone); the controller never reads the plant.
Settings: ``cut_force:`` of
``config/tms_rc/force_control.yaml`` (:func:`load_cut_force_settings`). Pure Python, no ROS.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tms_common.schema import load_schema, setting
from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_rc.excavator.admittance import AdmittanceDrag, AdmittanceSettings, cut_axes, settings_path
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import PilotPair, PistonControlSettings, PistonLut

__all__ = ["CutForceSettings", "CutForceStep", "CutForceDrag", "cut_depth_update", "load_cut_force_settings"]

SECTION = "cut_force"


@dataclass(frozen=True, kw_only=True)
class CutForceSettings:
    """The cut-force drag's choices (``cut_force:`` of ``config/tms_rc/force_control.yaml``)."""

    force_ki: float = setting(lo=0.0, doc="[m/s per kN] depth rate per kN of too little tangential force")
    ff_slope: float = setting(0.0, lo=0.0, doc="[kN per cm] the cutting resistance's slope with depth (0: no "
                              "feed-forward)")
    max_depth_rate: float = setting(lo=0.0, doc="[m/s] largest speed of the depth reference (force terms)")
    integrate_speed: float = setting(lo=0.0, doc="[m/s] the depth moves only while the path moves along the cut "
                                     "faster than this")
    filter_s: float = setting(lo=0.0, doc="[s] low-pass of the force estimates (0: none)")
    depth_min: float = setting(doc="[m] shallowest depth reference below the surface (- = above it)")
    depth_max: float = setting(doc="[m] deepest depth reference")
    normal_limit: float = setting(lo=0.0, doc="[kN] above this estimated force into the ground the depth backs off")
    backoff_rate: float = setting(lo=0.0, doc="[m/s] the depth's speed up while over normal_limit")
    path_gain: float = setting(lo=0.0, doc="[1/s] tip position error along the cut -> tip speed")
    normal_gain: float = setting(lo=0.0, doc="[1/s] tip position error along the normal -> tip speed")
    theta_gain: float = setting(lo=0.0, doc="[1/s] theta_w error -> its rate")
    velocity_deadband: float = setting(lo=0.0, doc="[m/s] a smaller piston speed command is none")
    theta_weight: float = setting(lo=0.0, doc="theta_w's row against the tip's where not all can be met")
    limit_margin: float = setting(lo=0.0, doc="[rad] a joint this close to its limit, moving into it, is stopped")

    def __post_init__(self) -> None:
        if self.depth_min > self.depth_max:
            raise ValueError(f"depth_min {self.depth_min} > depth_max {self.depth_max}")

    def follower(self) -> AdmittanceSettings:
        """The position follower's settings: the admittance design with its admittance off (the depth is ours)."""
        return AdmittanceSettings(admittance=0.0, max_normal_speed=0.0, filter_s=0.0, depth_min=-math.inf,
                                  depth_max=math.inf, path_gain=self.path_gain, normal_gain=self.normal_gain,
                                  theta_gain=self.theta_gain, velocity_deadband=self.velocity_deadband,
                                  theta_weight=self.theta_weight, limit_margin=self.limit_margin)


def load_cut_force_settings(path: str | Path | None = None) -> CutForceSettings:
    """``cut_force:`` of ``path`` (default ``config/tms_rc/force_control.yaml``); errors ``file:line: key: problem``."""
    return load_schema(CutForceSettings, path if path is not None else settings_path(), (SECTION,))


def cut_depth_update(depth: float, trim: float, f_ref: float, f_t: float, f_n: float, s: CutForceSettings,
                     dt: float, moving: bool = True) -> tuple[float, float, float]:
    """One step of the depth law: (new depth [m, + = deeper below the surface], new trim [m], the depth's speed
    [m/s]) for the tangential force reference ``f_ref`` and estimate ``f_t`` [N, the bucket on the soil along its
    motion] and the estimated force into the ground ``f_n`` [N]; ``moving``: the path moves along the cut (else the
    force terms rest).

    The depth aims at ``F_ref / ff_slope`` (the feed-forward; 0 without a slope) plus ``trim``, the integral of
    ``force_ki (F_ref - F_t)``; both the trim and the depth move at most ``max_depth_rate``, and the trim stops where
    the aim leaves ``[depth_min, depth_max]`` (no wind-up). Over ``normal_limit`` the trim backs off at
    ``backoff_rate`` and the depth follows at that speed, moving or not."""
    ff = f_ref / 1e3 / (100.0 * s.ff_slope) if s.ff_slope > 0.0 else 0.0
    if moving:
        step = max(-s.max_depth_rate, min(s.max_depth_rate, s.force_ki * (f_ref - f_t) / 1e3)) * dt
        trim = max(s.depth_min - ff, min(s.depth_max - ff, trim + step))
    limit = s.max_depth_rate
    if f_n > s.normal_limit * 1e3:  # the bearing limit overrides the force terms
        trim = max(s.depth_min - ff, min(trim, depth - ff) - s.backoff_rate * dt)
        limit = max(limit, s.backoff_rate)
    aim = max(s.depth_min, min(s.depth_max, ff + trim)) if moving or f_n > s.normal_limit * 1e3 else depth
    new = depth + max(-limit * dt, min(limit * dt, aim - depth))
    return new, trim, (new - depth) / dt


@dataclass
class CutForceStep:
    """One step's outcome: pilot pairs, the estimated pressed force [N, base_link], the filtered tangential and
    normal estimates [N], the depth reference [m] and its speed [m/s]."""

    pairs: dict[str, PilotPair]
    pressed: np.ndarray
    f_t: float
    f_n: float
    depth: float
    depth_rate: float


class CutForceDrag:
    """The cut-force drag of one excavator front (module docstring); arguments as
    :class:`~tms_rc.excavator.admittance.AdmittanceDrag`'s, ``settings`` the ``cut_force:`` section."""

    def __init__(self, dyn: FrontDynamics, kin: ExcavatorKinematics, luts: Mapping[str, PistonLut],
                 piston: PistonControlSettings, p_max: float, settings: CutForceSettings) -> None:
        self.settings = settings
        self.follow = AdmittanceDrag(dyn, kin, luts, piston, p_max, settings.follower())
        self.dyn, self.kin, self.dt = dyn, kin, self.follow.dt
        self.depth = 0.0
        self.trim = 0.0  # [m] the integral of the tangential force error, on top of the feed-forward depth
        self.f_t: float | None = None
        self.f_n: float | None = None
        self.sign = -1.0  # the drag's direction along the arm's heading (- = towards the machine) until it moves

    def reset(self, depth: float = 0.0) -> None:
        """Start a drag with the depth reference at ``depth`` [m] (where the edge is below the sensed surface)."""
        self.depth = depth
        self.trim = 0.0
        self.f_t = self.f_n = None
        self.follow.reset()

    def _filter(self, last: float | None, raw: float) -> float:
        tau = self.settings.filter_s
        if last is None or tau <= 0.0:
            return raw
        return last + (raw - last) * self.dt / (tau + self.dt)

    def step(self, q: np.ndarray, qd: np.ndarray, pressures: Mapping[str, tuple[float, float]], ref: IdReference,
             force_ref: float, normal: np.ndarray | None = None) -> CutForceStep:
        """One control period. ``ref``: the path on the sensed surface (point, velocity along the drag, theta_w);
        ``force_ref`` [N]: the force along the cut (>= 0); ``normal``: the ground's unit normal (default up)."""
        q = np.asarray(q, dtype=float)
        n = np.array([0.0, 0.0, 1.0]) if normal is None else np.asarray(normal, dtype=float)
        if abs(float(np.linalg.norm(n)) - 1.0) > 1e-6:
            raise ValueError(f"CutForceDrag.step: normal must be a unit vector, got {n}")
        s = self.settings
        out_axis = cut_axes(float(q[0]), n)
        speed = float(ref.velocity @ out_axis)
        moving = abs(speed) > s.integrate_speed
        if moving:
            self.sign = math.copysign(1.0, speed)
        pressed, _ = self.follow.estimate(q, pressures, n)
        self.f_t = self._filter(self.f_t, float(pressed @ (self.sign * out_axis)))
        self.f_n = self._filter(self.f_n, -float(pressed @ n))
        self.depth, self.trim, rate = cut_depth_update(self.depth, self.trim, force_ref, self.f_t, self.f_n, s,
                                                       self.dt, moving)
        self.follow.depth = self.depth
        path = dataclasses.replace(ref, velocity=ref.velocity - n * rate)
        out = self.follow.step(q, qd, pressures, path, 0.0, n)
        return CutForceStep(out.pairs, pressed, self.f_t, self.f_n, self.depth, rate)
