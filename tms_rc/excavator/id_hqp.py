"""HEAP's inverse-dynamics hierarchy for an excavator's front: joint accelerations and actuator torques per step.

Decision vector ``x = [qdd (4), tau (4)]`` (swing, boom, arm, bucket), solved by the strict-priority
:class:`~tms_rc.excavator.hqp.HierarchicalQP` (the IK controller's, which is general over the vector size) with
HEAP's ID task list (Jud et al. 2021, "HEAP - The autonomous walking excavator", sec. 4.3.1; the strict-priority
cascade after Bellicoso et al. 2016), highest first:

1. equations of motion ``M qdd + h + F_v qd + F_s sgn(qd) = tau + J^T F_ext`` (``F_ext`` = the wrench the soil
   exerts on the bucket at the tip, base_link axes: a 3-force or a 6-wrench [force; moment]; sgn smoothed as
   tanh(qd / friction_speed); F_v, F_s are settings, 0 by default: the controller has no identified friction);
2. pump flow ``sum_i a_i |J_p,i (qd_i + dt qdd_i)| <= Q_max`` over the functions on the main pumps (the
   description's ``flow_at_limit_lpm`` > 0: boom, arm, bucket on the ZX200; the swing has its own circuit),
   a_i the cap area when the cylinder extends and the rod area when it retracts: exactly, as 2^k linear rows
   (one per direction pattern), not linearised about a guessed direction;
3. force limits ``tau_min(q) <= tau <= tau_max(q)``: tau = J_p f with f in [-p_relief A_rod, p_relief A_cap]
   (swing motor: +- its relief pressure times its displacement);
4. actuator speed limits through J_p: ``|qd + dt qdd| <= v_max,i / |J_p,i(q)|`` (recomputed each step; v_max
   per actuator from the settings or, by default, the description's joint velocity limit times |J_p| at home);
5. stroke limits: ``q_min <= q + T qd + T^2/2 qdd <= q_max`` (T = ``stroke_horizon_s``; the joint limits of the
   description are the stroke ends: each cylinder length is monotonic over its joint's range);
6. collision, second-order velocity dampers (Faverjon & Tournassoud, ICRA 1987): (a) ground and swing-axis
   clearance of the bucket tip and pin, ``d_dd >= -(xi/T) d/d_i - d_d/T`` while ``d < d_i``, d = height above
   ``ground_min_z`` or distance from the swing axis beyond ``body_min_radius`` (the IK's rows, one order up);
   (b) self-collision between link primitives (HEAP's closest points of boxes; :mod:`tms_rc.excavator.collision`:
   boxes of boom, arm, bucket, upper structure, cab and undercarriage, closest points from coal), one row per
   pair ``d_dd = n^T (J_b - J_a) qdd + drift >= -(xi_c/T)(d - d_s)/(d_i - d_s) - d_d/T`` while ``d < d_i``
   (``self_collision_*`` settings; pairs whose bounding spheres are farther apart than d_i skip coal);
7. bucket orientation: theta_w (bucket pin -> tip angle below horizontal, :mod:`tms_model.excavator.kinematics`)
   ``alpha_d = alpha_ref + kp e + kd e_dot``;
8. bucket-tip position: ``J qdd + J_dot qd = a_d``, ``a_d = a_ref + kp e + kd e_dot``;
9. joint damping ``qdd = -k qd``.

Numerics: the torques are scaled by a fixed per-joint torque (the larger relief torque at home) so every column is
O(1), and the hierarchy is solved for the deviation from the particular EoM solution ``x0 = [0, h + friction -
J^T F_ext]``: the EoM level then has b = 0, holds at x = 0 and is eliminated exactly by the nullspace projection
(residual ~1e-9 N m instead of the regularisation's bias), and the regularisation pulls towards "hold still
against gravity", not towards zero torque. Cylinder forces f_i = tau_i / J_p,i (the swing's "force" is its motor's
port pressure difference [Pa]).

Pure Python core (numpy, pinocchio, OSQP); every buffer of a step is preallocated. The force loop around it
(a desired soil force in, piston force control out) is :mod:`tms_rc.excavator.force_control`. Not yet done (see
``tms_rc/excavator/README.md``): the switch between IK and ID in the excavate subtask, a node.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_rc.excavator.collision import CollisionSettings, SelfCollision
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.hqp import HierarchicalQP, HqpResult, LevelSpec

__all__ = ["IdSettings", "IdReference", "IdResult", "InverseDynamicsHQP", "LEVEL_NAMES"]

N = len(JOINTS)
#: [-] right-hand side that leaves an inactive row free (the scaled rows are O(1) .. O(1e4))
_FREE = 1e9
LEVEL_NAMES = ("eom", "pump_flow", "force_limits", "velocity_limits", "stroke_limits", "collision",
               "orientation", "position", "damping")


@dataclass(frozen=True)
class IdSettings:
    """Control choices of the ID hierarchy (figures of the machine come from its description)."""

    rate_hz: float = 100.0  # [Hz] control rate: dt of the pump-flow and velocity rows
    kp_position: float = 25.0  # [1/s^2] tip position error -> acceleration
    kd_position: float = 10.0  # [1/s] tip velocity error -> acceleration
    kp_theta_w: float = 25.0  # [1/s^2]
    kd_theta_w: float = 10.0  # [1/s]
    joint_damping: float = 2.0  # [1/s] level 9: qdd = -k qd
    viscous_friction: tuple[float, ...] = (0.0,) * N  # F_v [N m s/rad] per joint
    static_friction: tuple[float, ...] = (0.0,) * N  # F_s [N m] per joint
    friction_speed: float = 0.01  # [rad/s] sgn(qd) ~ tanh(qd / this)
    pump_flow_lpm: float | None = None  # [L/min] None: the description's pump_flow
    #: actuator speed limits (swing [m^3/s], cylinders [m/s]); None: joint velocity limit x |J_p(home)|
    speed_limits: tuple[float, ...] | None = None
    stroke_horizon_s: float = 0.1  # [s] T of the stroke rows (HEAP: the control period)
    stroke_margin: float = 0.0  # [rad] kept inside the joint limits
    ground_min_z: float = -2.5  # [m] bucket tip and pin above this (base_link), as the IK's collision setting
    body_min_radius: float = 3.2  # [m] tip and pin this far from the swing axis, as the IK's
    damper_influence: float = 0.5  # [m] d_i: a damper row acts below this distance
    damper_xi: float = 0.5  # [m/s] xi of the damper
    damper_horizon_s: float = 0.1  # [s] T of the damper
    #: link-primitive self-collision (level 6 (b)); HEAP's d_i, d_s and xi are not published: ours
    self_collision: bool = True
    self_collision_influence: float = 0.5  # [m] d_i: a pair's row acts below this distance
    self_collision_safety: float = 0.1  # [m] d_s: the distance the damper holds (it approaches it exponentially)
    self_collision_xi: float = 0.5  # [m/s] xi: approach speed at d_i (T = damper_horizon_s)
    #: primitive sizes and pairs (:class:`~tms_rc.excavator.collision.CollisionSettings`)
    collision_primitives: CollisionSettings = field(default_factory=CollisionSettings)
    eps: float = 1e-6  # OSQP tolerances
    max_iter: int = 2000
    regularisation: float = 1e-6
    fix_tolerance: float = 1e-5


@dataclass
class IdReference:
    """One step's task references in base_link: tip position/velocity/acceleration and theta_w with its rates."""

    position: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    theta_w: float = 0.0
    theta_w_rate: float = 0.0
    theta_w_accel: float = 0.0


