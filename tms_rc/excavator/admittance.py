"""Force-referenced drag by an outer force loop over piston velocity control (admittance style).

The second design of issue 35's force-controlled digging, beside :class:`tms_rc.excavator.force_control.ForceLoop`
(the ID hierarchy + per-cylinder force control). Here every cylinder (boom, arm, bucket) is under piston *velocity*
control (:class:`~tms_rc.excavator.piston.PistonVelocityController`: the identified look-up table + PI), and the
force is controlled *through the position* of the edge, as is common on hydraulic excavators whose valves are too
slow for a pressure loop. Per control step (:meth:`AdmittanceDrag.step`):

1. the normal force the bucket presses on the soil is estimated from the measured cylinder pressures by the
   controller's own statics (:func:`~tms_rc.excavator.force_control.contact_force_estimate`: ``J^T F_s = g(q) -
   J_p f``), its part along the ground normal ``n`` low-passed (``filter_s``): ``F_est`` [N, + = into the ground];
2. admittance law (:func:`admittance_update`): a depth offset ``d`` of the tip reference below the path (+ = deeper,
   along -n) integrates the force error: ``d_dot = sat(admittance * (F_ref - F_est), max_normal_speed)`` (no motion
   within ``force_deadband``), ``d`` held within ``[depth_min, depth_max]`` (it stops integrating at a bound): too
   little force drives the edge deeper, too much lifts it;
3. the tip's commanded velocity ``v = v_path - n d_dot + path_gain e_t + normal_gain e_n`` with ``e = p_path - n d -
   tip`` split along the cut (``e_t``) and the normal (``e_n``) (the path point and its velocity from the reference;
   the P terms correct what the velocity loops leave; ``normal_gain`` 0: the normal speed is the admittance's alone,
   damping control, the shipped choice) and theta_w's rate
   ``theta_w_rate + theta_gain (theta_w_ref - theta_w)`` are resolved into boom, arm and bucket joint rates
   (:func:`resolved_rates`: the tip Jacobian's rows along the cut ``t`` and the normal ``n`` in the front's vertical
   plane plus theta_w = sum of the three angles, theta_w's row weighted ``theta_weight``); a joint within
   ``limit_margin`` of its limit (the description's) moving into it is stopped and the other two keep the tip on
   its path, theta_w giving way (:func:`limit_blocked`);
4. each joint rate times dl/dq is its piston speed, handed to the cylinder's velocity controller (a speed below
   ``velocity_deadband`` is none: the spool centres and the oil holds).

The controller never reads the plant: the tables come from an identification on the machine, the model is the
machine description's (:class:`~tms_rc.excavator.dynamics.FrontDynamics`), the settings from
``config/tms_rc/force_control.yaml`` (:func:`load_force_control_settings`). The swing is not driven.

Pure Python (numpy, pinocchio through the model), no ROS.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tms_common.config import config_path
from tms_common.schema import load_schema, setting
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.force_control import contact_force_estimate
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    PilotPair,
    PistonControlSettings,
    PistonLut,
    PistonVelocityController,
    cylinder_force,
    cylinder_of,
    extend_sign,
)

__all__ = ["SETTINGS_FILE", "AdmittanceSettings", "ForceControlSettings", "AdmittanceStep", "AdmittanceDrag",
           "admittance_update", "resolved_rates", "limit_blocked", "cut_axes", "load_force_control_settings"]

SETTINGS_FILE = "force_control.yaml"


@dataclass(frozen=True, kw_only=True)
class AdmittanceSettings:
    """The admittance drag's choices (``admittance:`` of ``config/tms_rc/force_control.yaml``)."""

    admittance: float = setting(lo=0.0, doc="[m/s per kN] the edge's speed into the ground per kN of too little force")
    max_normal_speed: float = setting(lo=0.0, doc="[m/s] largest speed of the depth offset")
    force_deadband: float = setting(0.0, lo=0.0, doc="[kN] a smaller force error moves the depth offset not at all")
    filter_s: float = setting(lo=0.0, doc="[s] time constant of the force estimate's low-pass (0: none)")
    depth_min: float = setting(doc="[m] the depth offset below the path never goes above this (- = above the path)")
    depth_max: float = setting(doc="[m] ... nor deeper than this")
    path_gain: float = setting(lo=0.0, doc="[1/s] tip position error (along the cut and the normal) -> tip speed")
    normal_gain: float | None = setting(None, lo=0.0, doc="[1/s] the P gain along the normal alone (None: "
                                        "path_gain; 0: the normal speed is the admittance's alone, damping control)")
    theta_gain: float = setting(lo=0.0, doc="[1/s] theta_w error -> its rate")
    velocity_deadband: float = setting(lo=0.0, doc="[m/s] a smaller piston speed command is none (spool centred)")
    theta_weight: float = setting(lo=0.0, doc="theta_w's row against the tip's (1) where not all can be met")
    limit_margin: float = setting(lo=0.0, doc="[rad] a joint this close to a limit of the description moving into "
                                  "it is stopped; the others keep the tip on its path, theta_w gives way")

    def __post_init__(self) -> None:
        if self.depth_min > self.depth_max:
            raise ValueError(f"depth_min {self.depth_min} > depth_max {self.depth_max}")


