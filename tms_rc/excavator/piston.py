"""Piston-level control of an excavator's front through COM3 pilot-pressure commands (HEAP, section 2.4).

Below the arm controller, each cylinder is driven on its own at the control rate (100 Hz in HEAP):

* velocity control (:class:`PistonVelocityController`): a feed-forward look-up table identified on the machine
  (per function and direction, pairs pilot pressure -> steady piston speed, :class:`PistonLut`; the table's inverse by
  linear interpolation gives the pilot for a commanded speed), plus PI feedback on the piston speed error (with
  anti-windup), plus dead-zone compensation;
* force control (:class:`PistonForceController`): PI on the cylinder force error (the force from the chamber pressures
  times the areas, :func:`cylinder_force`), plus dead-zone compensation.

Both work in a signed "pilot above the dead zone" ``u`` [MPa] along the piston (+ extends the cylinder) and hand out
the pilot pressures of the function's two COM3 lines (:class:`PilotPair`, ``Pilot_Pressure_Cmd_1``, 0 .. the DBC's
maximum ``p_max``, :func:`pilot_range`). Dead-zone compensation: a ``u`` beyond ``zero_band_mpa`` jumps to the crack
pilot pressure of the direction it commands (the first pilot of that direction's identified table: the spool starts
passing oil there) and adds ``|u|`` to it; a smaller ``u`` is no command (both lines at 0: the spool centres and the
oil holds the piston).

The COM3 pilot pair of a front function is named by *joint* direction (``boom_down``/``boom_up``, ...): a cylinder
extends when its joint turns the way of the sign of dl/dq, which the machine description's geometry gives
(:func:`extend_sign`). Nothing here reads the plant's model: the tables and cracks come from an identification on
the machine (:mod:`tms_rc.piston_lut`), the gains and choices from ``config/tms_rc/piston_control.yaml``.

Pure Python (no ROS): a node or the arm controller would call ``step`` once per control period.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import cantools

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader, load_schema, setting
from tms_model.cylinders import Cylinder, cylinder_length, moment_arm
from tms_model.machines import Machine

__all__ = [
    "CYLINDER_FUNCTIONS", "SETTINGS_FILE", "PiGains", "PistonControlSettings", "LutIdentificationSettings",
    "DirectionLut", "PistonLut", "PilotPair", "PiController", "PistonVelocityController", "PistonForceController",
    "dead_zone", "cylinder_force", "extend_sign", "cylinder_of", "piston_length", "piston_stroke",
    "load_piston_settings", "settings_path", "pilot_range", "piston_lut_path", "load_piston_luts",
]

#: the front functions driven by a cylinder (the swing motor is not done here)
CYLINDER_FUNCTIONS = ("boom_joint", "arm_joint", "bucket_joint")
SETTINGS_FILE = "piston_control.yaml"
#: the COM3 frame of the front's pilot pressure commands
PILOT_FRAME = "Pilot_Pressure_Cmd_1"


@functools.cache
def pilot_range(dbc: str) -> tuple[float, float]:
    """(maximum, resolution) [MPa] of the front's pilot commands (``Pilot_Pressure_Cmd_1``) in the machine's DBC
    ``dbc`` (``Machine.dbc``: 5 MPa in 0.02 MPa steps on the ZX200). Read through cantools from com3_can's package
    directory: com3_can is on tms_rc's architecture level and not imported (as ``tms_rc.identify`` reads it)."""
    db = cantools.database.load_file(str(resources.files("com3_can").joinpath("dbc", dbc)), strict=True)
    sigs = db.get_message_by_name(PILOT_FRAME).signals
    return float(min(sg.maximum for sg in sigs)), float(max(sg.scale for sg in sigs))


# ---------------------------------------------------------------------------------------------- settings
@dataclass(frozen=True, kw_only=True)
class PiGains:
    """One PI loop: ``u = kp e + ki integral(e)``; the integral's share ``ki * I`` held within ``i_limit_mpa``."""

    kp: float = setting(lo=0.0, doc="[MPa per unit of error]")
    ki: float = setting(lo=0.0, doc="[MPa per unit of error and second]")
    i_limit_mpa: float = setting(lo=0.0, doc="[MPa] largest pilot the integral may add")
    i_zone: float | None = setting(None, lo=0.0, doc="integrate only while |error| is within this (None: always): "
                                   "the valve's dead time after a step of the reference is not wound up")


