"""The excavator arm controller: HEAP-style hierarchical inverse kinematics at 100 Hz (any excavator kind).

Every control step turns the measured joint angles into joint-velocity commands by solving
:class:`~tms_rc.excavator.hqp.HierarchicalQP` with these priorities, highest first:

1. pump flow: ``sum_i flow_i |dq_i| <= pump_flow`` (16 linear rows, one per sign pattern; the pump flow and
   each joint's flow identified on the machine, :mod:`tms_rc.identify`);
2. joint (cylinder) velocity limits, rate-limited by the acceleration limits;
3. joint position limits (velocity bounds that shrink towards a limit, so no step crosses it);
4. ground and self-collision avoidance of the bucket tip and pin (height and distance from the
   swing axis, linearised with the pinocchio Jacobians);
5. bucket-edge angle theta_w;          (joint-space segments: the joint reference instead of 5-6)
6. bucket-tip position;
7. least joint motion.

References run from the state at segment start to the target on trapezoidal speed profiles: joint
space with every joint at the same fraction of its move, Cartesian segments along the tip line and the
edge angle; the most limited of the joints (velocity, acceleration, pump-flow share) and the tip / edge
speed and acceleration limits set the timing. The task rows ask for the reference velocity plus PID
feedback on its position. The machine's command dead time and lag (identified on it over CAN,
``config/tms_rc/identified/<machine>.yaml``) are compensated with a Smith
predictor: the controller acts on the state predicted for when its command takes effect (measured
state + what the lag still moves + commands still in flight), joints' delays are equalised in the
output, and each reference starts at the predicted state, so the machine follows it one predictor
horizon (``preview_s``) later.

Pure Python (numpy, pinocchio via tms_model.excavator.kinematics, OSQP); the node is
:mod:`tms_rc.nodes.excavator_arm_controller`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import load_schema, read_schema, setting
from tms_model.excavator import codes
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.excavator.targets import JointTarget, Target
from tms_model.geometry import wrap_angle
from tms_model.machines import EXCAVATOR, Machine
from tms_rc.excavator.hqp import HierarchicalQP, LevelSpec

__all__ = [
    "ControllerConfig",
    "ControllerSettings",
    "controller_config",
    "IdentifiedHydraulics",
    "IdentifiedFile",
    "IdentifiedJoint",
    "identified_file",
    "load_identified",
    "load_controller_config",
    "load_controller_settings",
    "settings_path",
    "TrapezoidSegment",
    "ControllerStatus",
    "ArmController",
]

N = len(JOINTS)
#: [s] shortest segment: a near-zero move still gets a smooth reference the PID can follow
MIN_SEGMENT_S = 0.5
#: fraction of the pump flow a segment's timing plans with (the rest is the PID's margin)
PLANNED_PUMP_SHARE = 0.8
SETTINGS_FILE = "excavator_arm_controller.yaml"


def _per_joint_values(name: str, values: Mapping[str, float]) -> None:
    """ValueError unless ``values`` names exactly the excavator's joints."""
    if set(values) != set(JOINTS):
        raise ValueError(f"{name}: expected a value for each of {list(JOINTS)}, got {sorted(values)}")


@dataclass(frozen=True)
class PidGains:
    """One PID of the task rows: gains and the conditional integration's clamp and zone."""

    kp: float = setting(lo=0.0, doc="[1/s] proportional gain")
    ki: float = setting(lo=0.0, doc="[1/s^2] integral gain")
    kd: float = setting(lo=0.0, doc="[-] derivative gain")
    i_limit: float = setting(lo=0.0, doc="[m or rad] clamp of the integral")
    i_zone: float = setting(lo=0.0, doc="[m or rad] the integral accumulates only while the error is inside")


@dataclass(frozen=True)
class PidSettings:
    """The PIDs of the tasks: tip position, bucket-edge angle theta_w, joint-space reference."""

    position: PidGains
    theta_w: PidGains
    joint: PidGains


@dataclass(frozen=True)
class CollisionSettings:
    """Ground and self-collision avoidance of the bucket tip and pin, base_link frame [m]."""

    ground_min_z: float = setting(doc="[m] bucket tip and pin never below this height")
    body_min_radius: float = setting(lo=0.0, doc="[m] tip and pin keep this distance from the swing axis")
    gain: float = setting(lo=0.0, doc="[1/s] approach gain of the linearised distance constraints")


@dataclass(frozen=True)
class IdentifiedHydraulics:
    """What ``tms_rc_identify`` measured on one machine over its CAN bus, in :data:`JOINTS` order: command dead time
    (CAN link included) and lag [s], flow into each drive per unit joint speed [L/min per rad/s] (the larger of the
    two directions) and the pump flow [L/min]."""

    source: str
    dead_time_s: np.ndarray
    lag_s: np.ndarray
    flow_per_rad_s: np.ndarray
    pump_flow_lpm: float


def _remake(name: str) -> str:
    return (f"make it with `tms_rc_identify --machine {name}` against the machine's bus, or "
            f"`tms_rc_identify --machine {name} --plant-config config/sim/<plant>.yaml` against a simulated one")


@dataclass(frozen=True)
class IdentifiedJoint:
    """One joint of ``config/tms_rc/identified/<name>.yaml`` (written by :func:`tms_rc.identify.render`); pairs are
    [negative, positive direction], null = not measured (only what the controller does not use may be null)."""

    dead_time_s: float = setting(lo=0.0, doc="[s] first response after a velocity step (CAN link included)")
    lag_s: float = setting(lo=0.0, doc="[s] first-order lag")
    flow_lpm_per_rad_s: tuple[float, float] = setting(lo=0.0, doc="[L/min per rad/s] flow into the drive")
    gain: float | None = setting(None, lo=0.0, doc="steady speed / command")
    saturated_speed_rad_s: tuple[float | None, float | None] | None = setting(None, lo=0.0)
    dead_band_rad_s: tuple[float | None, float | None] | None = setting(None, lo=0.0)
    bandwidth_hz: float | None = setting(None, lo=0.0, doc="-3 dB of a chirp")