@dataclass(frozen=True, kw_only=True)
class ForceControlSettings:
    """``config/tms_rc/force_control.yaml``."""

    admittance: AdmittanceSettings = setting(doc="the admittance drag (tms_rc.excavator.admittance)")
    #: the cut-force drag's section, read and checked key by key by tms_rc.excavator.cut_force (which imports this
    #: module: a nested dataclass here would import it back)
    cut_force: dict[str, float] | None = setting(None, doc="the cut-force drag (tms_rc.excavator.cut_force)")


def settings_path() -> Path:
    return Path(config_path("tms_rc", SETTINGS_FILE))


def load_force_control_settings(path: str | Path | None = None) -> ForceControlSettings:
    """The choices of ``path`` (default ``config/tms_rc/force_control.yaml``); errors ``file:line: key: problem``."""
    return load_schema(ForceControlSettings, path if path is not None else settings_path())


def admittance_update(depth: float, f_ref: float, f_est: float, s: AdmittanceSettings,
                      dt: float) -> tuple[float, float]:
    """One step of the admittance law: (new depth offset [m, + = deeper], its speed [m/s]) for the normal force
    reference ``f_ref`` and estimate ``f_est`` [N, + = pressing into the ground]."""
    err_kn = (f_ref - f_est) / 1e3
    if abs(err_kn) <= s.force_deadband:
        return depth, 0.0
    err_kn -= math.copysign(s.force_deadband, err_kn)
    speed = max(-s.max_normal_speed, min(s.max_normal_speed, s.admittance * err_kn))
    new = max(s.depth_min, min(s.depth_max, depth + speed * dt))
    return new, (new - depth) / dt


def cut_axes(heading: float, normal: np.ndarray) -> np.ndarray:
    """The unit vector along the cut in the front's vertical plane at swing angle ``heading``, across ``normal``."""
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    t = h - normal * float(h @ normal)
    return t / max(float(np.linalg.norm(t)), 1e-9)


def resolved_rates(jac: np.ndarray, t: np.ndarray, n: np.ndarray, v_tip: np.ndarray, theta_rate: float,
                   theta_weight: float = 1.0, blocked: tuple[int, ...] = ()) -> np.ndarray:
    """Boom, arm and bucket joint rates [rad/s] for the tip velocity ``v_tip`` [m/s, base_link] (its parts along
    ``t`` and ``n``) and theta_w's rate (the sum of the three rates); ``jac`` the tip's 3 x 3 position Jacobian over
    boom, arm, bucket. Weighted least squares: theta_w's row weighs ``theta_weight`` against the tip's (1), which
    only matters where the three cannot all be met; the joints ``blocked`` (0, 1, 2: at a limit, moving into it) get
    rate 0 and the others meet the rows as they can."""
    a = np.vstack([t @ jac, n @ jac, theta_weight * np.ones(3)])
    rhs = np.array([float(t @ v_tip), float(n @ v_tip), theta_weight * theta_rate])
    free = [k for k in range(3) if k not in blocked]
    rates = np.zeros(3)
    if free:
        sol, *_ = np.linalg.lstsq(a[:, free], rhs, rcond=None)
        rates[free] = sol
    return rates


def limit_blocked(q: np.ndarray, rates: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                  margin: float) -> tuple[int, ...]:
    """The joints (indices into ``q``/``rates``, boom, arm, bucket) within ``margin`` [rad] of a limit whose rate
    moves further into it."""
    return tuple(k for k in range(len(q))
                 if (rates[k] > 0.0 and q[k] >= upper[k] - margin) or (rates[k] < 0.0 and q[k] <= lower[k] + margin))


@dataclass
class AdmittanceStep:
    """One step's outcome: pilot pairs per cylinder function, the estimated pressed force [N, base_link], the
    filtered normal force estimate [N, + into the ground], the depth offset [m] and its speed [m/s], the commanded
    tip velocity [m/s] and piston speeds [m/s]."""

    pairs: dict[str, PilotPair]
    pressed: np.ndarray
    f_est: float
    depth: float
    depth_rate: float
    v_tip: np.ndarray
    piston_speeds: dict[str, float]


