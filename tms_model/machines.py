"""Per machine kind an immutable description, read once from ``config/machines/<kind>.yaml``.

:func:`load_machine` parses and validates the file (every problem is ``file:line: key.path: problem``)
and caches the result per file, so the converter, the plant, the planners, the controllers, sensing
and the UI all see one description of a machine. Three types of machine exist today:

* ``excavator`` (ZX200, ZX120): a front of four revolute joints swing/boom/arm/bucket, a bucket, tracks;
* ``crawler_dump`` (IC120, MST-110CR, MST-2200VD): tracks and a vessel on a rear hinge; optionally (``swing:``)
  an upper body that carries the vessel and rotates on a slew ring (the MSTs' ``rotate_joint``);
* ``dozer`` (D37PXi): tracks and a blade on a lift arm (``lift_joint``, as OPERA's d37pxi_description names it).

Every kind names the DBC its COM3 bus speaks (``can: {dbc: <file in com3_can/dbc>}``, required).

The ``type:`` key of the YAML names the type, and :data:`PARSERS` the parser of each type (the one place the
types are listed: a new type is a constant, a parser and a row there); sections another package owns alone (e.g.
``sim``) are
left to it, but inside the sections read here an unknown key is an error (a typo must not silently fall
back to a default).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader, setting
from tms_model.cylinders import Cylinders

__all__ = [
    "Blade",
    "Bucket",
    "Footprint",
    "Joint",
    "JointDrive",
    "LinkBox",
    "Machine",
    "PilotCutoff",
    "TrackDrive",
    "Tracks",
    "Swing",
    "Vessel",
    "EXCAVATOR",
    "CRAWLER_DUMP",
    "DOZER",
    "PARSERS",
    "TYPES",
    "ROTATE_JOINT",
    "VESSEL_JOINT",
    "LIFT_JOINT",
    "load_machine",
    "machine_path",
]

# the machine types; PARSERS (below) is the one table of them, TYPES its keys in order
EXCAVATOR = "excavator"
CRAWLER_DUMP = "crawler_dump"
DOZER = "dozer"

#: joint names of our interfaces (joint_states): a carrier's vessel and rotating upper body (com3_ros's MST name),
#: a dozer's blade lift arm (OPERA d37pxi_description's name)
VESSEL_JOINT = "vessel_joint"
ROTATE_JOINT = "rotate_joint"
LIFT_JOINT = "lift_joint"


@dataclass(frozen=True)
class Joint:
    """A revolute joint of the URDF chain: origin in its parent, axis, limits.

    ``lower``/``upper`` are None for a continuous joint (the swing); ``velocity`` [rad/s] and
    ``acceleration`` [rad/s^2] are the motion limits the planner and the controller respect.
    """

    name: str
    parent: str
    child: str
    origin_xyz: tuple[float, float, float]
    origin_rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float | None
    upper: float | None
    velocity: float
    acceleration: float


@dataclass(frozen=True)
class JointDrive:
    """Hydraulic actuator of one joint: dead time [s], first-order lag [s], pump flow drawn at its limit [L/min]."""

    dead_time: float
    time_constant: float
    flow_at_limit: float  # 0 = on its own circuit, not sharing the main pumps


@dataclass(frozen=True)
class Footprint:
    """Rectangle centred on base_link [m]: ``length`` along x, ``width`` along y."""

    length: float
    width: float


@dataclass(frozen=True)
class Tracks:
    """Skid-steer undercarriage limits: gauge [m], speed [m/s], yaw rate [rad/s], optional accelerations."""

    gauge: float
    max_speed: float
    max_yaw_rate: float
    max_accel: float | None = None
    max_yaw_accel: float | None = None


@dataclass(frozen=True)
class TrackDrive:
    """Travel hydraulics: dead time [s], lag [s], slip ratio and yaw slip (fraction of yaw rate lost)."""

    dead_time: float
    time_constant: float
    slip: float
    yaw_slip: float


@dataclass(frozen=True)
class Bucket:
    """The excavator's bucket: tip in bucket_link [m], heaped capacity [m^3] and soil handling of the plant."""

    tip_xyz: tuple[float, float, float]
    capacity: float
    width: float  # [m] cutting edge
    release_tip_angle: float  # [rad] spills while its pin->tip line is less than this below horizontal
    spill_time: float  # [s] to empty a full bucket when fully open
    cut_min_speed: float  # [m/s] the edge only cuts while moving