@dataclass(frozen=True, kw_only=True)
class LutIdentificationSettings:
    """How the look-up table is identified (:func:`tms_rc.piston_lut.identify_lut`): choices, no plant figures."""

    levels: int = setting(13, lo=2, hi=64, doc="pairs per function and direction (HEAP: 13)")
    hold_s: float = setting(lo=0.2, doc="[s] longest a pilot step is held")
    window_s: float = setting(lo=0.02, doc="[s] the steady speed is the mean over the step's last window")
    moving_mps: float = setting(lo=0.0, doc="[m/s] a piston faster than this moves (the crack search)")
    crack_tolerance_mpa: float = setting(lo=0.001, doc="[MPa] the crack bisection stops at this bracket")
    full_fraction: float = setting(lo=0.5, hi=1.0, doc="a pilot whose speed reaches this fraction of the speed at the "
                                   "largest pilot counts as full")
    full_tolerance_mpa: float = setting(lo=0.001, doc="[MPa] the full-pilot bisection stops at this bracket")
    stroke_margin_m: float = setting(lo=0.0, doc="[m] a step ends this far (plus its speed x lookahead) from an end")
    lookahead_s: float = setting(lo=0.0, doc="[s] the piston's travel over this is kept from the margin")
    start_fraction: float = setting(lo=0.0, hi=0.5, doc="a step with less than min_room_fraction of the stroke ahead "
                                    "starts this fraction of the stroke from the end it moves away from")
    min_room_fraction: float = setting(lo=0.0, hi=1.0, doc="a step with this fraction of the stroke ahead starts "
                                       "where the piston stands")
    reposition_pilot_mpa: float = setting(lo=0.0, doc="[MPa] pilot of the moves between steps")
    reposition_tolerance_m: float = setting(lo=0.0, doc="[m] a move between steps ends this close to its goal")
    rest_mps: float = setting(lo=0.0, doc="[m/s] the piston is at rest below this")
    rest_s: float = setting(lo=0.0, doc="[s] ... for this long")
    rest_timeout_s: float = setting(lo=0.0, doc="[s] longest wait for rest")


@dataclass(frozen=True, kw_only=True)
class PistonControlSettings:
    """The choices of ``config/tms_rc/piston_control.yaml``."""

    rate_hz: float = setting(lo=1.0, doc="[Hz] control rate (HEAP: 100)")
    zero_band_mpa: float = setting(lo=0.0, doc="[MPa] a controller output this small commands nothing")
    velocity: dict[str, PiGains] = setting(doc="PI of the piston speed error [m/s] per function")
    force: dict[str, PiGains] = setting(doc="PI of the cylinder force error [kN] per function, for a stiff stall "
                                        "(the bucket held in the soil: the oil column alone is the spring)")
    force_contact: dict[str, PiGains] = setting(doc="PI of the cylinder force error [kN] per function with the bucket "
                                                "pressed on the ground (the soil and the front in series with the "
                                                "oil: a softer load, the same PI ~3x too slow)")
    identification: LutIdentificationSettings = setting(doc="the look-up table's identification")

    def __post_init__(self) -> None:
        for what in ("velocity", "force", "force_contact"):
            missing = [f for f in CYLINDER_FUNCTIONS if f not in getattr(self, what)]
            if missing:
                raise ValueError(f"{what}: missing {', '.join(missing)}")


def settings_path() -> Path:
    """``config/tms_rc/piston_control.yaml``."""
    return Path(config_path("tms_rc", SETTINGS_FILE))


def load_piston_settings(path: str | Path | None = None) -> PistonControlSettings:
    """The piston-control choices of ``path`` (default :func:`settings_path`); errors ``file:line: key: problem``."""
    return load_schema(PistonControlSettings, path if path is not None else settings_path())