class AdmittanceDrag:
    """The admittance drag of one excavator front (module docstring).

    Args:
        dyn, kin: the front's model and kinematics (the machine's description).
        luts: the identified look-up table of each cylinder function.
        piston: ``config/tms_rc/piston_control.yaml``'s choices (``velocity`` gains, rate, zero band).
        p_max: the DBC's largest pilot [MPa].
        settings: ``config/tms_rc/force_control.yaml``'s ``admittance``.
    """

    def __init__(self, dyn: FrontDynamics, kin: ExcavatorKinematics, luts: Mapping[str, PistonLut],
                 piston: PistonControlSettings, p_max: float, settings: AdmittanceSettings) -> None:
        missing = [fn for fn in CYLINDER_FUNCTIONS if fn not in luts]
        if missing:
            raise ValueError(f"AdmittanceDrag: no identified look-up table for {', '.join(missing)}")
        self.dyn, self.kin, self.settings = dyn, kin, settings
        machine = dyn.machine
        self.dt = 1.0 / piston.rate_hz
        self.cylinders = {fn: cylinder_of(machine, fn) for fn in CYLINDER_FUNCTIONS}
        self.movers = {fn: PistonVelocityController(luts[fn], piston.velocity[fn], self.dt,
                                                    extend=extend_sign(machine, fn), zero_band=piston.zero_band_mpa,
                                                    p_max=p_max)
                       for fn in CYLINDER_FUNCTIONS}
        self.index = [JOINTS.index(fn) for fn in CYLINDER_FUNCTIONS]
        joints = [machine.joint(fn) for fn in CYLINDER_FUNCTIONS]
        self.lower = np.array([-math.inf if j.lower is None else j.lower for j in joints])
        self.upper = np.array([math.inf if j.upper is None else j.upper for j in joints])
        self.depth = 0.0
        self.f_est: float | None = None

    def reset(self) -> None:
        self.depth = 0.0
        self.f_est = None
        for ctl in self.movers.values():
            ctl.reset()

    def estimate(self, q: np.ndarray, pressures: Mapping[str, tuple[float, float]],
                 n: np.ndarray) -> tuple[np.ndarray, float]:
        """(pressed force [N, base_link] by statics, its low-passed part into the ground along -n [N])."""
        measured = np.array([cylinder_force(self.cylinders[fn], *pressures[fn]) for fn in CYLINDER_FUNCTIONS])
        pressed = contact_force_estimate(self.dyn, q, measured)
        raw = -float(pressed @ n)
        tau = self.settings.filter_s
        if self.f_est is None or tau <= 0.0:
            self.f_est = raw
        else:
            self.f_est += (raw - self.f_est) * self.dt / (tau + self.dt)
        return pressed, self.f_est

    def step(self, q: np.ndarray, qd: np.ndarray, pressures: Mapping[str, tuple[float, float]], ref: IdReference,
             force_ref: float, normal: np.ndarray | None = None) -> AdmittanceStep:
        """One control period. ``ref``: the path's point, velocity and theta_w (with its rate) [base_link];
        ``force_ref`` [N]: the normal force to press into the ground (>= 0); ``normal``: the ground's unit normal
        (default up)."""
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        n = np.array([0.0, 0.0, 1.0]) if normal is None else np.asarray(normal, dtype=float)
        if abs(float(np.linalg.norm(n)) - 1.0) > 1e-6:
            raise ValueError(f"AdmittanceDrag.step: normal must be a unit vector, got {n}")
        s = self.settings
        pressed, f_est = self.estimate(q, pressures, n)
        self.depth, d_rate = admittance_update(self.depth, force_ref, f_est, s, self.dt)
        tip = self.dyn.tip_position(q)
        target = ref.position - n * self.depth
        err = target - tip
        err_n = float(err @ n)
        k_n = s.path_gain if s.normal_gain is None else s.normal_gain
        v_tip = ref.velocity - n * d_rate + s.path_gain * (err - n * err_n) + k_n * err_n * n
        theta = float(q[1] + q[2] + q[3]) + self.kin.c_bucket
        theta_rate = ref.theta_w_rate + s.theta_gain * (ref.theta_w - theta)
        jac = self.dyn.tip_jacobian(q)[:, self.index]
        t = cut_axes(float(q[0]), n)
        rates = resolved_rates(jac, t, n, v_tip, theta_rate, s.theta_weight)
        blocked = limit_blocked(q[self.index], rates, self.lower, self.upper, s.limit_margin)
        if blocked:
            rates = resolved_rates(jac, t, n, v_tip, theta_rate, s.theta_weight, blocked)
        gains = self.dyn.actuator_gains(q)
        pairs, speeds = {}, {}
        for k, fn in enumerate(CYLINDER_FUNCTIONS):
            i = self.index[k]
            v_ref = float(gains[i] * rates[k])
            if abs(v_ref) < s.velocity_deadband:
                v_ref = 0.0
            speeds[fn] = v_ref
            pairs[fn] = self.movers[fn].step(v_ref, float(gains[i] * qd[i]))
        return AdmittanceStep(pairs, pressed, f_est, self.depth, d_rate, v_tip, speeds)