@dataclass(frozen=True)
class LinkBox:
    """The box of an excavator's front link in the link's (URDF) frame: full lengths ``size`` centred at ``offset``
    [m]. The plant's body of the link (its mass is centred in it) and the arm planner's collision box of it."""

    size: tuple[float, float, float] = setting(lo=0.01, doc="[m] full lengths along the link frame's x, y, z")
    offset: tuple[float, float, float] = setting((0.0, 0.0, 0.0), doc="[m] centre in the link frame")


@dataclass(frozen=True)
class Vessel:
    """The dump vessel on its rear hinge; angle 0 = lowered, + = raised (the URDF's sign is the opposite)."""

    hinge_xyz: tuple[float, float, float]
    max_angle: float  # [rad]
    velocity: float  # [rad/s]
    inner_length: float
    inner_width: float
    capacity: float  # [m^3] heaped
    floor_above_hinge: float  # [m] the inner floor above the hinge, vessel lowered
    rim_above_hinge: float  # [m] the side rim above the hinge, vessel lowered
    dead_time: float
    time_constant: float
    angle_gain: float  # [1/s] machine-side P gain from target angle to vessel velocity
    load_max_angle: float
    dump_start_angle: float
    dump_time: float
    dump_distance: float


@dataclass(frozen=True)
class Swing:
    """A carrier's rotating upper body (slew ring): ``rotate_joint`` about z at ``origin_xyz`` of base_link.

    Angle 0 = the vessel dumps to the rear of the tracks, + = counter-clockwise from above (as the excavator's
    swing). ``lower``/``upper`` None = endless (360 deg). The machine holds a commanded angle with its own
    P controller (``angle_gain``) through the dead time and lag of its hydraulic slew motor.
    """

    origin_xyz: tuple[float, float, float]
    lower: float | None
    upper: float | None
    velocity: float  # [rad/s]
    acceleration: float  # [rad/s^2]
    dead_time: float
    time_constant: float
    angle_gain: float  # [1/s]


@dataclass(frozen=True)
class Blade:
    """A dozer's blade on its lift arm: ``lift_joint`` (URDF + = down), cutting edge in ``blade_arm_link``.

    The machine holds a commanded lift angle with its own P controller (``angle_gain``) or follows a lift velocity.
    """

    edge_xyz: tuple[float, float, float]
    width: float  # [m] cutting edge
    capacity: float  # [m^3] soil the blade can push (rated blade capacity)
    angle_gain: float  # [1/s]
    cut_min_speed: float  # [m/s] the edge cuts only while the machine moves at least this fast
    spill_distance: float  # [m] ahead of the edge where soil beyond the blade's capacity is piled


@dataclass(frozen=True)
class PilotCutoff:
    """Pilot cut-off (hydraulic lock): solenoid delay [s], then actuators decay with these time constants [s]."""

    solenoid_delay: float
    front_time_constant: float
    tracks_time_constant: float