@dataclass(frozen=True)
class IdentifiedFile:
    """The schema of ``config/tms_rc/identified/<name>.yaml``: unknown keys refused, types and bounds checked."""

    machine: str = setting(doc="the machine's name on the site")
    pump_flow_lpm: float = setting(lo=1.0, doc="[L/min] boom+arm+bucket together at full command")
    joints: dict[str, IdentifiedJoint] = setting(doc="one entry per front joint")
    pump_saturated: bool = setting(True, doc="false: the pump flow is a lower bound only")


def load_identified(path: str | Path, name: str) -> IdentifiedHydraulics:
    """The identified hydraulics of machine ``name`` from ``path``, read through :mod:`tms_common.schema`
    (:class:`IdentifiedFile`); a ConfigError ``file:line: key: problem`` (and the command that makes the file)
    otherwise."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no identified hydraulics of {name}: {_remake(name)}")
    try:
        data, where = load_yaml(path)
        doc = read_schema(IdentifiedFile, data, where)
        if doc.machine != name:
            raise where.error(("machine",), f"machine: expected {name!r}, got {doc.machine!r}")
        if set(doc.joints) != set(JOINTS):
            raise where.error(("joints",), f"joints: expected an entry for each of {list(JOINTS)}, got "
                              f"{sorted(doc.joints)}")
    except ConfigError as exc:
        raise ConfigError(f"{exc} ({_remake(name)})") from None

    def per_joint(field_: str) -> np.ndarray:
        values = [getattr(doc.joints[j], field_) for j in JOINTS]
        # [negative, positive direction]: the pump row takes |dq|, the larger
        return np.array([max(v) if isinstance(v, tuple) else v for v in values], dtype=float)

    return IdentifiedHydraulics(
        source=str(path),
        dead_time_s=per_joint("dead_time_s"),
        lag_s=per_joint("lag_s"),
        flow_per_rad_s=per_joint("flow_lpm_per_rad_s"),
        pump_flow_lpm=float(doc.pump_flow_lpm),
    )


@dataclass(frozen=True)
class OsqpSettings:
    """OSQP settings of every level of the hierarchical QP."""

    eps: float = setting(1.0e-5, lo=0.0)
    max_iter: int = setting(1000, lo=1)
    polish: bool = False
    regularisation: float = setting(1.0e-4, lo=0.0)
    fix_tolerance: float = setting(1.0e-4, lo=0.0)


@dataclass(frozen=True, kw_only=True)
class ControllerSettings:
    """The control choices of ``config/tms_rc/excavator_arm_controller.yaml``; the machine's figures come from its
    description (geometry, joint limits) and its identified file (pump flow, flow drawn per joint, hydraulic delays;
    :func:`controller_config`)."""

    rate_hz: float = setting(lo=1.0, doc="[Hz] control rate")
    position_limit_gain: dict[str, float] = setting(lo=0.0, doc="[1/s] approach gain towards a position limit")
    position_limit_margin: float = setting(lo=0.0, doc="[rad] kept inside the URDF limits")
    use_acceleration_limits: bool = setting(True, doc="rate-limit |ddq| to the joints' acceleration limits")
    collision: CollisionSettings = setting(doc="ground and self-collision avoidance")
    pid: PidSettings = setting(doc="task PIDs")
    max_tip_speed: float = setting(lo=1e-6, doc="[m/s] Cartesian segments' peak tip speed")
    max_theta_w_rate: float = setting(lo=1e-6, doc="[rad/s] Cartesian segments' peak edge-angle rate")
    max_tip_accel: float = setting(lo=1e-6, doc="[m/s^2]")
    max_theta_w_accel: float = setting(lo=1e-6, doc="[rad/s^2]")
    #: one fraction for every joint or a mapping joint -> fraction (a value-dependent shape: checked below)
    joint_speed_scale: Any = setting(doc="fraction of each joint's velocity and acceleration limits")
    transport_delay_s: float = setting(0.0, lo=0.0, hi=1.0,
                                       doc="[s] transport outside the identified CAN link, added to the dead times")
    identified: str = setting("identified/{name}.yaml",
                              doc="the identified hydraulics per machine name, relative to config/tms_rc/")
    goal_tolerance_m: float = setting(lo=1e-6)
    goal_tolerance_rad: float = setting(lo=1e-6)
    via_tolerance_m: float = setting(0.05, lo=1e-6)
    via_tolerance_rad: float = setting(0.05, lo=1e-6)
    via_stall_s: float = setting(0.0, lo=0.0, doc="[s] a via segment followed by another whose tip came no closer by "
                                 "via_stall_progress_m this long after its reference ended is passed on (0: never)")
    via_stall_progress_m: float = setting(0.05, lo=0.0, doc="[m] progress that counts as moving on a via segment")
    rest_speed: float = setting(lo=0.0, doc="[rad/s] joints at rest below this")
    settle_s: float = setting(lo=0.0, doc="[s] at rest this long before a goal succeeds")
    segment_timeout_margin_s: float = setting(lo=1e-3, doc="[s] a segment times out after its duration + this")
    stop_timeout_s: float = setting(15.0, lo=1e-3, doc="[s] stopping ends after this even if never at rest")
    osqp: OsqpSettings = setting(default_factory=OsqpSettings)

    def __post_init__(self) -> None:
        _per_joint_values("position_limit_gain", self.position_limit_gain)
        scale = self.joint_speed_scale
        if isinstance(scale, dict):
            _per_joint_values("joint_speed_scale", scale)
            values = list(scale.values())
        else:
            values = [scale]
        if not all(isinstance(v, int | float) and not isinstance(v, bool) and 0.0 < v <= 1.0 for v in values):
            raise ValueError(f"joint_speed_scale: expected a fraction in (0, 1] or a mapping joint -> fraction "
                             f"(of the joint limits), got {scale!r}")


@dataclass(frozen=True, kw_only=True)
class ControllerConfig:
    """Parameters of :class:`ArmController`: the settings file's choices with one machine's figures
    (:func:`controller_config`); per-joint arrays in :data:`JOINTS` order."""

    rate_hz: float
    pump_flow_lpm: float
    flow_per_rad_s: np.ndarray
    position_limit_gain: np.ndarray
    position_limit_margin: float
    use_acceleration_limits: bool
    ground_min_z: float
    body_min_radius: float
    collision_gain: float
    pid: Mapping[str, PidGains]
    max_tip_speed: float
    max_theta_w_rate: float
    max_tip_accel: float
    max_theta_w_accel: float
    joint_speed_scale: np.ndarray
    dead_time_s: np.ndarray
    lag_s: np.ndarray
    goal_tolerance_m: float
    goal_tolerance_rad: float
    via_tolerance_m: float
    via_tolerance_rad: float
    rest_speed: float
    via_stall_s: float
    via_stall_progress_m: float
    settle_s: float
    segment_timeout_margin_s: float
    stop_timeout_s: float
    osqp: OsqpSettings
    machine: str = ""  # the description's model name, for messages

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz


def settings_path() -> Path:
    """``config/tms_rc/excavator_arm_controller.yaml``."""
    return Path(config_path("tms_rc", SETTINGS_FILE))


def load_controller_settings(path: str | Path | None = None) -> ControllerSettings:
    """The control choices of ``path`` (default :func:`settings_path`); errors ``file:line: key: problem``."""
    return load_schema(ControllerSettings, path if path is not None else settings_path())


def identified_file(settings: ControllerSettings, name: str) -> Path:
    """The identified-hydraulics file of machine ``name``: ``settings.identified`` with ``{name}`` filled in,
    relative to ``config/tms_rc/``."""
    path = Path(settings.identified.format(name=name))
    return path if path.is_absolute() else Path(config_path("tms_rc")) / path


def controller_config(settings: ControllerSettings, machine: Machine,
                      identified: IdentifiedHydraulics | None = None) -> ControllerConfig:
    """The controller of ``machine`` (an excavator description: geometry, joint limits) with the choices ``settings``
    and its hydraulics ``identified`` (default: read from :func:`identified_file` of its name)."""
    machine.require(EXCAVATOR)
    hyd = identified or load_identified(identified_file(settings, machine.model_name), machine.model_name)
    scale = settings.joint_speed_scale
    if isinstance(scale, dict):
        speed_scale = np.array([float(scale[j]) for j in JOINTS])
    else:
        speed_scale = np.full(N, float(scale))
    # the identified dead time was measured over the CAN link; the controller's path to it (DDS) comes on top
    dead = hyd.dead_time_s + settings.transport_delay_s
    lag = hyd.lag_s.copy()
    col, pid = settings.collision, settings.pid
    return ControllerConfig(
        rate_hz=settings.rate_hz,
        pump_flow_lpm=hyd.pump_flow_lpm,
        flow_per_rad_s=hyd.flow_per_rad_s.copy(),
        position_limit_gain=np.array([settings.position_limit_gain[j] for j in JOINTS]),
        position_limit_margin=settings.position_limit_margin,
        use_acceleration_limits=settings.use_acceleration_limits,
        ground_min_z=col.ground_min_z,
        body_min_radius=col.body_min_radius,
        collision_gain=col.gain,
        pid=MappingProxyType({"position": pid.position, "theta_w": pid.theta_w, "joint": pid.joint}),
        max_tip_speed=settings.max_tip_speed,
        max_theta_w_rate=settings.max_theta_w_rate,
        max_tip_accel=settings.max_tip_accel,
        max_theta_w_accel=settings.max_theta_w_accel,
        joint_speed_scale=speed_scale,
        dead_time_s=dead,
        lag_s=lag,
        goal_tolerance_m=settings.goal_tolerance_m,
        goal_tolerance_rad=settings.goal_tolerance_rad,
        via_tolerance_m=settings.via_tolerance_m,
        via_tolerance_rad=settings.via_tolerance_rad,
        via_stall_s=settings.via_stall_s,
        via_stall_progress_m=settings.via_stall_progress_m,
        rest_speed=settings.rest_speed,
        settle_s=settings.settle_s,
        segment_timeout_margin_s=settings.segment_timeout_margin_s,
        stop_timeout_s=settings.stop_timeout_s,
        osqp=settings.osqp,
        machine=machine.model_name,
    )


def load_controller_config(machine: Machine, path: str | Path | None = None) -> ControllerConfig:
    """:func:`controller_config` of ``machine`` with the settings file ``path`` (default :func:`settings_path`)."""
    return controller_config(load_controller_settings(path), machine)


# ---------------------------------------------------------------------------------------------- references
@dataclass(frozen=True)
class TrapezoidSegment:
    """Straight move from ``p0`` to ``p1`` over ``duration`` with a trapezoidal speed profile.

    The path fraction accelerates uniformly for ``accel_time``, coasts, and decelerates for ``accel_time``
    (``accel_time = duration / 2``: triangular). For a given peak acceleration and speed this is the
    shortest rest-to-rest move: a cubic needs sqrt(6/4) = 1.22 times as long at the same peak acceleration
    (the swings, acceleration-limited, are most of a load pass). Joint-space segments run on one (every
    joint the same fraction of its move); a Cartesian segment's tip line and edge angle on two with the
    same timing.
    """

    p0: np.ndarray
    p1: np.ndarray
    duration: float
    accel_time: float

    def __post_init__(self) -> None:
        if not (self.duration > 0 and 0 < self.accel_time <= 0.5 * self.duration + 1e-12):
            raise ValueError(f"TrapezoidSegment: need 0 < accel_time {self.accel_time} <= duration / 2 "
                             f"(duration {self.duration})")

    @staticmethod
    def timing(speed: float, accel: float, min_duration: float = 0.0) -> tuple[float, float]:
        """(duration, accel_time) of the fastest path-fraction profile with peak ``speed`` [1/s] and
        ``accel`` [1/s^2]; a profile shorter than ``min_duration`` is slowed uniformly to it."""
        if speed * speed >= accel:  # the top speed is never reached: triangular
            t_a = 1.0 / math.sqrt(accel)
            dur = 2.0 * t_a
        else:
            t_a = speed / accel
            dur = 1.0 / speed + t_a
        if dur < min_duration:
            t_a *= min_duration / dur
            dur = min_duration
        return dur, t_a

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) at time ``t`` (clamped to [0, duration])."""
        dur, t_a = self.duration, self.accel_time
        speed = 1.0 / (dur - t_a)
        accel = speed / t_a
        t = min(max(t, 0.0), dur)
        if t < t_a:
            s, ds = 0.5 * accel * t * t, accel * t
        elif t <= dur - t_a:
            s, ds = 0.5 * speed * t_a + speed * (t - t_a), speed
        else:
            rest = dur - t
            s, ds = 1.0 - 0.5 * accel * rest * rest, accel * rest
        delta = self.p1 - self.p0
        return self.p0 + s * delta, ds * delta