@dataclass
class IdResult:
    """Joint accelerations [rad/s^2], joint torques [N m], actuator forces (swing: pressure [Pa]; cylinders [N],
    + = extending), the EoM residual [N m], the tasks' desired accelerations and the hierarchy's own result."""

    qdd: np.ndarray
    tau: np.ndarray
    force: np.ndarray
    eom_residual: np.ndarray
    tip_accel_desired: np.ndarray
    tip_accel: np.ndarray
    theta_w_accel_desired: float
    hqp: HqpResult


class InverseDynamicsHQP:
    """The ID hierarchy of one excavator front; call :meth:`solve` once per control step.

    Args:
        dyn: the front's rigid-body model and actuator map (:class:`FrontDynamics`).
        kin: the kinematics of the same description (joint limits, theta_w offset, swing axis).
        settings: the control choices.
    """

    def __init__(self, dyn: FrontDynamics, kin: ExcavatorKinematics, settings: IdSettings | None = None) -> None:
        s = settings or IdSettings()
        self.dyn, self.kin, self.settings = dyn, kin, s
        self.dt = 1.0 / s.rate_hz
        machine = dyn.machine
        acts = dyn.actuators
        pump = [i for i, a in enumerate(acts) if a.on_pump]
        flow_lpm = s.pump_flow_lpm if s.pump_flow_lpm is not None else machine.pump_flow
        self.pump_joints = tuple(pump)
        self.q_max = (flow_lpm or math.inf) / 60000.0  # [m^3/s]
        self.collision = SelfCollision(dyn.model, machine, s.collision_primitives) if s.self_collision else None
        n_pairs = len(self.collision.names) if self.collision is not None else 0
        if self.collision is not None and not 0.0 <= s.self_collision_safety < s.self_collision_influence:
            raise ValueError(f"self-collision: need 0 <= d_s < d_i, got d_s={s.self_collision_safety}, "
                             f"d_i={s.self_collision_influence}")
        # pump: one row per direction pattern; collision: ground + swing axis of tip and pin, then one per pair
        rows = (N, max(2 ** len(pump), 1), 2 * N, 2 * N, 2 * N, 4 + n_pairs, 1, 3, N)
        kinds = ("eq", "ineq", "ineq", "ineq", "ineq", "ineq", "eq", "eq", "eq")
        levels = [LevelSpec(name, kind, r) for name, kind, r in zip(LEVEL_NAMES, kinds, rows, strict=True)]
        self.levels = levels
        self.hqp = HierarchicalQP(2 * N, levels, eps=s.eps, max_iter=s.max_iter, regularisation=s.regularisation,
                                  fix_tolerance=s.fix_tolerance)
        home_gain = np.abs(dyn.actuator_gains(kin.home))
        tmin, tmax = dyn.torque_limits(home_gain)
        self.torque_scale = np.maximum(np.abs(tmin), np.abs(tmax))  # [N m] tau = scale * x[4:]
        lim = kin.limits
        self.speed_limits = (np.array(s.speed_limits, dtype=float) if s.speed_limits is not None
                             else lim.velocity * home_gain)
        self._lower = np.where(np.isfinite(lim.lower), lim.lower + s.stroke_margin, -_FREE)
        self._upper = np.where(np.isfinite(lim.upper), lim.upper - s.stroke_margin, _FREE)
        self._bounded = np.isfinite(lim.lower) & np.isfinite(lim.upper)
        self._fv = np.array(s.viscous_friction, dtype=float)
        self._fs = np.array(s.static_friction, dtype=float)
        # pump rows: sign pattern x area of that direction, per pump joint (0 for the others)
        self._pump_area = np.zeros((levels[1].rows, N))
        for r, signs in enumerate(itertools.product((1.0, -1.0), repeat=len(pump))):
            for sgn, i in zip(signs, pump, strict=True):
                self._pump_area[r, i] = sgn * (acts[i].area_extend if sgn > 0 else acts[i].area_retract)
        # task buffers (A, b) per level, filled in place each step; constant parts written once
        self._a = [np.zeros((lv.rows, 2 * N)) for lv in levels]
        self._b = [np.zeros(lv.rows) for lv in levels]
        self._tasks = list(zip(self._a, self._b, strict=True))
        eye = np.eye(N)
        self._a[0][:, N:] = -eye
        self._a[2][:N, N:] = eye
        self._a[2][N:, N:] = -eye
        self._a[3][:N, :N] = eye
        self._a[3][N:, :N] = -eye
        self._a[4][:N, :N] = np.where(self._bounded, 1.0, 0.0)[:, None] * eye
        self._a[4][N:, :N] = -self._a[4][:N, :N]
        self._a[6][0, 1:N] = 1.0  # theta_w = boom + arm + bucket + c
        self._a[8][:, :N] = eye
        self._gains = np.zeros(N)
        self._swing_xy = np.array(kin.swing_origin[:2], dtype=float)
        self._b[5][4:] = _FREE  # pair rows: free until a pair comes within d_i
        self._pairs_set = False

    # ------------------------------------------------------------------ one step
    def solve(self, q: np.ndarray, qd: np.ndarray, ref: IdReference, f_ext: np.ndarray | None = None) -> IdResult:
        """Accelerations, torques and actuator forces for the state (q, qd), the references and the wrench
        ``f_ext`` (force [N] or [force; moment] the soil exerts on the bucket at the tip, base_link axes)."""
        s, dt = self.settings, self.dt
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        dyn = self.dyn
        dyn.update(q, qd)
        m, h = dyn.terms()
        tip, jac, jdq = dyn.tip()
        pin_p, pin_jac, pin_jdq = dyn.bucket_pin()
        g = dyn.actuator_gains(q, out=self._gains)
        sc = self.torque_scale
        a, b = self._a, self._b

        # 1. EoM about the particular solution tau0 (qdd = 0): M qdd - S tau_s' = 0
        tau0 = h + self._fv * qd
        if self._fs.any():
            tau0 = tau0 + self._fs * np.tanh(qd / s.friction_speed)
        if f_ext is not None:
            f = np.asarray(f_ext, dtype=float)
            tau0 = tau0 - (jac[: f.size].T @ f)
        tau0_s = tau0 / sc
        a[0][:, :N] = m / sc[:, None]
        # b[0] stays 0

        # 2. pump flow (scaled by Q_max): rows over qdd of the sign patterns
        if self.pump_joints:
            ag = self._pump_area * g
            a[1][:, :N] = ag * (dt / self.q_max)
            b[1][:] = 1.0 - (ag @ qd) / self.q_max

        # 3. force limits on the scaled torque deviation
        tmin, tmax = dyn.torque_limits(g)
        b[2][:N] = tmax / sc - tau0_s
        b[2][N:] = tau0_s - tmin / sc

        # 4. actuator speed limits as joint speed bounds over one period (rows in rad/s^2)
        vmax = self.speed_limits / np.maximum(np.abs(g), 1e-9)
        b[3][:N] = (vmax - qd) / dt
        b[3][N:] = (vmax + qd) / dt

        # 5. stroke limits at the horizon (rows in rad/s^2)
        t = s.stroke_horizon_s
        pred = q + t * qd
        half = 0.5 * t * t
        b[4][:N] = np.where(self._bounded, (self._upper - pred) / half, _FREE)
        b[4][N:] = np.where(self._bounded, (pred - self._lower) / half, _FREE)

        # 6. ground and swing-axis dampers of tip and pin, then the primitive pairs: d_dd >= beta while d < d_i
        self._dampers(tip, jac, jdq, pin_p, pin_jac, pin_jdq, qd)
        if self.collision is not None:
            self._pair_dampers(qd)

        # 7. theta_w acceleration
        th = float(q[1] + q[2] + q[3]) + self.kin.c_bucket
        om = float(qd[1] + qd[2] + qd[3])
        alpha_d = ref.theta_w_accel + s.kp_theta_w * (ref.theta_w - th) + s.kd_theta_w * (ref.theta_w_rate - om)
        b[6][0] = alpha_d

        # 8. tip acceleration
        vel = jac[:3] @ qd
        a_d = ref.acceleration + s.kp_position * (ref.position - tip) + s.kd_position * (ref.velocity - vel)
        a[7][:, :N] = jac[:3]
        b[7][:] = a_d - jdq

        # 9. joint damping
        np.multiply(-s.joint_damping, qd, out=b[8])

        res = self.hqp.solve(self._tasks)
        x = res.x
        qdd = x[:N].copy()
        tau = sc * x[N:] + tau0
        eom = m @ qdd + tau0 - tau
        force = tau / np.where(np.abs(g) > 1e-12, g, 1e-12)
        return IdResult(qdd=qdd, tau=tau, force=force, eom_residual=eom, tip_accel_desired=np.array(a_d),
                        tip_accel=jac[:3] @ qdd + jdq, theta_w_accel_desired=alpha_d, hqp=res)

    def _dampers(self, tip, jac, jdq, pin_p, pin_jac, pin_jdq, qd) -> None:
        """Level 6 rows ``-d_dd(qdd) <= -beta`` (ground, swing axis) of the tip and the pin, free when far."""
        s = self.settings
        a, b = self._a[5], self._b[5]
        di, xi, t = s.damper_influence, s.damper_xi, s.damper_horizon_s
        r = 0
        for p, j, jd in ((tip, jac, jdq), (pin_p, pin_jac, pin_jdq)):
            # ground: d = z - z_min, d_dd = J_z qdd + jd_z
            d = float(p[2]) - s.ground_min_z
            a[r, :N] = -j[2]
            if d < di:
                beta = -(xi / t) * d / di - float(j[2] @ qd) / t
                b[r] = float(jd[2]) - beta
            else:
                b[r] = _FREE
            r += 1
            # swing axis: rho = |p_xy - o_xy|, rho_dd = n . a_xy + (|v_xy|^2 - rho_d^2) / rho
            rel = p[:2] - self._swing_xy
            rho = max(math.hypot(float(rel[0]), float(rel[1])), 1e-6)
            n = rel / rho
            a[r, :N] = -(n @ j[:2])
            d = rho - s.body_min_radius
            if d < di:
                v = j[:2] @ qd
                rho_d = float(n @ v)
                beta = -(xi / t) * d / di - rho_d / t
                b[r] = float(n @ jd[:2]) + (float(v @ v) - rho_d * rho_d) / rho - beta
            else:
                b[r] = _FREE
            r += 1

    def _pair_dampers(self, qd) -> None:
        """Level 6 rows 4.. : per primitive pair ``-row qdd <= drift - beta`` while d < d_i, else free (zero row).

        The pinocchio data of :attr:`dyn` holds this step's placements, joint Jacobians and (qd, qdd = 0) motion.
        """
        s = self.settings
        col = self.collision
        a, b = self._a[5], self._b[5]
        di, ds, xi, t = (s.self_collision_influence, s.self_collision_safety, s.self_collision_xi,
                         s.damper_horizon_s)
        count = col.update(self.dyn.data, di)
        if not count:
            if self._pairs_set:  # clear the rows of the last active step once
                a[4:].fill(0.0)
                b[4:].fill(_FREE)
                self._pairs_set = False
            return
        self._pairs_set = True
        for k, on in enumerate(col.active):
            r = 4 + k
            if on:
                row = col.rows[k]
                d = float(col.distance[k])
                beta = -(xi / t) * (d - ds) / (di - ds) - float(row @ qd) / t
                a[r, :N] = -row
                b[r] = float(col.drift[k]) - beta
            else:
                a[r, :N] = 0.0
                b[r] = _FREE