@dataclass(frozen=True)
class Machine:
    """One machine kind. ``joints`` are the hydraulically driven joints in bus (COM3 / joint_states) order."""

    kind: str
    type: str
    joints: tuple[Joint, ...]
    drives: Mapping[str, JointDrive]
    home_pose: Mapping[str, float]
    masses: Mapping[str, float]
    footprint: Footprint
    tracks: Tracks
    track_drive: TrackDrive
    pilot_cutoff: PilotCutoff | None
    pump_flow: float | None = None  # [L/min] shared by the joints with flow_at_limit > 0
    bucket: Bucket | None = None
    vessel: Vessel | None = None
    tf_prefix: str = ""  # frames of this machine on /tf are "<tf_prefix>/<link>" ("" = bare link names)
    swing: Swing | None = None  # crawler_dump: the rotating upper body, when it has one
    blade: Blade | None = None  # dozer
    cylinders: Cylinders | None = None  # excavator: the front's cylinders, bucket linkage and swing motor
    #: excavator: the box of each front joint's child link (body, boom, arm, bucket), ``link_boxes:`` of the YAML
    link_boxes: Mapping[str, LinkBox] = field(default_factory=lambda: MappingProxyType({}))
    dbc: str = ""  # DBC file of its COM3 bus in com3_can/dbc (can.dbc of the YAML)
    source: str = field(default="", compare=False)
    #: the machine's name on the site (its namespace; :func:`tms_model.fleet.load_named`); "" = the kind itself
    name: str = ""

    @property
    def model_name(self) -> str:
        """The name of this machine on the site (the original's ``model_name``): its own name, else its kind."""
        return self.name or self.kind

    def named(self, name: str) -> Machine:
        """This kind as the machine called ``name``. A ``tf_prefix`` that begins with the kind is the
        namespace's (ic120_ros2 launches ``<namespace>_tf``), so the name replaces the kind in it."""
        prefix = self.tf_prefix
        if prefix.startswith(self.kind):
            prefix = name + prefix[len(self.kind):]
        return dataclasses.replace(self, name=name, tf_prefix=prefix)

    def frame(self, link: str) -> str:
        """The /tf frame id of ``link`` of this machine (OPERA's ``${tf_prefix}/<link>`` convention)."""
        return f"{self.tf_prefix}/{link}" if self.tf_prefix else link

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"{self.source}: {self.kind} has no joint {name!r} (joints: {list(self.joint_names)})")

    def require(self, machine_type: str) -> Machine:
        """``self`` if it is of ``machine_type``, else a ConfigError naming the file (for per-type consumers)."""
        if self.type != machine_type:
            raise ConfigError(f"{self.source}: machine kind {self.kind!r} is a {self.type}, expected a {machine_type}")
        return self


def machine_path(kind: str) -> Path:
    """``config/machines/<kind>.yaml``."""
    return config_path("machines", f"{kind}.yaml")


def _joint(jr: Reader, name: str) -> Joint:
    j = jr.sub(name)
    j.only({"parent", "child", "origin_xyz", "origin_rpy", "axis", "position", "velocity", "acceleration"})
    pos = j.raw("position")
    lo = hi = None
    if pos is not None:
        lo, hi = j.vector("position", 2)
        if not lo < hi:
            raise j.key_error("position", f"lower limit must be below upper, got {pos!r}")
    axis = j.vector("axis", 3)
    if axis not in ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0)):
        raise j.key_error("axis", f"expected [0, 0, 1] (swing) or [0, 1, 0] (pitch), got {list(axis)}")
    return Joint(
        name=name,
        parent=j.string("parent"),
        child=j.string("child"),
        origin_xyz=j.vector("origin_xyz", 3),  # type: ignore[arg-type]
        origin_rpy=j.vector("origin_rpy", 3),  # type: ignore[arg-type]
        axis=axis,  # type: ignore[arg-type]
        lower=lo,
        upper=hi,
        velocity=j.number("velocity", lo=0.0),
        acceleration=j.number("acceleration", lo=0.0),
    )


def _tracks(top: Reader) -> tuple[Tracks, Footprint]:
    t = top.sub("tracks")
    if top.has("footprint"):
        t.only({"gauge", "max_speed", "max_yaw_rate", "max_accel", "max_yaw_accel"})
        fp = top.sub("footprint")
        fp.only({"length", "width"})
        footprint = Footprint(fp.number("length", lo=0.1), fp.number("width", lo=0.1))
    else:  # the excavator writes its footprint into tracks
        t.only({"gauge", "max_speed", "max_yaw_rate", "max_accel", "max_yaw_accel", "length", "width"})
        footprint = Footprint(t.number("length", lo=0.1), t.number("width", lo=0.1))
    tracks = Tracks(
        gauge=t.number("gauge", lo=0.1),
        max_speed=t.number("max_speed", lo=0.0),
        max_yaw_rate=t.number("max_yaw_rate", lo=0.0),
        max_accel=t.number("max_accel", lo=0.0) if t.has("max_accel") else None,
        max_yaw_accel=t.number("max_yaw_accel", lo=0.0) if t.has("max_yaw_accel") else None,
    )
    return tracks, footprint