@dataclass
class ControllerStatus:
    """What the controller is doing: ``mode`` idle | moving | stopping; ``result`` set when a run ends."""

    mode: str = "idle"
    segment: int = 0
    segments: int = 0
    label: str = ""
    distance_remaining: float = 0.0
    result: int | None = None
    message: str = ""


class _Pid:
    def __init__(self, gains: PidGains, dim: int, dt: float) -> None:
        self.kp, self.ki, self.kd = gains.kp, gains.ki, gains.kd
        self.limit = gains.i_limit
        self.zone = gains.i_zone  # integrate only components with |error| <= i_zone
        self.dt = dt
        self.integral = np.zeros(dim)
        self.prev: np.ndarray | None = None

    def reset(self) -> None:
        self.integral[:] = 0.0
        self.prev = None

    def __call__(self, error: np.ndarray, dt: float | None = None, integrate: bool = True) -> np.ndarray:
        """PID output; ``integrate`` False holds the integral (conditional integration, anti-windup)."""
        dt = self.dt if dt is None else dt
        if integrate:
            inside = np.abs(error) <= self.zone
            self.integral = np.where(
                inside, np.clip(self.integral + error * dt, -self.limit, self.limit), self.integral
            )
        deriv = np.zeros_like(error) if self.prev is None or dt <= 0 else (error - self.prev) / dt
        self.prev = error.copy()
        return self.kp * error + self.ki * self.integral + self.kd * deriv