# ---------------------------------------------------------------------------------------------- look-up table
@dataclass(frozen=True)
class DirectionLut:
    """One direction of one function: ``pilots`` [MPa] rising, the steady piston ``speeds`` [m/s, >= 0] there.

    ``pilots[0]`` is the crack (the spool starts passing oil just above it). The speeds are made non-decreasing
    (a measured dip would make the inverse ambiguous)."""

    pilots: tuple[float, ...]
    speeds: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.pilots) < 2 or len(self.pilots) != len(self.speeds):
            raise ValueError(f"DirectionLut: need >= 2 pairs of equal length, got {len(self.pilots)} pilots and "
                             f"{len(self.speeds)} speeds")
        if any(b <= a for a, b in zip(self.pilots, self.pilots[1:], strict=False)):
            raise ValueError(f"DirectionLut: pilots must rise strictly: {self.pilots}")
        mono, top = [], 0.0
        for s in self.speeds:
            top = max(top, abs(float(s)))
            mono.append(top)
        object.__setattr__(self, "speeds", tuple(mono))
        object.__setattr__(self, "pilots", tuple(float(p) for p in self.pilots))

    @property
    def crack(self) -> float:
        return self.pilots[0]

    @property
    def max_speed(self) -> float:
        return self.speeds[-1]

    def speed(self, pilot: float) -> float:
        """Steady speed [m/s] at ``pilot`` [MPa]: linear between the pairs, 0 below the crack, the last beyond."""
        p, s = self.pilots, self.speeds
        if pilot <= p[0]:
            return 0.0 if pilot < p[0] else s[0]
        if pilot >= p[-1]:
            return s[-1]
        k = bisect.bisect_right(p, pilot) - 1
        return s[k] + (s[k + 1] - s[k]) * (pilot - p[k]) / (p[k + 1] - p[k])

    def pilot(self, speed: float) -> float:
        """The pilot [MPa] for a steady ``speed`` [m/s, >= 0]: the table's inverse by linear interpolation (the lowest
        pilot of a flat stretch); the crack for 0, the last pilot beyond the fastest pair."""
        p, s = self.pilots, self.speeds
        if speed <= s[0]:
            return p[0]
        if speed >= s[-1]:
            return p[-1]
        k = bisect.bisect_left(s, speed)  # s[k-1] < speed <= s[k]
        return p[k - 1] + (p[k] - p[k - 1]) * (speed - s[k - 1]) / (s[k] - s[k - 1])


@dataclass(frozen=True)
class PistonLut:
    """The identified table of one function: ``extend`` and ``retract`` (speeds as magnitudes)."""

    extend: DirectionLut
    retract: DirectionLut

    def side(self, direction: float) -> DirectionLut:
        return self.extend if direction > 0 else self.retract

    def crack(self, direction: float) -> float:
        return self.side(direction).crack

    def feedforward(self, velocity: float) -> float:
        """The signed pilot above the crack [MPa] for a piston ``velocity`` [m/s] (+ extending); 0 for 0."""
        if velocity == 0.0:
            return 0.0
        d = self.side(velocity)
        return math.copysign(d.pilot(abs(velocity)) - d.crack, velocity)

    def velocity(self, piston_pilot: float) -> float:
        """The table's steady piston velocity [m/s] for a signed pilot [MPa] (+ extending)."""
        if piston_pilot == 0.0:
            return 0.0
        return math.copysign(self.side(piston_pilot).speed(abs(piston_pilot)), piston_pilot)

    def as_dict(self) -> dict[str, dict[str, list[float]]]:
        return {name: {"pilot_mpa": list(d.pilots), "speed_mps": list(d.speeds)}
                for name, d in (("extend", self.extend), ("retract", self.retract))}

    @classmethod
    def from_dict(cls, data: Mapping[str, Mapping[str, Sequence[float]]]) -> PistonLut:
        return cls(*(DirectionLut(tuple(data[n]["pilot_mpa"]), tuple(data[n]["speed_mps"]))
                     for n in ("extend", "retract")))


def piston_lut_path(name: str) -> Path:
    """``config/tms_rc/identified/<name>_piston_lut.yaml``: the tables ``tms_rc_identify_pistons`` identified on the
    machine called ``name`` (beside the dead times and flow gains of ``tms_rc_identify``'s ``<name>.yaml``)."""
    return Path(config_path("tms_rc", "identified", f"{name}_piston_lut.yaml"))