def _track_drive(hyd: Reader) -> TrackDrive:
    h = hyd.sub("tracks")
    h.only({"dead_time_s", "time_constant_s", "slip", "yaw_slip"})
    return TrackDrive(
        dead_time=h.number("dead_time_s", lo=0.0, hi=5.0),
        time_constant=h.number("time_constant_s", lo=0.0, hi=10.0),
        slip=h.number("slip", lo=0.0, hi=0.9),
        yaw_slip=h.number("yaw_slip", lo=0.0, hi=0.9),
    )


def _cutoff(top: Reader) -> PilotCutoff | None:
    if not top.has("pilot_cutoff"):
        return None
    c = top.sub("pilot_cutoff")
    c.only({"source", "solenoid_delay_s", "front_time_constant_s", "tracks_time_constant_s"})
    return PilotCutoff(
        solenoid_delay=c.number("solenoid_delay_s", lo=0.0, hi=1.0),
        front_time_constant=c.number("front_time_constant_s", lo=0.0, hi=1.0),
        tracks_time_constant=c.number("tracks_time_constant_s", lo=0.0, hi=1.0),
    )


def _tf_prefix(top: Reader) -> str:
    if not top.has("tf_prefix"):
        return ""
    prefix = top.string("tf_prefix")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*", prefix):
        raise top.key_error(
            "tf_prefix", f"expected a frame name prefix such as <kind>_tf (no leading or trailing '/'), got {prefix!r}"
        )
    return prefix


def _dbc(top: Reader) -> str:
    """``can.dbc``: the DBC file of the machine's COM3 bus (a file name in com3_can/dbc)."""
    c = top.sub("can")
    c.only({"dbc"})
    name = c.string("dbc")
    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*\.dbc", name):
        raise c.key_error(
            "dbc", f"expected a DBC file name in com3_can/dbc such as crawler_carrier_com3.dbc, got {name!r}"
        )
    return name


def _masses(top: Reader) -> Mapping[str, float]:
    m = top.sub("masses")
    return MappingProxyType({name: m.number(name, lo=0.0) for name in m.keys()})


def _cylinders(top: Reader, front: tuple[str, ...]) -> Cylinders:
    cyl = top.schema(Cylinders, "cylinders")
    r = top.sub("cylinders")
    for key, c, joint in zip(("boom", "arm", "bucket"), cyl.all, front[1:], strict=True):
        if c.joint != joint:
            raise r.sub(key).key_error("joint", f"expected {joint!r} (front_joints order), got {c.joint!r}")
        if (c.child_pin is None) == (c.linkage is None):
            raise r.key_error(key, "give exactly one of child_pin (a pin on the child link) or linkage")
        if c.rod >= c.bore:
            raise r.sub(key).key_error("rod", f"rod {c.rod} m must be thinner than the bore {c.bore} m")
    if cyl.swing is None:
        raise r.key_error("swing", "an excavator needs its swing motor (displacement, relief, brake)")
    return cyl