# ---------------------------------------------------------------------------------------------- controller
class ArmController:
    """The hierarchical arm controller; call :meth:`step` once per control period.

    Args:
        kin: the excavator's kinematic model (its description: joint limits).
        cfg: controller parameters (:func:`controller_config` of the same description).
    """

    SAFETY_LEVELS = (
        LevelSpec("pump_flow", "ineq", 2**N),
        LevelSpec("joint_velocity", "ineq", 2 * N),
        LevelSpec("position_limits", "ineq", 2 * N),
        LevelSpec("collision", "ineq", 4),
    )

    def __init__(self, kin: ExcavatorKinematics, cfg: ControllerConfig) -> None:
        self.kin = kin
        self.cfg = cfg
        self.dt = cfg.dt
        lim = kin.limits
        osqp_cfg = dataclasses.asdict(cfg.osqp)
        self.hqp_cartesian = HierarchicalQP(
            N,
            [
                *self.SAFETY_LEVELS,
                LevelSpec("theta_w", "eq", 1),
                LevelSpec("position", "eq", 3),
                LevelSpec("least_motion", "eq", N),
            ],
            **osqp_cfg,
        )
        self.hqp_joint = HierarchicalQP(
            N, [*self.SAFETY_LEVELS, LevelSpec("joint", "eq", N), LevelSpec("least_motion", "eq", N)], **osqp_cfg
        )
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=N)))
        self._pump_a = signs * cfg.flow_per_rad_s
        self._pump_b = np.full(2**N, cfg.pump_flow_lpm)
        self._eye2 = np.vstack([np.eye(N), -np.eye(N)])
        self._lower, self._upper = lim.lower, lim.upper
        # Smith predictor with equalised delays (dead time + lag, as steps).
        delays = cfg.dead_time_s + cfg.lag_s
        self._horizon_steps = int(round(float(np.max(delays)) / self.dt))
        # Each joint's extra command delay [s] equalising it to the slowest joint; applied on time stamps
        # (not step counts), so late ticks do not stretch a joint's delay beyond what the predictor assumes.
        self._extra_s = np.round((float(np.max(delays)) - np.asarray(delays, dtype=float)) / self.dt) * self.dt
        self.preview_s = self._horizon_steps * self.dt
        # Commands in flight as (command, how long it was applied [s]); the newest one's duration is only
        # known at the next step (time-stamped steps) and counts as one period until then. The predictor
        # sums command x duration over the last preview_s seconds, so a controller whose ticks are late
        # or skipped (sim-time timer under CPU load) still predicts what the plant really received.
        self._in_flight: deque[np.ndarray] = deque()
        self._in_flight_dur: deque[float] = deque()
        self._in_flight_sum = np.zeros(N)  # running sum of command x duration (rad) over the deque
        self._in_flight_time = 0.0  # running sum of the durations [s]
        self._last_now: float | None = None
        self.elapsed = self.dt  # duration of the current step [s] (cfg.dt without time stamps)
        self._clock = 0.0  # sum of the steps' durations [s]: the time axis of _out_hist
        self._out_hist: deque[tuple[float, np.ndarray]] = deque()  # (clock, command), oldest first
        self.u_prev = np.zeros(N)
        self.status = ControllerStatus()
        self._targets: list[Target] = []
        self._seg: int = 0
        self._spline: TrapezoidSegment | None = None
        self._theta_spline: TrapezoidSegment | None = None
        self._seg_time = 0.0
        self._settled = 0.0
        self._in_flight_s = float(np.max(cfg.dead_time_s + cfg.lag_s))  # [s] until a command has acted
        self._stall_best = math.inf  # [m] the closest the tip came to the segment's end since it last progressed
        self._stall_time = 0.0  # [s] since then (counted once the reference has ended)
        #: segments of the current run passed on stalled: (label, metres short)
        self.stalled: list[tuple[str, float]] = []
        self._pid_pos = _Pid(cfg.pid["position"], 3, self.dt)
        self._pid_th = _Pid(cfg.pid["theta_w"], 1, self.dt)
        self._pid_q = _Pid(cfg.pid["joint"], N, self.dt)
        self.last_result = None
        self._stop_code = codes.CANCELED
        self._stop_time = 0.0
        self._remaining = ""
        self.reference_tip: np.ndarray | None = None

    # -------------------------------------------------------------------------- commands
    def start(self, targets: list[Target]) -> None:
        """Begin a run through ``targets`` (validated by the planner); replaces any current run."""
        if not targets:
            raise ValueError("ArmController.start: empty target list")
        self._targets = list(targets)
        self._seg = 0
        self._spline = None
        self.stalled = []
        self.status = ControllerStatus(mode="moving", segment=1, segments=len(targets), label=targets[0].label)

    def stop(self, message: str = "canceled") -> None:
        """Decelerate to rest within the velocity and acceleration limits (result CANCELED once at rest)."""
        self._stop_code = codes.CANCELED
        if self.status.mode == "moving" or (self.status.mode == "idle" and np.any(self.u_prev)):
            self.status = ControllerStatus(mode="stopping", message=message)
            self._stop_time = 0.0
        elif self.status.mode != "stopping":
            self.status = ControllerStatus(mode="idle", result=codes.CANCELED, message=message)

    # -------------------------------------------------------------------------- helpers
    def predicted(self, q: np.ndarray, dq: np.ndarray | None = None) -> np.ndarray:
        """Where the joints go with the commands already sent: measured + commands still in flight.

        With measured velocities ``dq``, joint i's first-order lag is its own state: what it still moves is
        ``lag_i * dq_i`` (exact for a first-order lag), and only the commands of the last
        ``preview_s - lag_i`` seconds (not yet acting: equalising delay + dead time) are added. Without
        velocities, the lag counts as more dead time (commands of the last ``preview_s``), which is wrong
        while the joint accelerates or brakes: at the end of a fast swing the prediction said "there"
        while the swing overshot by 5 cm, and the goal then crept in for 2 s (paper load pass).
        """
        q = np.asarray(q, dtype=float)
        if dq is None:
            return q + self._in_flight_sum if self._in_flight else q.copy()
        lagged = self.cfg.lag_s * np.asarray(dq, dtype=float)
        if not self._in_flight:
            return q + lagged
        cmds = np.asarray(self._in_flight)
        durs = np.asarray(self._in_flight_dur)
        started_ago = np.cumsum(durs[::-1])[::-1]  # how long ago each command was first applied [s]
        newer_start = started_ago - durs
        acting_after = self.preview_s - self.cfg.lag_s  # per joint: a command acts this long after it is sent
        weights = np.clip(acting_after[None, :] - newer_start[:, None], 0.0, durs[:, None])
        return q + lagged + np.sum(cmds * weights, axis=0)

    def _advance_time(self, now: float | None) -> None:
        """Set :attr:`elapsed` from the time stamp and give the previous command its real duration."""
        if now is None:
            self.elapsed = self.dt
        else:
            now = float(now)
            if self._last_now is None or not math.isfinite(now):
                self.elapsed = self.dt
            elif now < self._last_now:
                # A clock that jumps back (a bad stamp, a restarted simulation) says nothing about the time
                # that passed: count one period and keep our own time running, so the next good stamp is
                # not read as a second-long late tick. (sim_plant once stamped whole seconds 0.95 s early:
                # the next step then counted 1 s, which inflated the settle time and corrupted the
                # predictor, and a goal could end "reached" with its tip still 2 cm from the target.)
                self.elapsed = self.dt
                now = self._last_now + self.dt
            else:
                # Late ticks are real (the plant kept applying the last command); a pause of seconds is
                # not: bound it to the preview so one bad stamp cannot wipe or inflate the prediction.
                self.elapsed = min(now - self._last_now, max(self.preview_s, self.dt))
            self._last_now = now if math.isfinite(now) else self._last_now
        if self._in_flight and self.elapsed != self._in_flight_dur[-1]:
            # the newest command was provisionally counted as one period: correct to its real duration
            self._in_flight_sum += self._in_flight[-1] * (self.elapsed - self._in_flight_dur[-1])
            self._in_flight_time += self.elapsed - self._in_flight_dur[-1]
            self._in_flight_dur[-1] = self.elapsed
        self._trim_in_flight()

    def _trim_in_flight(self) -> None:
        """Keep only the last ``preview_s`` seconds of commands (the oldest one partly)."""
        horizon = self.preview_s
        while self._in_flight and self._in_flight_time - self._in_flight_dur[0] >= horizon - 1e-9:
            u0, d0 = self._in_flight.popleft(), self._in_flight_dur.popleft()
            self._in_flight_sum -= u0 * d0
            self._in_flight_time -= d0
        excess = self._in_flight_time - horizon
        if self._in_flight and excess > 1e-9:
            self._in_flight_sum -= self._in_flight[0] * excess
            self._in_flight_time -= excess
            self._in_flight_dur[0] -= excess
        if not self._in_flight:
            self._in_flight_sum[:] = 0.0
            self._in_flight_time = 0.0

    def _profile(self, dq: np.ndarray, speed_scale: float, speed_caps: tuple[float, ...] = (),
                 accel_caps: tuple[float, ...] = ()) -> tuple[float, float]:
        """(duration, accel_time) of a segment moving the joints by ``dq`` (end to end): the path fraction's
        peak speed and acceleration are the largest every joint allows at ``joint_speed_scale`` of its
        limits, with the pump flow at 80 % of its limit (the rest is the PID's margin), and within
        ``speed_caps`` / ``accel_caps`` (path fraction per s, per s^2: a Cartesian segment's tip and edge
        angle limits). For a Cartesian segment ``dq`` is the IK difference of its ends, an estimate."""
        cfg, lim = self.cfg, self.kin.limits
        scale = np.minimum(1.0, cfg.joint_speed_scale * speed_scale)  # per joint; never beyond the joint limits
        dq = np.maximum(np.abs(dq), 1e-9)
        flow = float(np.sum(cfg.flow_per_rad_s * dq))  # 0: only joints on their own circuits move
        speed = min((float(np.min(scale * lim.velocity / dq)),
                     PLANNED_PUMP_SHARE * cfg.pump_flow_lpm / flow if flow > 0 else math.inf, *speed_caps))
        accel = min((float(np.min(scale * lim.acceleration / dq)), *accel_caps))
        return TrapezoidSegment.timing(speed, accel, MIN_SEGMENT_S)

    @staticmethod
    def _joint_delta(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        d = np.asarray(q1, dtype=float) - q0
        d[0] = wrap_angle(d[0])  # continuous swing: shortest way round
        return d

    def _begin_segment(self, qp: np.ndarray) -> None:
        target = self._targets[self._seg]
        if isinstance(target, JointTarget):
            delta = self._joint_delta(qp, target.q)
            dur, t_a = self._profile(delta, target.speed_scale)
            self._spline = TrapezoidSegment(qp.copy(), qp + delta, dur, t_a)
            self._theta_spline = None
        else:
            cfg, k = self.cfg, target.speed_scale
            q1 = self.kin.ik_position_with_angle(target.position, target.theta_w, check_limits=False)
            p0, p1 = self.kin.tip_position(qp), np.asarray(target.position, dtype=float)
            th0 = self.kin.theta_w(qp)
            dist = max(float(np.linalg.norm(p1 - p0)), 1e-9)
            dth = max(abs(target.theta_w - th0), 1e-9)
            dur, t_a = self._profile(
                self._joint_delta(qp, q1), k,
                speed_caps=(cfg.max_tip_speed * k / dist, cfg.max_theta_w_rate * k / dth),
                accel_caps=(cfg.max_tip_accel * k / dist, cfg.max_theta_w_accel * k / dth),
            )
            self._spline = TrapezoidSegment(p0, p1, dur, t_a)
            self._theta_spline = TrapezoidSegment(np.array([th0]), np.array([target.theta_w]), dur, t_a)
        self._seg_time = 0.0
        self._settled = 0.0
        self._stall_best, self._stall_time = math.inf, 0.0
        for pid in (self._pid_pos, self._pid_th, self._pid_q):
            pid.reset()
        self.status.segment = self._seg + 1
        self.status.label = target.label

    def _accel_dt(self) -> float:
        """Time over which the command may change by acceleration x dt: the real duration of this step.

        A late tick (sim-time timer under CPU load) has let the previous command act for longer; with the
        nominal period the arm would accelerate at a fraction of its limit whenever ticks are late
        (the paper launch's swings took 9-13 s instead of 6 s). Capped at 3 periods so a long pause
        does not allow a jump.
        """
        return min(max(self.elapsed, self.dt), 3.0 * self.dt)

    # -------------------------------------------------------------------------- safety rows
    def _safety_tasks(self, qp: np.ndarray, tip: np.ndarray, jt: np.ndarray, pin_p: np.ndarray, jp: np.ndarray):
        cfg, lim = self.cfg, self.kin.limits
        vmax = lim.velocity
        if cfg.use_acceleration_limits:
            a = lim.acceleration * self._accel_dt()
            hi = np.minimum(vmax, self.u_prev + a)
            lo = np.maximum(-vmax, self.u_prev - a)
        else:
            hi, lo = vmax, -vmax
        vel = (self._eye2, np.concatenate([hi, -lo]))
        m = cfg.position_limit_margin
        k = cfg.position_limit_gain
        pos = (self._eye2, np.concatenate([k * (self._upper - m - qp), k * (qp - self._lower - m)]))
        rows, b = [], []
        so = self.kin.swing_origin
        kc = cfg.collision_gain
        for p, j in ((tip, jt), (pin_p, jp)):
            rows.append(-j[2])
            b.append(kc * (p[2] - cfg.ground_min_z))
            rel = p[:2] - so[:2]
            rho = float(np.linalg.norm(rel))
            rows.append(-(rel / max(rho, 1e-6)) @ j[:2])
            b.append(kc * (rho - cfg.body_min_radius))
        col = (np.array(rows), np.array(b))
        return [(self._pump_a, self._pump_b), vel, pos, col]

    def _enforce_hard_limits(self, u: np.ndarray) -> np.ndarray:
        """Final guard against solver tolerance: clip to the velocity/acceleration box, scale to the pump."""
        vmax = self.kin.limits.velocity
        if self.cfg.use_acceleration_limits:
            a = self.kin.limits.acceleration * self._accel_dt()
            u = np.clip(u, np.maximum(-vmax, self.u_prev - a), np.minimum(vmax, self.u_prev + a))
        else:
            u = np.clip(u, -vmax, vmax)
        flow = float(np.sum(self.cfg.flow_per_rad_s * np.abs(u)))
        if flow > self.cfg.pump_flow_lpm:
            u = u * (self.cfg.pump_flow_lpm / flow)
        return u

    # -------------------------------------------------------------------------- the step
    def step(self, q: np.ndarray, dq: np.ndarray | None = None, now: float | None = None) -> np.ndarray:
        """One control period: measured joints ``q`` (and velocities ``dq``) -> joint-velocity command.

        ``now`` [s] is the time of this step on the plant's clock (the node passes its ROS clock,
        simulated time in the launches): with it, the Smith predictor, the PID integrators and the
        reference advance by the time that really passed, so late or skipped ticks do not make the
        prediction wrong (without it every step counts as one period ``1 / rate_hz``).
        The returned command is what to send now (delays equalised per joint). :attr:`status`
        reports the phase and, when a run ends, ``result`` (an ErrorCodes value) and ``message``.
        """
        self._advance_time(now)
        q = np.asarray(q, dtype=float)
        dq_measured = dq
        dq = np.zeros(N) if dq is None else np.asarray(dq, dtype=float)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            self.stop("non-finite joint state")
            q, dq = np.nan_to_num(q), np.nan_to_num(dq)
        qp = self.predicted(q, None if dq_measured is None else dq)
        tip, jt, pin_p, jp = self.kin.jacobians(qp)
        tasks = self._safety_tasks(qp, tip, jt, pin_p, jp)
        st = self.status
        if st.mode == "moving":
            if self._spline is None:
                self._begin_segment(qp)
            u = self._track(q, qp, dq, tip, jt, tasks)
        else:
            res = self.hqp_joint.solve([*tasks, (np.eye(N), np.zeros(N)), (np.eye(N), np.zeros(N))])
            u = res.x
            self.last_result = res
            if st.mode == "stopping":
                self._stop_time += self.elapsed
                in_flight = max((float(np.max(np.abs(c))) for _, c in self._out_hist), default=0.0)
                if self._in_flight:
                    in_flight = max(in_flight, float(np.max(np.abs(np.asarray(self._in_flight)))))
                if np.max(np.abs(u)) < 1e-4 and np.max(np.abs(dq)) < self.cfg.rest_speed and in_flight < 1e-4:
                    self.status = ControllerStatus(
                        mode="idle", result=self._stop_code, message=st.message or "canceled"
                    )
                elif self._stop_time >= self.cfg.stop_timeout_s:
                    # Never hang in "stopping": the command is zero (or holding a limit) but the measured
                    # joints still move (plant not following, noisy joint_states). End with what we know.
                    code = codes.FAILURE if self._stop_code == codes.CANCELED else self._stop_code
                    self.status = ControllerStatus(
                        mode="idle", result=code,
                        message=f"{st.message or 'canceled'}; not at rest {self.cfg.stop_timeout_s:g} s after stopping "
                        f"(joint speeds {np.round(dq, 3).tolist()} rad/s, command {np.round(u, 4).tolist()} rad/s)",
                    )
            else:
                u = np.zeros(N) if np.max(np.abs(u)) < 1e-9 else u
        u = self._enforce_hard_limits(u)
        self.u_prev = u
        if self._horizon_steps:
            self._in_flight.append(u)
            self._in_flight_dur.append(self.dt)  # corrected to the real duration at the next step
            self._in_flight_sum += u * self.dt
            self._in_flight_time += self.dt
            self._trim_in_flight()
        return self._delayed(u)

    def _delayed(self, u: np.ndarray) -> np.ndarray:
        """Per joint, the command of ``_extra_s`` ago (the oldest kept until then): delays equalised."""
        self._clock += self.elapsed
        hist = self._out_hist
        hist.append((self._clock, u))
        oldest_needed = self._clock - float(np.max(self._extra_s)) + 0.5 * self.dt
        while len(hist) > 1 and hist[1][0] <= oldest_needed:
            hist.popleft()
        out = np.empty(N)
        for i, extra in enumerate(self._extra_s):
            cutoff = self._clock - extra + 0.5 * self.dt
            out[i] = next((c[i] for t, c in reversed(hist) if t <= cutoff), hist[0][1][i])
        return out

    def _track(self, q, qp, dq, tip, jt, tasks) -> np.ndarray:  # internal
        cfg = self.cfg
        target = self._targets[self._seg]
        self._seg_time += self.elapsed
        # The reference starts at the predicted state (p0 = qp at segment start), so it is a trajectory of
        # the predicted state and is read at the segment's own time: the plant follows it preview_s later.
        # (Reading it preview_s ahead instead skipped the first 1.3 s of every swing: the PID
        # chased a reference that had left without it, a trapezoidal swing overshot by 0.5 rad, and a
        # 1.1 s penetrate took 2.2 s to converge.)
        t_ref = self._seg_time
        spline = self._spline
        assert spline is not None
        # Integrate only once the reference holds its end point and the error is inside the
        # PID's i_zone: while the arm moves, the error is mostly the tracking lag of the dead time
        # (1.3 s on the swing), and integrating it wound the integrator up to its clamp in every move; at the goal
        # that wound-up term (ki x i_limit) then balanced
        # kp x error, so the arm sat millimetres to centimetres off and only crept in as the integral
        # bled off at the rate of that small error (tens of seconds: the paper demo's swing stuck at
        # 0.008 rad for 26 s). The plant integrates velocity, so P alone has no steady-state error;
        # the integral is only there for a constant velocity bias (leaking valves) at the goal.
        hold = t_ref >= spline.duration
        last = self._seg == len(self._targets) - 1
        # Via segments (every one but the last, and targets marked ``via``: the planner sends approach,
        # carry, ... one goal each) only need to pass near their target, like Nav2's waypoint vs goal
        # tolerance, and do not wait for rest; the final one gets the goal precision.
        via = target.via or not last
        tol_m = cfg.via_tolerance_m if via else cfg.goal_tolerance_m
        tol_rad = cfg.via_tolerance_rad if via else cfg.goal_tolerance_rad
        if isinstance(target, JointTarget):
            q_ref, v_ref = spline.sample(t_ref)
            err = q_ref - qp
            err[0] = wrap_angle(err[0])
            b = v_ref + self._pid_q(err, self.elapsed, hold)
            res = self.hqp_joint.solve([*tasks, (np.eye(N), b), (np.eye(N), np.zeros(N))])
            self.reference_tip = None
            tip_goal = self.kin.tip_position(spline.p1)
            self.status.distance_remaining = float(np.linalg.norm(tip_goal - self.kin.tip_position(q)))
            # Joints within tolerance AND the tip (a small swing error is centimetres at full reach), both
            # as measured and as predicted once the commands still in flight (swing: ~1.3 s of dead time
            # and lag) have acted: declaring success on the measurement alone let the arm drift off after.
            joint_err = [self._joint_delta(x, spline.p1) for x in (q, qp)]
            tip_err = [self.status.distance_remaining, float(np.linalg.norm(tip_goal - self.kin.tip_position(qp)))]
            # A via point is passed on the prediction alone (the next segment's spline starts from it), unless it
            # asks for the measurement too (target.measured).
            checked = slice(1, 2) if via and not target.measured else slice(0, 2)
            reached = (max(float(np.max(np.abs(e))) for e in joint_err[checked]) < tol_rad
                       and max(tip_err[checked]) < tol_m)
            self._remaining = (
                f"tip {self.status.distance_remaining:.3f} m off, joints off by "
                + ", ".join(f"{n} {e:+.4f} rad" for n, e in zip(JOINTS, joint_err[0], strict=True))
            )
        else:
            assert self._theta_spline is not None
            p_ref, v_ref = spline.sample(t_ref)
            th_ref, w_ref = self._theta_spline.sample(t_ref)
            th = self.kin.theta_w(qp)
            b_th = w_ref + self._pid_th(th_ref - th, self.elapsed, hold)
            b_p = v_ref + self._pid_pos(p_ref - tip, self.elapsed, hold)
            res = self.hqp_cartesian.solve(
                [*tasks, (self.kin.theta_w_jacobian()[None, :], b_th), (jt, b_p), (np.eye(N), np.zeros(N))]
            )
            self.reference_tip = spline.sample(self._seg_time - self.preview_s)[0]  # where the plant should be now
            dists = [float(np.linalg.norm(spline.p1 - self.kin.tip_position(x))) for x in (q, qp)]
            th_errs = [abs(float(self._theta_spline.p1[0]) - self.kin.theta_w(x)) for x in (q, qp)]
            # measured and predicted (commands in flight) both within tolerance, as for joint targets
            checked = slice(1, 2) if via and not target.measured else slice(0, 2)
            reached = max(dists[checked]) < tol_m and max(th_errs[checked]) < tol_rad
            dist = dists[0]
            self.status.distance_remaining = dist
            self._remaining = f"tip {dist:.3f} m off, theta_w {th_errs[0]:.4f} rad off"
        self.last_result = res
        u = res.x
        if self._seg_time >= spline.duration:
            if reached and (via or np.max(np.abs(dq)) < cfg.rest_speed):
                self._settled += self.elapsed
            else:
                self._settled = 0.0
            # A via segment that another follows and that the arm cannot finish (a drag deeper than the cylinders
            # can pull through: they stand at relief) is passed on once the tip has stopped closing in, as an
            # operator lifts out of a cut that stalls; the next segment starts from where the arm is.
            # Counted only once the commands in flight have acted (the swing's dead time and lag are ~1.9 s: a short
            # swing's profile ends before its measured tip has begun to move).
            # A segment reached on the measurement creeps in slowly (in the soil, under load): it stalls only once the
            # joints stand, not while they still move.
            left = self.status.distance_remaining
            if (left < self._stall_best - cfg.via_stall_progress_m
                    or self._seg_time < spline.duration + self._in_flight_s
                    or (target.measured and float(np.max(np.abs(dq))) >= cfg.rest_speed)):
                self._stall_best, self._stall_time = left, 0.0
            else:
                self._stall_time += self.elapsed
            if (not reached and via and not last and cfg.via_stall_s > 0
                    and self._stall_time >= cfg.via_stall_s):
                self.stalled.append((target.label or f"segment {self._seg + 1}", left))
                reached = True
            if reached and (via or self._settled >= cfg.settle_s):
                if last:
                    stalls = "; ".join(f"{label} stalled {m:.2f} m short, passed on" for label, m in self.stalled)
                    self.status = ControllerStatus(
                        mode="idle", segment=self._seg + 1, segments=len(self._targets), label=target.label,
                        distance_remaining=self.status.distance_remaining, result=codes.SUCCESS,
                        message=f"reached ({stalls})" if stalls else "reached",
                    )
                    self._spline = None
                    return u
                self._seg += 1
                self._spline = None
            elif self._seg_time > spline.duration + cfg.segment_timeout_margin_s:
                self.status = ControllerStatus(
                    mode="stopping", result=None,
                    message=f"segment {self._seg + 1} ({target.label or 'move'}) not reached within "
                    f"{spline.duration + cfg.segment_timeout_margin_s:.1f} s: {self._remaining} "
                    f"(tolerance {tol_m:g} m / {tol_rad:g} rad)",
                )
                self._stop_code = codes.TIMEOUT
                self._stop_time = 0.0
        return u
