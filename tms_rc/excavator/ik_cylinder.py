"""HEAP's inverse-kinematics hierarchy for an excavator's front, solved in cylinder space.

Decision vector ``v = [w_swing, v_boom, v_arm, v_bucket]``: the piston velocities [m/s] of the boom, arm and bucket
cylinders (+ = extending) and the swing motor's speed. The swing is a rotary hydraulic motor, not a cylinder: its
"cylinder velocity" is the swing joint speed itself [rad/s] (its actuator map entry is 1). The joint velocities are
``qd = J_p(q)^-1 v`` with ``J_p = diag(1, dl_boom/dq, dl_arm/dq, dl_bucket/dq)`` (HEAP eq. 14 by virtual work; the
cylinder lengths and their derivatives come from the machine description's pins and bucket four-bar,
:mod:`tms_model.cylinders`). Solved by the strict-priority :class:`~tms_rc.excavator.hqp.HierarchicalQP` (the
joint-velocity IK's, general over the vector size) with HEAP's IK task list (Jud et al. 2021, "HEAP - The
autonomous walking excavator", sec. 4.3.2, eqs. 29-36; the cascade after Bellicoso et al. 2016), highest first:

1. pump flow ``sum_i a_i |v_i| <= Q_max`` over the functions on the main pumps (the description's
   ``flow_at_limit_lpm`` > 0: boom, arm, bucket on the ZX200; the swing has its own circuit), a_i the cap area when
   the cylinder extends and the rod area when it retracts: exactly, as 2^k rows (one per direction pattern). In
   joint space this is HEAP's configuration-dependent ``a^T J_p(q) qd``; in cylinder space the rows are constant;
2. cylinder velocity limits ``|v_i| <= v_max,i`` (settings, or by default the description's joint velocity limit
   times |J_p| at home, as the ID hierarchy takes them; the swing: its joint velocity limit);
3. cylinder position (stroke) limits as a velocity damper over a horizon T: ``l_min <= l + T v <= l_max``, the
   stroke ends being the cylinder lengths at the description's joint limits (each length is monotonic over its
   joint's range) less ``stroke_margin``; the swing is continuous (free rows);
4. collision: first-order velocity dampers (Faverjon & Tournassoud) ``d_dot >= -xi (d - d_s) / (d_i - d_s)``
   while ``d < d_i``, mapped through J_p^-1 (``qd = v / J_p``), in this order: (a) the bucket tip's and pin's
   height above ``ground_min_z`` and distance from the swing axis beyond ``body_min_radius`` (rows 0-3; the ID
   hierarchy's level 6 (a) rows, one order down); (b) self-collision between link primitives (rows 4..;
   ``self_collision`` settings, the ID's primitives and pairs: :class:`~tms_rc.excavator.collision.SelfCollision`
   on the kinematics' pinocchio model, closest points of boxes by coal), one row per pair
   ``-(n^T (J_b - J_a) / J_p) v <= xi_c (d - d_s) / (d_i - d_s)`` while the pair is within d_i, else free
   (:meth:`~tms_rc.excavator.collision.SelfCollision.first_order`'s rows; pairs whose bounding spheres are
   farther apart than d_i skip coal); (c) **hook**: ``IkSettings.extra_collision_rows`` more rows filled from
   ``solve(collision_rows=(A, b))``, rows ``A qd <= b`` in joint velocities (e.g. pairs of a machine-specific
   check outside :class:`~tms_rc.excavator.collision.CollisionSettings`); unused rows are free;
5. end-effector orientation: theta_w rate (bucket pin -> tip angle, :mod:`tms_model.excavator.kinematics`;
   ``[0, 1, 1, 1] J_p^-1 v``) = ``omega_ref + kp e_theta (+ ki, kd)``;
6. end-effector position: tip velocity ``J_tip J_p^-1 v = v_d``, v_d from HEAP eq. 36 (:class:`~.hermite.Pid`:
   ``v_ref + Kp e + Ki int(e) + Kd e_dot``; the integral is frozen on a step after the hierarchy gave way on this
   level, clamped, and charged only inside an error zone);
7. minimal cylinder velocity ``v = 0`` (whatever freedom is left).

Every buffer of a step is preallocated; the pump rows are constant (their OSQP matrix is never re-sent). Over the
piston control on the plant: :mod:`tms_rc.excavator.ik_drive`. Not yet done (``tms_rc/excavator/README.md``): a
node and a config file.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from tms_common.errors import ConfigError
from tms_model.cylinders import Cylinder, cylinder_length, moment_arm
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_rc.excavator.collision import CollisionSettings, SelfCollision
from tms_rc.excavator.hermite import Pid
from tms_rc.excavator.hqp import HierarchicalQP, HqpResult, LevelSpec

__all__ = ["IkSettings", "IkReference", "IkResult", "CylinderIkHQP", "LEVEL_NAMES"]

N = len(JOINTS)
#: right-hand side that leaves an inactive inequality row free
_FREE = 1e9
LEVEL_NAMES = ("pump_flow", "velocity_limits", "stroke_limits", "collision", "orientation", "position",
               "min_velocity")


@dataclass(frozen=True)
class IkSettings:
    """Control choices of the cylinder-space IK hierarchy (the machine's figures come from its description)."""

    rate_hz: float = 100.0  # [Hz] control rate (the PID's dt)
    kp_position: float = 2.0  # [1/s] HEAP eq. 36
    ki_position: float = 0.2  # [1/s^2]
    kd_position: float = 0.0  # [-]
    i_limit_position: float = 0.05  # [m s] bound of the integral per axis
    i_zone_position: float = 0.02  # [m] an axis integrates only while its error is within this
    kp_theta_w: float = 2.0  # [1/s]
    ki_theta_w: float = 0.0  # [1/s^2]
    i_limit_theta_w: float = 0.05  # [rad s]
    i_zone_theta_w: float = 0.02  # [rad]
    #: [m/s] the position task counts as given way (the PID integral holds) when its achieved tip velocity is this
    #: far from the command
    give_way_tolerance: float = 1e-3
    pump_flow_lpm: float | None = None  # [L/min] None: the description's pump_flow
    #: actuator speed limits (swing [rad/s], cylinders [m/s]); None: joint velocity limit x |J_p(home)| (swing: its
    #: joint velocity limit)
    speed_limits: tuple[float, ...] | None = None
    stroke_horizon_s: float = 0.2  # [s] T of the stroke damper: the last T of motion to a stroke end decays
    stroke_margin: float = 0.005  # [m] kept inside each stroke end
    ground_min_z: float = -2.5  # [m] bucket tip and pin above this (base_link), as the IK's collision setting
    body_min_radius: float = 3.2  # [m] tip and pin this far from the swing axis
    damper_influence: float = 0.5  # [m] d_i: a damper row acts below this distance
    damper_safety: float = 0.0  # [m] d_s: the distance the damper keeps
    damper_xi: float = 0.5  # [m/s] xi: the largest approach speed the damper allows at d_i
    #: link-primitive self-collision (level 4 (b)), as the ID's (:class:`~tms_rc.excavator.id_hqp.IdSettings`);
    #: HEAP's d_i, d_s and xi are not published: ours, the ID's values
    self_collision: bool = True
    self_collision_influence: float = 0.5  # [m] d_i: a pair's row acts below this distance
    self_collision_safety: float = 0.1  # [m] d_s: the distance the damper holds (approached exponentially)
    self_collision_xi: float = 0.5  # [m/s] xi: the largest approach speed a pair's row allows at d_i
    #: primitive sizes and pairs (:class:`~tms_rc.excavator.collision.CollisionSettings`), the ID's default
    collision_primitives: CollisionSettings = field(default_factory=CollisionSettings)
    extra_collision_rows: int = 0  # rows of the collision level filled by solve(collision_rows=...), after the pairs
    eps: float = 1e-6  # OSQP tolerances
    max_iter: int = 2000
    regularisation: float = 1e-6
    fix_tolerance: float = 1e-5


@dataclass
class IkReference:
    """One step's references in base_link: tip position [m] and velocity [m/s], theta_w [rad] and its rate."""

    position: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    theta_w: float = 0.0
    theta_w_rate: float = 0.0


@dataclass
class IkResult:
    """Actuator velocities ``v`` (swing [rad/s], cylinders [m/s]), joint velocities ``qd`` [rad/s], the position
    task's command (eq. 36) and what the solution gives, the theta_w rate commanded and achieved, the main pumps'
    flow [m^3/s], the cylinder lengths [m] at q (swing: nan) and the hierarchy's own result."""

    v: np.ndarray
    qd: np.ndarray
    tip_velocity_cmd: np.ndarray
    tip_velocity: np.ndarray
    theta_w_rate_cmd: float
    theta_w_rate: float
    pump_flow: float
    lengths: np.ndarray
    hqp: HqpResult
    #: the position task was not met within ``give_way_tolerance`` (a higher task held the tip back): the PID
    #: integral holds on the next step
    gave_way: bool = False


class CylinderIkHQP:
    """The cylinder-space IK hierarchy of one excavator front; call :meth:`solve` once per control step.

    Args:
        kin: the front's kinematics (its description gives joints, limits, cylinders, pump flow).
        settings: the control choices.
    """

    def __init__(self, kin: ExcavatorKinematics, settings: IkSettings | None = None) -> None:
        s = settings or IkSettings()
        machine = kin.machine
        cyl = machine.cylinders
        if cyl is None or cyl.swing is None:
            raise ConfigError(f"{machine.source}: the cylinder-space IK needs cylinders (with swing)")
        if s.extra_collision_rows < 0:
            raise ValueError(f"extra_collision_rows must be >= 0, got {s.extra_collision_rows}")
        self.kin, self.settings = kin, s
        self.collision = SelfCollision(kin.model, machine, s.collision_primitives) if s.self_collision else None
        if self.collision is not None and not 0.0 <= s.self_collision_safety < s.self_collision_influence:
            raise ValueError(f"self-collision: need 0 <= d_s < d_i, got d_s={s.self_collision_safety}, "
                             f"d_i={s.self_collision_influence}")
        self._n_pairs = len(self.collision.names) if self.collision is not None else 0
        self._pairs_set = False
        self.dt = 1.0 / s.rate_hz
        by_joint = {c.joint: c for c in cyl.all}
        self.cylinders: list[Cylinder | None] = [None]
        self._planes: list[tuple[tuple[float, float], float]] = [((0.0, 0.0), 0.0)]
        for joint in machine.joints[1:]:
            c = by_joint.get(joint.name)
            if c is None:
                raise ConfigError(f"{machine.source}: cylinders: no cylinder drives {joint.name}")
            self.cylinders.append(c)
            self._planes.append(((joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]))
        # oil per unit actuator speed in each direction: cylinders cap / rod area, the swing motor its displacement
        area_ext = [cyl.swing.displacement_per_rad] + [c.cap_area for c in self.cylinders[1:]]
        area_ret = [cyl.swing.displacement_per_rad] + [c.rod_area for c in self.cylinders[1:]]
        self.area_extend, self.area_retract = np.array(area_ext), np.array(area_ret)
        pump = tuple(i for i, j in enumerate(machine.joints) if machine.drives[j.name].flow_at_limit > 0.0)
        self.pump_joints = pump
        flow_lpm = s.pump_flow_lpm if s.pump_flow_lpm is not None else machine.pump_flow
        self.q_max = (flow_lpm or math.inf) / 60000.0  # [m^3/s]
        # stroke ends: lengths at the joint limits (monotonic over the range), less the margin
        lim = kin.limits
        self.l_min = np.full(N, -math.inf)
        self.l_max = np.full(N, math.inf)
        for i in range(1, N):
            ends = [self._length(i, float(lim.lower[i])), self._length(i, float(lim.upper[i]))]
            self.l_min[i], self.l_max[i] = min(ends) + s.stroke_margin, max(ends) - s.stroke_margin
        self._gains = np.ones(N)
        self._gains[1:] = [self._gain(i, float(kin.home[i])) for i in range(1, N)]
        self.speed_limits = (np.array(s.speed_limits, dtype=float) if s.speed_limits is not None
                             else lim.velocity * np.abs(self._gains))
        if self.speed_limits.shape != (N,):
            raise ValueError(f"speed_limits needs {N} values, got {self.speed_limits.tolist()}")
        self._n_extra = s.extra_collision_rows
        # collision: ground + swing axis of tip and pin, one row per primitive pair, then the hook's rows
        rows = (max(2 ** len(pump), 1), 2 * N, 2 * N, 4 + self._n_pairs + self._n_extra, 1, 3, N)
        kinds = ("ineq", "ineq", "ineq", "ineq", "eq", "eq", "eq")
        self.levels = [LevelSpec(name, kind, r) for name, kind, r in zip(LEVEL_NAMES, kinds, rows, strict=True)]
        self.hqp = HierarchicalQP(N, self.levels, eps=s.eps, max_iter=s.max_iter, regularisation=s.regularisation,
                                  fix_tolerance=s.fix_tolerance)
        # task buffers (A, b) per level, filled in place; constant parts written once
        self._a = [np.zeros((lv.rows, N)) for lv in self.levels]
        self._b = [np.zeros(lv.rows) for lv in self.levels]
        self._tasks = list(zip(self._a, self._b, strict=True))
        eye = np.eye(N)
        # 1. pump rows over v, scaled by Q_max: sign pattern x area of that direction
        for r, signs in enumerate(itertools.product((1.0, -1.0), repeat=len(pump))):
            for sgn, i in zip(signs, pump, strict=True):
                self._a[0][r, i] = sgn * (self.area_extend[i] if sgn > 0 else self.area_retract[i]) / self.q_max
        self._b[0][:] = 1.0 if pump else _FREE
        # 2. and 3. boxes [I; -I] (the hierarchy takes their closed form)
        for k in (1, 2):
            self._a[k][:N] = eye
            self._a[k][N:] = -eye
        self._b[1][:N] = self.speed_limits
        self._b[1][N:] = self.speed_limits
        self._a[6][:] = eye  # 7. minimal cylinder velocity, b = 0
        self._b[3][4:] = _FREE
        self._ginv = np.ones(N)
        self._lengths = np.full(N, math.nan)
        self._swing_xy = np.array(kin.swing_origin[:2], dtype=float)
        self._rate_row = kin.theta_w_jacobian()
        self.pid = Pid(s.kp_position, s.ki_position, s.kd_position, self.dt, s.i_limit_position, dim=3,
                       i_zone=s.i_zone_position)
        self.pid_theta_w = Pid(s.kp_theta_w, s.ki_theta_w, 0.0, self.dt, s.i_limit_theta_w, dim=1,
                               i_zone=s.i_zone_theta_w)
        self._hold = False  # the last step's position task gave way: do not integrate this step
        self._last_error: np.ndarray | None = None
        self._ref_theta = np.zeros(1)
        self._err_theta = np.zeros(1)

    # ------------------------------------------------------------------ actuator map
    def _length(self, i: int, q: float) -> float:
        origin, pitch = self._planes[i]
        cyl = self.cylinders[i]
        assert cyl is not None
        return cylinder_length(cyl, origin, pitch, q)

    def _gain(self, i: int, q: float) -> float:
        origin, pitch = self._planes[i]
        cyl = self.cylinders[i]
        assert cyl is not None
        return moment_arm(cyl, origin, pitch, q)

    def actuator_state(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(J_p diagonal, cylinder lengths) at ``q``: swing 1 and nan, cylinders dl/dq [m/rad] and l [m].

        Beyond the bucket four-bar's closing range the last value computed is kept (as the plant does). Buffers
        overwritten by the next call.
        """
        g, lengths = self._gains, self._lengths
        for i in range(1, N):
            try:
                g[i] = self._gain(i, float(q[i]))
                lengths[i] = self._length(i, float(q[i]))
            except ValueError:
                if math.isnan(lengths[i]):
                    raise
        return g, lengths

    def pump_flow(self, v: np.ndarray) -> float:
        """[m^3/s] the main pumps' flow at actuator velocities ``v`` (area by direction x |speed|)."""
        return float(sum(
            (self.area_extend[i] if v[i] > 0 else self.area_retract[i]) * abs(float(v[i])) for i in self.pump_joints
        ))

    def reset(self) -> None:
        """A new motion: forget the PID integrals and the last error."""
        self.pid.reset()
        self.pid_theta_w.reset()
        self._hold = False
        self._last_error = None

    # ------------------------------------------------------------------ one step
    def solve(
        self, q: np.ndarray, ref: IkReference, qd: np.ndarray | None = None,
        collision_rows: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> IkResult:
        """Actuator and joint velocities for the joint positions ``q`` and this step's references.

        Args:
            q: joint positions [rad].
            ref: tip position / velocity and theta_w / rate references (e.g. from :class:`~.hermite.HermiteReference`).
            qd: measured joint velocities (the PID's e_dot = v_ref - J qd); None: the error's finite difference.
            collision_rows: ``(A, b)`` with ``A qd <= b`` in joint velocities, at most ``extra_collision_rows`` rows,
                added to the collision level after the primitive pairs' own rows (the hook for more dampers).
        """
        s = self.settings
        q = np.asarray(q, dtype=float)
        kin = self.kin
        kin.forward(q)
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        tip = kin.data.oMf[kin.tip_frame].translation
        pin_p = kin.data.oMf[kin.pin_frame].translation
        jt = pin.getFrameJacobian(kin.model, kin.data, kin.tip_frame, lwa)[:3]
        jp = pin.getFrameJacobian(kin.model, kin.data, kin.pin_frame, lwa)[:3]
        g, lengths = self.actuator_state(q)
        ginv = np.divide(1.0, g, out=self._ginv)
        a, b = self._a, self._b

        # 3. stroke damper: v <= (l_max - l) / T, -v <= (l - l_min) / T (swing: free)
        t = s.stroke_horizon_s
        b[2][0] = b[2][N] = _FREE
        np.subtract(self.l_max[1:], lengths[1:], out=b[2][1:N])
        np.subtract(lengths[1:], self.l_min[1:], out=b[2][N + 1:])
        b[2][1:N] /= t
        b[2][N + 1:] /= t

        # 4. clearance dampers of tip and pin, the primitive pairs, the hook's rows
        self._dampers(tip, jt, pin_p, jp, ginv)
        if self.collision is not None:
            self._pair_dampers(ginv)
        if self._n_extra:
            first = 4 + self._n_pairs
            ax, bx = a[3][first:], b[3][first:]
            ax.fill(0.0)
            bx.fill(_FREE)
            if collision_rows is not None:
                rows_q, rhs = np.atleast_2d(collision_rows[0]), np.atleast_1d(collision_rows[1])
                m = rows_q.shape[0]
                if m > self._n_extra or rhs.shape != (m,):
                    raise ValueError(f"collision_rows: {m} rows / {rhs.shape} bounds; room for {self._n_extra}")
                np.multiply(rows_q, ginv, out=ax[:m])
                bx[:m] = rhs
        elif collision_rows is not None and np.size(collision_rows[1]):
            raise ValueError("collision_rows given but IkSettings.extra_collision_rows is 0")

        # 5. theta_w rate
        np.multiply(self._rate_row, ginv, out=a[4][0])
        self._err_theta[0] = ref.theta_w - kin.theta_w(q)
        self._ref_theta[0] = ref.theta_w_rate
        om_d = float(self.pid_theta_w.update(self._err_theta, 0.0, self._ref_theta, hold=self._hold)[0])
        b[4][0] = om_d

        # 6. tip velocity, HEAP eq. 36
        np.multiply(jt, ginv, out=a[5])
        err = ref.position - tip
        if qd is not None:
            e_dot = ref.velocity - jt @ np.asarray(qd, dtype=float)
        elif self._last_error is not None:
            e_dot = (err - self._last_error) / self.dt
        else:
            e_dot = np.zeros(3)
        self._last_error = err
        b[5][:] = self.pid.update(err, e_dot, ref.velocity, hold=self._hold)

        res = self.hqp.solve(self._tasks)
        v = res.x
        qd_out = v * ginv
        tip_v = jt @ qd_out
        cmd = b[5].copy()
        self._hold = bool(np.abs(tip_v - cmd).max() > s.give_way_tolerance)
        return IkResult(v=v, qd=qd_out, tip_velocity_cmd=cmd, tip_velocity=tip_v, theta_w_rate_cmd=om_d,
                        theta_w_rate=float(self._rate_row @ qd_out), pump_flow=self.pump_flow(v),
                        lengths=lengths.copy(), hqp=res, gave_way=self._hold)

    def _dampers(self, tip, jt, pin_p, jp, ginv) -> None:
        """Collision rows ``-d_dot(v) <= xi (d - d_s) / (d_i - d_s)`` (ground, swing axis) of tip and pin."""
        s = self.settings
        a, b = self._a[3], self._b[3]
        di, ds, xi = s.damper_influence, s.damper_safety, s.damper_xi
        scale = xi / (di - ds)
        r = 0
        for p, j in ((tip, jt), (pin_p, jp)):
            # ground: d = z - z_min, d_dot = J_z qd
            d = float(p[2]) - s.ground_min_z
            np.multiply(j[2], -ginv, out=a[r])
            b[r] = scale * (d - ds) if d < di else _FREE
            r += 1
            # swing axis: rho = |p_xy - o_xy|, rho_dot = n . J_xy qd
            rel = p[:2] - self._swing_xy
            rho = max(math.hypot(float(rel[0]), float(rel[1])), 1e-6)
            np.multiply(-(rel @ j[:2]) / rho, ginv, out=a[r])
            d = rho - s.body_min_radius
            b[r] = scale * (d - ds) if d < di else _FREE
            r += 1

    def _pair_dampers(self, ginv) -> None:
        """Collision rows 4.. : per primitive pair ``-(row / J_p) v <= xi (d - d_s)/(d_i - d_s)`` while d < d_i,
        else free (zero row). :attr:`kin`'s pinocchio data holds this step's placements and joint Jacobians."""
        s = self.settings
        col = self.collision
        assert col is not None
        a, b = self._a[3], self._b[3]
        di, ds, xi = s.self_collision_influence, s.self_collision_safety, s.self_collision_xi
        end = 4 + self._n_pairs
        if not col.update(self.kin.data, di, drift=False):
            if self._pairs_set:  # clear the rows of the last active step once
                a[4:end].fill(0.0)
                b[4:end].fill(_FREE)
                self._pairs_set = False
            return
        self._pairs_set = True
        scale = xi / (di - ds)
        for k, on in enumerate(col.active):
            r = 4 + k
            if on:  # row @ qd >= -xi (d - d_s)/(d_i - d_s), qd = v / J_p
                np.multiply(col.rows[k], -ginv, out=a[r])
                b[r] = scale * (float(col.distance[k]) - ds)
            else:
                a[r].fill(0.0)
                b[r] = _FREE