def _excavator(top: Reader, kind: str, source: str) -> Machine:
    front = top.names("front_joints")
    if len(front) != 4:
        raise top.key_error(
            "front_joints", f"an excavator has 4 front joints (swing, boom, arm, bucket), got {list(front)}"
        )
    jr = top.sub("joints")
    jr.only(set(front))
    joints = tuple(_joint(jr, name) for name in front)
    if joints[0].axis != (0.0, 0.0, 1.0):
        raise jr.key_error(front[0], "the first front joint is the swing: axis must be [0, 0, 1]")
    for j in joints[1:]:
        if j.axis != (0.0, 1.0, 0.0):
            raise jr.key_error(j.name, "boom, arm and bucket pitch about y: axis must be [0, 1, 0]")
    hyd = top.sub("hydraulics")
    hyd.only({"source", "dead_time_s", "time_constant_s", "pump_flow_lpm", "flow_at_limit_lpm", "tracks", "bucket"})
    dead = hyd.per_name("dead_time_s", front, lo=0.0)
    tau = hyd.per_name("time_constant_s", front, lo=0.0)
    flows = hyd.sub("flow_at_limit_lpm")
    flows.only(set(front))
    drives = {n: JointDrive(dead[n], tau[n], flows.number(n, lo=0.0, default=0.0)) for n in front}
    home_r = top.sub("home_pose")
    home_r.only(set(front))
    home = {n: home_r.number(n) for n in front}
    b = hyd.sub("bucket")
    b.only({"width", "release_tip_angle", "spill_time_s", "cut_min_speed"})
    bucket = Bucket(
        tip_xyz=top.vector("bucket_tip_xyz", 3),  # type: ignore[arg-type]
        capacity=top.number("bucket_capacity", lo=0.01),
        width=b.number("width", lo=0.1),
        release_tip_angle=b.number("release_tip_angle"),
        spill_time=b.number("spill_time_s", lo=0.01),
        cut_min_speed=b.number("cut_min_speed", lo=0.0),
    )
    tracks, footprint = _tracks(top)
    boxes = top.sub("link_boxes")
    boxes.only({j.child for j in joints})
    return Machine(
        kind=kind,
        type=EXCAVATOR,
        cylinders=_cylinders(top, front),
        link_boxes=MappingProxyType({j.child: boxes.schema(LinkBox, j.child) for j in joints}),
        joints=joints,
        drives=MappingProxyType(drives),
        home_pose=MappingProxyType(home),
        masses=_masses(top),
        footprint=footprint,
        tracks=tracks,
        track_drive=_track_drive(hyd),
        pilot_cutoff=_cutoff(top),
        pump_flow=hyd.number("pump_flow_lpm", lo=1.0),
        bucket=bucket,
        tf_prefix=_tf_prefix(top),
        dbc=_dbc(top),
        source=source,
    )


def _limits(r: Reader, key: str) -> tuple[float | None, float | None]:
    """``position``-style limits: null = endless, else ``[lower, upper]`` with lower < upper."""
    if r.raw(key) is None:
        return None, None
    lo, hi = r.vector(key, 2)
    if not lo < hi:
        raise r.key_error(key, f"lower limit must be below upper, got {r.raw(key)!r}")
    return lo, hi


def _swing(top: Reader, hyd: Reader) -> Swing | None:
    if not top.has("swing"):
        if hyd.has("swing"):
            raise hyd.key_error("swing", "hydraulics of a swing, but the machine has no swing: section")
        return None
    s = top.sub("swing")
    s.only({"origin_xyz", "position", "velocity", "acceleration"})
    h = hyd.sub("swing")
    h.only({"dead_time_s", "time_constant_s", "angle_gain"})
    lo, hi = _limits(s, "position")
    if lo is not None and hi is not None and not (-math.pi <= lo and hi <= math.pi):
        raise s.key_error("position", f"limits must lie in [-pi, pi] rad (null = endless), got {s.raw('position')!r}")
    return Swing(
        origin_xyz=s.vector("origin_xyz", 3),  # type: ignore[arg-type]
        lower=lo,
        upper=hi,
        velocity=s.number("velocity", lo=0.001),
        acceleration=s.number("acceleration", lo=0.0),
        dead_time=h.number("dead_time_s", lo=0.0, hi=5.0),
        time_constant=h.number("time_constant_s", lo=0.0, hi=10.0),
        angle_gain=h.number("angle_gain", lo=0.0),
    )