def load_piston_luts(name: str | None = None, path: str | Path | None = None) -> dict[str, PistonLut]:
    """The identified table of each function in ``path`` (default :func:`piston_lut_path` of ``name``): its
    ``functions: {<joint>: {extend: {pilot_mpa: [...], speed_mps: [...]}, retract: {...}}}``. A missing file is a
    ConfigError naming it and the command that writes it; a bad one ``file:line: key: problem``."""
    if path is None:
        if name is None:
            raise ValueError("load_piston_luts: give the machine's name or the file")
        path = piston_lut_path(name)
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no identified piston look-up table; tms_rc_identify_pistons --machine "
                          f"{name or '<machine>'} writes it")
    data, where = load_yaml(path)
    functions = Reader(data, where).sub("functions")
    functions.only(set(CYLINDER_FUNCTIONS))
    out = {}
    for fn in functions.keys():
        sides = []
        per_fn = functions.sub(fn)
        per_fn.only({"extend", "retract"})
        for direction in ("extend", "retract"):
            pairs = per_fn.sub(direction)
            pairs.only({"pilot_mpa", "speed_mps"})
            pilots = pairs.raw("pilot_mpa")
            n = len(pilots) if isinstance(pilots, list) else -1
            try:
                sides.append(DirectionLut(pairs.vector("pilot_mpa", n), pairs.vector("speed_mps", n)))
            except ValueError as exc:
                raise pairs.error(pairs.path, str(exc)) from None
        out[fn] = PistonLut(*sides)
    return out


# ---------------------------------------------------------------------------------------------- output stage
@dataclass(frozen=True)
class PilotPair:
    """The pilot pressures [MPa] of one function's two COM3 lines: ``plus`` turns the joint +, ``minus`` - (for the
    boom ``boom_down`` / ``boom_up``, the arm ``arm_crowd`` / ``arm_dump``, the bucket ``bucket_crowd`` /
    ``bucket_dump``: :data:`com3_can.signal_map.EXCAVATOR_FRONT`)."""

    plus: float
    minus: float

    @property
    def difference(self) -> float:
        """``plus - minus``: what the machine's valve block sees of the pair."""
        return self.plus - self.minus

    @classmethod
    def from_piston(cls, piston_pilot: float, extend: int) -> PilotPair:
        """The pair for a signed pilot along the piston (+ extends) on a function whose cylinder extends when its
        joint turns ``extend`` (+1 / -1, :func:`extend_sign`)."""
        p = abs(piston_pilot)
        if p == 0.0:
            return cls(0.0, 0.0)
        return cls(p, 0.0) if piston_pilot * extend > 0 else cls(0.0, p)


def dead_zone(u: float, crack_extend: float, crack_retract: float, zero_band: float, p_max: float) -> float:
    """Dead-zone compensation: the signed pilot along the piston for a signed ``u`` above the dead zone [MPa].

    ``|u| <= zero_band``: 0 (no command); else the crack of the direction ``u`` commands plus ``|u|``, at most
    ``p_max``, with ``u``'s sign."""
    if abs(u) <= zero_band:
        return 0.0
    crack = crack_extend if u > 0 else crack_retract
    return math.copysign(min(p_max, crack + abs(u)), u)


class PiController:
    """PI with anti-windup: the integral's share is held within ``i_limit_mpa``, and it does not integrate while the
    output stage is saturated (``saturated_sign`` of the last output) with the error pushing further into it, nor
    (``i_zone``) while the error is larger than the zone."""

    def __init__(self, gains: PiGains, dt: float) -> None:
        self.gains, self.dt = gains, dt
        self.integral = 0.0  # [error unit x s]
        self.saturated_sign = 0  # +1 / -1: the last output was held at the top / bottom limit

    def reset(self) -> None:
        self.integral = 0.0
        self.saturated_sign = 0

    def step(self, error: float) -> float:
        g = self.gains
        pushing_on = self.saturated_sign and error * self.saturated_sign > 0
        if not pushing_on and (g.i_zone is None or abs(error) <= g.i_zone):
            self.integral += error * self.dt
        if g.ki > 0.0:
            lim = g.i_limit_mpa / g.ki
            self.integral = max(-lim, min(lim, self.integral))
        else:
            self.integral = 0.0
        return g.kp * error + g.ki * self.integral


class _PistonOutput:
    """Shared output stage: dead-zone compensation, bounds, anti-windup flag, the pilot pair."""

    def __init__(self, lut: PistonLut, extend: int, zero_band: float, p_max: float) -> None:
        if extend not in (1, -1):
            raise ValueError(f"extend must be +1 or -1, got {extend}")
        self.lut, self.extend, self.zero_band, self.p_max = lut, extend, zero_band, p_max
        self.piston_pilot = 0.0  # the last signed pilot along the piston [MPa]
        self.u = 0.0  # the last signed pilot above the dead zone [MPa]

    def _out(self, u: float, pi: PiController | None) -> PilotPair:
        p = dead_zone(u, self.lut.crack(1), self.lut.crack(-1), self.zero_band, self.p_max)
        if pi is not None:
            pi.saturated_sign = int(math.copysign(1, u)) if abs(p) >= self.p_max else 0
        self.u, self.piston_pilot = u, p
        return PilotPair.from_piston(p, self.extend)