def _crawler_dump(top: Reader, kind: str, source: str) -> Machine:
    hyd = top.sub("hydraulics")
    hyd.only({"source", "tracks", "vessel", "swing"})
    hv = hyd.sub("vessel")
    hv.only(
        {
            "dead_time_s",
            "time_constant_s",
            "angle_gain",
            "load_max_angle",
            "dump_start_angle",
            "dump_time_s",
            "dump_distance",
        }
    )
    v = top.sub("vessel")
    v.only({"hinge_xyz", "max_angle", "velocity", "inner_length", "inner_width", "capacity",
            "floor_above_hinge", "rim_above_hinge"})
    max_angle = v.number("max_angle", lo=0.01, hi=math.pi / 2)
    if not v.number("rim_above_hinge") > v.number("floor_above_hinge"):
        raise v.key_error("rim_above_hinge", f"must be above floor_above_hinge {v.number('floor_above_hinge')}, "
                          f"got {v.number('rim_above_hinge')}")
    vessel = Vessel(
        hinge_xyz=v.vector("hinge_xyz", 3),  # type: ignore[arg-type]
        max_angle=max_angle,
        velocity=v.number("velocity", lo=0.0),
        inner_length=v.number("inner_length", lo=0.1),
        inner_width=v.number("inner_width", lo=0.1),
        capacity=v.number("capacity", lo=0.01),
        floor_above_hinge=v.number("floor_above_hinge", lo=-5.0, hi=5.0),
        rim_above_hinge=v.number("rim_above_hinge", lo=-5.0, hi=10.0),
        dead_time=hv.number("dead_time_s", lo=0.0, hi=5.0),
        time_constant=hv.number("time_constant_s", lo=0.0, hi=10.0),
        angle_gain=hv.number("angle_gain", lo=0.0),
        load_max_angle=hv.number("load_max_angle", lo=0.0),
        dump_start_angle=hv.number("dump_start_angle", lo=0.0, hi=max_angle),
        dump_time=hv.number("dump_time_s", lo=0.01),
        dump_distance=hv.number("dump_distance", lo=0.0),
    )
    swing = _swing(top, hyd)
    joints: list[Joint] = []
    drives = {}
    home = {}
    hinge_parent, hinge = "base_link", vessel.hinge_xyz
    if swing is not None:  # bus order: rotate_joint, then the vessel (com3_ros's rot_dump_cmd order)
        joints.append(Joint(
            name=ROTATE_JOINT,
            parent="track_link",
            child="body_link",
            origin_xyz=swing.origin_xyz,
            origin_rpy=(0.0, 0.0, 0.0),
            axis=(0.0, 0.0, 1.0),
            lower=swing.lower,
            upper=swing.upper,
            velocity=swing.velocity,
            acceleration=swing.acceleration,
        ))
        drives[ROTATE_JOINT] = JointDrive(swing.dead_time, swing.time_constant, 0.0)
        home[ROTATE_JOINT] = 0.0
        # the hinge is given in base_link at swing 0; on the rotating body it is relative to the slew centre
        hinge_parent = "body_link"
        hinge = tuple(h - o for h, o in zip(vessel.hinge_xyz, swing.origin_xyz, strict=True))  # type: ignore[assignment]
    joints.append(Joint(
        name=VESSEL_JOINT,
        parent=hinge_parent,
        child="vessel_link",
        origin_xyz=hinge,
        origin_rpy=(0.0, 0.0, 0.0),
        axis=(0.0, -1.0, 0.0),  # URDF: negative = raised about +y; ours: positive = raised
        lower=0.0,
        upper=max_angle,
        velocity=vessel.velocity,
        acceleration=math.inf,
    ))
    drives[VESSEL_JOINT] = JointDrive(vessel.dead_time, vessel.time_constant, 0.0)
    home[VESSEL_JOINT] = 0.0
    tracks, footprint = _tracks(top)
    return Machine(
        kind=kind,
        type=CRAWLER_DUMP,
        joints=tuple(joints),
        drives=MappingProxyType(drives),
        home_pose=MappingProxyType(home),
        masses=_masses(top),
        footprint=footprint,
        tracks=tracks,
        track_drive=_track_drive(hyd),
        pilot_cutoff=_cutoff(top),
        vessel=vessel,
        tf_prefix=_tf_prefix(top),
        swing=swing,
        dbc=_dbc(top),
        source=source,
    )


def _dozer(top: Reader, kind: str, source: str) -> Machine:
    hyd = top.sub("hydraulics")
    hyd.only({"source", "tracks", "blade"})
    hb = hyd.sub("blade")
    hb.only({"dead_time_s", "time_constant_s", "angle_gain", "cut_min_speed", "spill_distance"})
    b = top.sub("blade")
    b.only({"lift_joint", "edge_xyz", "width", "capacity"})
    lift = _joint(b, "lift_joint")
    if lift.axis != (0.0, 1.0, 0.0) or lift.lower is None or lift.upper is None:
        raise b.key_error("lift_joint", "the blade lifts about y with limits: axis [0, 1, 0], position [lower, upper]")
    lift = Joint(LIFT_JOINT, lift.parent, lift.child, lift.origin_xyz, lift.origin_rpy, lift.axis, lift.lower,
                 lift.upper, lift.velocity, lift.acceleration)
    blade = Blade(
        edge_xyz=b.vector("edge_xyz", 3),  # type: ignore[arg-type]
        width=b.number("width", lo=0.1),
        capacity=b.number("capacity", lo=0.01),
        angle_gain=hb.number("angle_gain", lo=0.0),
        cut_min_speed=hb.number("cut_min_speed", lo=0.0),
        spill_distance=hb.number("spill_distance", lo=0.0),
    )
    tracks, footprint = _tracks(top)
    return Machine(
        kind=kind,
        type=DOZER,
        joints=(lift,),
        drives=MappingProxyType({LIFT_JOINT: JointDrive(hb.number("dead_time_s", lo=0.0, hi=5.0),
                                                        hb.number("time_constant_s", lo=0.0, hi=10.0), 0.0)}),
        home_pose=MappingProxyType({LIFT_JOINT: max(lift.lower, min(lift.upper, 0.0))}),
        masses=_masses(top),
        footprint=footprint,
        tracks=tracks,
        track_drive=_track_drive(hyd),
        pilot_cutoff=_cutoff(top),
        blade=blade,
        tf_prefix=_tf_prefix(top),
        dbc=_dbc(top),
        source=source,
    )


#: machine type -> parser of its description (``(reader of the file, kind, source) -> Machine``)
PARSERS: Mapping[str, Callable[[Reader, str, str], Machine]] = MappingProxyType({
    EXCAVATOR: _excavator,
    CRAWLER_DUMP: _crawler_dump,
    DOZER: _dozer,
})
#: the machine types, in the order of :data:`PARSERS`
TYPES: tuple[str, ...] = tuple(PARSERS)


def parse_machine(path: str | Path, kind: str | None = None) -> Machine:
    """Parse one machine YAML (uncached; tests feed malformed files through this)."""
    path = Path(path)
    data, where = load_yaml(path)
    top = Reader(data, where)
    kind = kind or path.stem
    name = top.string("model_name")
    if name != kind:
        raise top.key_error("model_name", f"expected {kind!r} (the file's kind), got {name!r}")
    mtype = top.string("type")
    parser = PARSERS.get(mtype)
    if parser is None:
        raise top.key_error("type", f"unknown machine type {mtype!r}; expected one of {list(TYPES)}")
    return parser(top, kind, str(path))


@functools.lru_cache(maxsize=16)
def _cached(path: str, kind: str) -> Machine:
    return parse_machine(path, kind)


def load_machine(kind: str, path: str | Path | None = None) -> Machine:
    """The description of machine ``kind`` from ``config/machines/<kind>.yaml`` (or ``path``), parsed once.

    Raises:
        ConfigError: unknown kind (naming the file searched) or ``file:line: key: problem``.
    """
    resolved = Path(path) if path else machine_path(kind)
    if not resolved.is_file():
        known = sorted(p.stem for p in machine_path(kind).parent.glob("*.yaml"))
        raise ConfigError(f"{resolved}: no such machine description (machine kind {kind!r}; known kinds: {known})")
    return _cached(str(resolved.resolve()), kind)