class PistonVelocityController(_PistonOutput):
    """Piston speed control of one function: LUT feed-forward + PI (optional) + dead-zone compensation.

    ``step(v_ref, v)`` with the commanded and measured piston velocities [m/s] (+ extending) returns the
    :class:`PilotPair`. ``v_ref == 0`` commands nothing and clears the integral (the spool centres, the oil holds)."""

    def __init__(self, lut: PistonLut, gains: PiGains, dt: float, *, extend: int, zero_band: float,
                 p_max: float, feedback: bool = True) -> None:
        super().__init__(lut, extend, zero_band, p_max)
        self.pi = PiController(gains, dt) if feedback else None

    def reset(self) -> None:
        if self.pi is not None:
            self.pi.reset()

    def step(self, v_ref: float, v: float) -> PilotPair:
        if v_ref == 0.0:
            self.reset()
            return self._out(0.0, None)
        u = self.lut.feedforward(v_ref)
        if self.pi is not None:
            u += self.pi.step(v_ref - v)
        return self._out(u, self.pi)


class PistonForceController(_PistonOutput):
    """Cylinder force control of one function: PI on the force error [kN] + dead-zone compensation.

    ``step(f_ref, f)`` with the commanded and measured cylinder forces [N] (+ pushing: cap side,
    :func:`cylinder_force`) returns the :class:`PilotPair`; more force = oil into the cap side = extend. ``lut``
    gives the cracks of both directions (the identified table)."""

    def __init__(self, lut: PistonLut, gains: PiGains, dt: float, *, extend: int, zero_band: float,
                 p_max: float) -> None:
        super().__init__(lut, extend, zero_band, p_max)
        self.pi = PiController(gains, dt)

    def reset(self) -> None:
        self.pi.reset()

    def step(self, f_ref: float, f: float) -> PilotPair:
        return self._out(self.pi.step((f_ref - f) / 1e3), self.pi)


# ---------------------------------------------------------------------------------------------- geometry
def cylinder_of(machine: Machine, joint: str) -> Cylinder:
    assert machine.cylinders is not None, f"{machine.model_name}: no cylinders (not an excavator)"
    for c in machine.cylinders.all:
        if c.joint == joint:
            return c
    raise KeyError(f"{machine.model_name}: no cylinder drives {joint}")


def _plane(machine: Machine, joint: str) -> tuple[tuple[float, float], float]:
    j = machine.joint(joint)
    return (j.origin_xyz[0], j.origin_xyz[2]), j.origin_rpy[1]


def piston_length(machine: Machine, joint: str, q: float) -> float:
    """Pin-to-pin length [m] of the cylinder of ``joint`` at angle ``q`` (the description's geometry)."""
    return cylinder_length(cylinder_of(machine, joint), *_plane(machine, joint), q)


def piston_stroke(machine: Machine, joint: str) -> tuple[float, float]:
    """(shortest, longest) length [m] of the cylinder of ``joint`` over the joint's range."""
    j = machine.joint(joint)
    assert j.lower is not None and j.upper is not None
    a, b = piston_length(machine, joint, j.lower), piston_length(machine, joint, j.upper)
    return min(a, b), max(a, b)


def extend_sign(machine: Machine, joint: str) -> int:
    """+1 when the cylinder of ``joint`` extends as the joint turns +, else -1 (dl/dq at mid-range)."""
    j = machine.joint(joint)
    assert j.lower is not None and j.upper is not None
    return 1 if moment_arm(cylinder_of(machine, joint), *_plane(machine, joint), 0.5 * (j.lower + j.upper)) > 0 else -1


def cylinder_force(cylinder: Cylinder, p_cap_mpa: float, p_rod_mpa: float) -> float:
    """Cylinder force [N] (+ pushing) from the chamber pressures [MPa] (COM3 ``Pressure_1``) and the bore/rod areas
    of the description."""
    return (p_cap_mpa * cylinder.cap_area - p_rod_mpa * cylinder.rod_area) * 1e6
