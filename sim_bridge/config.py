"""Plant configuration: the plant YAML (``config/sim/plant.yaml``) and the plant's view of the machines and site.

The machine descriptions (``config/machines/*.yaml``) and the site (``config/site.yaml``) are read by
:mod:`tms_model`; this module reads the plant YAML and freezes what the plant needs into dataclasses. A
wrong value raises :class:`~sim_bridge.errors.SimConfigError` with ``file:line: key.path: problem (got
value)``, so a malformed machine YAML names the key that is wrong; inside the plant YAML, unknown keys are
errors (a typo must not silently fall back to a default).
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sim_bridge.errors import SimConfigError
from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_model.machines import (
    CRAWLER_DUMP,
    DOZER,
    EXCAVATOR,
    LIFT_JOINT,
    ROTATE_JOINT,
    VESSEL_JOINT,
    Blade,
    Joint,
    JointDrive,
    Machine,
    load_machine,
    machine_path,
    parse_machine,
)
from tms_common.schema import Reader
from tms_model.site import Site, load_site

__all__ = [
    "TrackSpec",
    "ExcavatorSpec",
    "CarrierSpec",
    "DozerSpec",
    "Zx200Spec",
    "Ic120Spec",
    "SoilSpec",
    "SensorSpec",
    "PlantSpec",
    "CutoffSpec",
    "load_excavator",
    "load_carrier",
    "load_dozer",
    "load_zx200",
    "load_ic120",
    "load_plant",
]


@dataclass(frozen=True)
class CutoffSpec:
    """Pilot cut-off (hydraulic lock): the pilot shut-off solenoid vents the pilot line, spools spring to neutral.

    ``solenoid_delay`` [s] from the cut-off command on the bus to pilot pressure gone; then every actuator
    output decays to zero with ``front_time_constant`` (main spools centring, cylinders held) or
    ``tracks_time_constant`` (travel spools centring, travel motors braked), bypassing the proportional
    command path's dead time.
    """

    solenoid_delay: float
    front_time_constant: float
    tracks_time_constant: float


@dataclass(frozen=True)
class TrackSpec:
    """Skid-steer undercarriage: limits, actuator lag and slip."""

    gauge: float  # [m]
    max_speed: float  # [m/s] per track
    max_yaw_rate: float  # [rad/s]
    length: float  # footprint [m]
    width: float
    dead_time: float  # [s]
    time_constant: float  # [s]
    slip: float  # longitudinal slip ratio: ground speed = track speed * (1 - slip)
    yaw_slip: float  # yaw rate lost to lateral skidding: yaw = (vr - vl) / gauge * (1 - yaw_slip)


@dataclass(frozen=True)
class ExcavatorSpec:
    """A backhoe (ZX200, ZX120, ...): front joints in bus order, bucket tip, tracks, pumps and bucket soil handling."""

    joints: tuple[Joint, ...]  # tms_model's, in bus order
    drives: Mapping[str, JointDrive]  # joint name -> its hydraulic actuator
    bucket_tip_xyz: tuple[float, float, float]
    home_pose: dict[str, float]
    tracks: TrackSpec
    pump_flow: float  # [L/min] shared by the joints with flow_at_limit > 0
    bucket_capacity: float  # [m^3]
    bucket_width: float  # [m] cutting edge width
    release_tip_angle: float  # [rad] tip angle below horizontal under which the bucket spills
    spill_time: float  # [s] to empty a full bucket when fully open
    cut_min_speed: float  # [m/s] the edge only cuts while moving at least this fast
    source: str
    pilot_cutoff: CutoffSpec | None = None  # None: no pilot cut-off modelled (section absent)

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)


@dataclass(frozen=True)
class CarrierSpec:
    """A crawler carrier (IC120; the MSTs with a rotating upper body): tracks and the vessel on its rear hinge.

    ``hinge_xyz`` is in base_link at swing 0; with a ``swing`` the vessel turns with the upper body about the
    vertical axis through ``swing.origin_xyz``.
    """

    tracks: TrackSpec
    hinge_xyz: tuple[float, float, float]
    vessel: Joint  # angle 0 = lowered, + = raised
    drives: Mapping[str, JointDrive]  # the vessel joint's hydraulic actuator
    vessel_angle_gain: float  # [1/s] P gain of the machine's own angle controller (vessel_cmd is a target angle)
    inner_length: float
    inner_width: float
    capacity: float  # [m^3]
    load_max_angle: float  # [rad] soil lands in the vessel only while it is this low
    dump_start_angle: float  # [rad] soil starts to slide out above this angle
    dump_time: float  # [s] to empty a full vessel when fully raised
    dump_distance: float  # [m] behind the hinge where the dumped pile is centred
    source: str
    pilot_cutoff: CutoffSpec | None = None  # None: no pilot cut-off modelled (section absent)
    swing: Joint | None = None  # rotate_joint of the upper body (None: the vessel does not swing)
    swing_angle_gain: float = 0.0  # [1/s] P gain of the machine's own swing angle controller

    @property
    def joints(self) -> tuple[Joint, ...]:
        """The machine's joints in bus order (rotate_joint first, as com3_ros's rot_dump_cmd)."""
        return (self.vessel,) if self.swing is None else (self.swing, self.vessel)


@dataclass(frozen=True)
class DozerSpec:
    """A dozer (D37PXi): tracks and the blade on its lift arm (``lift``: lift_joint, + = down)."""

    tracks: TrackSpec
    lift: Joint
    drives: Mapping[str, JointDrive]  # the lift joint's hydraulic actuator
    blade: Blade  # edge, width, capacity, angle gain, cutting
    home_lift: float
    source: str
    pilot_cutoff: CutoffSpec | None = None


@dataclass(frozen=True)
class SoilSpec:
    """Height-field site with one mound (a truncated cone on flat ground, from ``site.yaml``'s ``mound``)."""

    x_min: float
    y_min: float
    size_x: float
    size_y: float
    resolution: float
    mound_center: tuple[float, float]
    mound_base_radius: float
    mound_top_radius: float  # truncated cone; 0 = cone
    mound_height: float
    ground_z: float
    deposit_radius: float  # [m] disc over which released soil lands on the ground
    dump_radius: float  # [m] disc of a vessel dump pile
    mound_region_margin: float  # [m] beyond the base radius still counted as the mound (spills at its foot)


@dataclass(frozen=True)
class SensorSpec:
    """Sensor noise (1 sigma) and seed: RTK-fix GNSS, IMU, encoders."""

    gnss_sigma_h: float
    gnss_sigma_v: float
    imu_sigma: float
    seed: int


@dataclass(frozen=True)
class PlantSpec:
    """Everything the plant needs, with where it came from.

    ``machines`` maps each machine's name on the site (``zx200``, ``ic120``, ``zx120``, ``mst110cr``, ...) to its
    spec, ``types`` to its type (the plant profile, :mod:`sim_bridge.profiles`) and ``dbcs`` to the DBC of its bus
    (its machine description's). The paper's soil experiment (``experiment: dig_and_carry``, the default) digs with
    ``excavator`` and carries with ``carrier``: the first machine of each type in the plant YAML; a plant YAML
    with ``experiment: none`` may hold any machines (then ``excavator`` / ``carrier`` may be "").
    """

    machines: dict[str, Any]
    types: dict[str, str]
    site: Site  # tms_model: points, mound, CRS, map origin and the one projector
    soil: SoilSpec
    sensors: SensorSpec
    dt: float
    watchdog_s: float
    initial_poses: dict[str, tuple[float, float, float]]  # machine -> (x, y, yaw) in map
    files: tuple[str, ...]
    excavator: str = ""
    carrier: str = ""
    dbcs: dict[str, str] = field(default_factory=dict)
    experiment: str = "dig_and_carry"

    @property
    def zx200(self) -> ExcavatorSpec:
        """The spec of the soil-digging excavator (the paper's ZX200)."""
        return self.machines[self.excavator]

    @property
    def ic120(self) -> CarrierSpec:
        """The spec of the soil-carrying crawler carrier (the paper's IC120)."""
        return self.machines[self.carrier]


@contextlib.contextmanager
def _as_plant_error():
    """tms_model's ``ConfigError`` (``file:line: key: problem``) re-raised as a plant configuration error."""
    try:
        yield
    except SimConfigError:
        raise
    except ConfigError as exc:
        raise SimConfigError(str(exc)) from None


@_as_plant_error()
def _description(path: str | Path, machine_type: str | None = None) -> Machine:
    """The tms_model description of a machine YAML, required to be of ``machine_type`` when given.

    Files under ``config/`` are read once (tms_model's cache); others (tests' broken copies) every time.
    """
    path = Path(path)
    if path.resolve().is_relative_to(config_path().resolve()):
        machine = load_machine(path.stem, path)
    else:
        machine = parse_machine(path)
    return machine if machine_type is None else machine.require(machine_type)


def _track_spec(m: Machine) -> TrackSpec:
    t, d = m.tracks, m.track_drive
    return TrackSpec(
        gauge=t.gauge, max_speed=t.max_speed, max_yaw_rate=t.max_yaw_rate, length=m.footprint.length,
        width=m.footprint.width, dead_time=d.dead_time, time_constant=d.time_constant, slip=d.slip,
        yaw_slip=d.yaw_slip,
    )


def _cutoff_spec(m: Machine) -> CutoffSpec | None:
    c = m.pilot_cutoff
    return None if c is None else CutoffSpec(c.solenoid_delay, c.front_time_constant, c.tracks_time_constant)


def load_excavator(path: str | Path) -> ExcavatorSpec:
    """The plant's view of an excavator description (geometry from the URDF section, actuators from ``hydraulics:``)."""
    m = _description(path, EXCAVATOR)
    b = m.bucket
    assert b is not None and m.pump_flow is not None  # tms_model: every excavator has them
    return ExcavatorSpec(
        joints=m.joints,
        drives=m.drives,
        bucket_tip_xyz=b.tip_xyz,
        home_pose=dict(m.home_pose),
        tracks=_track_spec(m),
        pump_flow=m.pump_flow,
        bucket_capacity=b.capacity,
        bucket_width=b.width,
        release_tip_angle=b.release_tip_angle,
        spill_time=b.spill_time,
        cut_min_speed=b.cut_min_speed,
        source=str(path),
        pilot_cutoff=_cutoff_spec(m),
    )


def load_carrier(path: str | Path) -> CarrierSpec:
    """The plant's view of a crawler-dump description (tracks, vessel, ``hydraulics:``)."""
    m = _description(path, CRAWLER_DUMP)
    v = m.vessel
    assert v is not None  # tms_model: every crawler dump has one
    return CarrierSpec(
        tracks=_track_spec(m),
        hinge_xyz=v.hinge_xyz,
        vessel=m.joint(VESSEL_JOINT),
        drives=m.drives,
        vessel_angle_gain=v.angle_gain,
        inner_length=v.inner_length,
        inner_width=v.inner_width,
        capacity=v.capacity,
        load_max_angle=v.load_max_angle,
        dump_start_angle=v.dump_start_angle,
        dump_time=v.dump_time,
        dump_distance=v.dump_distance,
        source=str(path),
        pilot_cutoff=_cutoff_spec(m),
        swing=m.joint(ROTATE_JOINT) if m.swing is not None else None,
        swing_angle_gain=m.swing.angle_gain if m.swing is not None else 0.0,
    )


def load_dozer(path: str | Path) -> DozerSpec:
    """The plant's view of a dozer description (tracks, blade, ``hydraulics:``)."""
    m = _description(path, DOZER)
    assert m.blade is not None  # tms_model: every dozer has one
    return DozerSpec(
        tracks=_track_spec(m),
        lift=m.joint(LIFT_JOINT),
        drives=m.drives,
        blade=m.blade,
        home_lift=m.home_pose[LIFT_JOINT],
        source=str(path),
        pilot_cutoff=_cutoff_spec(m),
    )


def load_zx200(path: str | Path | None = None) -> ExcavatorSpec:
    """The ZX200 (default ``config/machines/zx200.yaml``)."""
    return load_excavator(path or machine_path("zx200"))


def load_ic120(path: str | Path | None = None) -> CarrierSpec:
    """The IC120 (default ``config/machines/ic120.yaml``)."""
    return load_carrier(path or machine_path("ic120"))


#: plant YAML ``experiment``: the paper's dig-load-carry-dump soil experiment (needs an excavator and a crawler
#: carrier), or none (any machines, e.g. a test plant of one kind)
EXPERIMENTS = ("dig_and_carry", "none")

Zx200Spec = ExcavatorSpec
Ic120Spec = CarrierSpec


@_as_plant_error()
def load_plant(
    path: str | Path | None = None,
    *,
    zx200: str | Path | None = None,
    ic120: str | Path | None = None,
    site: str | Path | None = None,
) -> PlantSpec:
    """Read the plant YAML and the machine/site YAMLs it names (paths relative to ``config/``).

    ``machines`` maps a machine name to its machine YAML; the YAML's ``type`` picks the plant profile
    that reads it. Explicit ``zx200``/``ic120``/``site`` paths override the plant file's entries of those
    names (tests use this to feed a malformed machine YAML).
    """
    from sim_bridge.profiles import PLANT_PROFILES

    path = Path(path) if path else config_path("sim", "plant.yaml")
    data, where = load_yaml(path)
    top = Reader(data, where)
    top.only({"machines", "site", "step_s", "watchdog_s", "initial_poses", "initial_front", "soil", "sensors",
              "experiment"})
    experiment = top.string("experiment", default="dig_and_carry")
    if experiment not in EXPERIMENTS:
        raise top.key_error("experiment", f"expected one of {list(EXPERIMENTS)}, got {experiment!r}")
    m = top.sub("machines")
    base = config_path()
    given = {"zx200": zx200, "ic120": ic120}
    machine_paths = {name: Path(given[name]) if given.get(name) else base / m.string(name) for name in m.data}
    site_path = Path(site) if site else base / top.string("site")
    site_model = load_site(site_path)
    poses_r = top.sub("initial_poses")
    poses_r.only(set(machine_paths))
    poses = {}
    for name in machine_paths:
        if isinstance(poses_r.raw(name), str):  # a point name in site.yaml
            point = poses_r.string(name)
            if point not in site_model.points:
                raise poses_r.key_error(name, f"no point {point!r} in {site_path} "
                                        f"(known: {sorted(site_model.points)})")
            p = site_model.points[point]
            poses[name] = (p.x, p.y, p.yaw)
        else:
            poses[name] = poses_r.vector(name, 3)
    s = top.sub("soil")
    s.only({"grid", "deposit_radius", "dump_radius", "mound_region_margin"})
    g = s.sub("grid")
    g.only({"x_min", "y_min", "size_x", "size_y", "resolution"})
    mound = site_model.mound
    soil = SoilSpec(
        x_min=g.number("x_min"),
        y_min=g.number("y_min"),
        size_x=g.number("size_x", lo=1.0),
        size_y=g.number("size_y", lo=1.0),
        resolution=g.number("resolution", lo=0.02, hi=2.0),
        mound_center=(mound.cx, mound.cy),
        mound_base_radius=mound.base_radius,
        mound_top_radius=mound.top_radius,
        mound_height=mound.height,
        ground_z=mound.ground_z,
        deposit_radius=s.number("deposit_radius", lo=0.0),
        dump_radius=s.number("dump_radius", lo=0.0),
        mound_region_margin=s.number("mound_region_margin", lo=0.0),
    )
    sn = top.sub("sensors")
    sn.only({"gnss_sigma_h", "gnss_sigma_v", "imu_sigma", "seed"})
    sensors = SensorSpec(
        gnss_sigma_h=sn.number("gnss_sigma_h", lo=0.0),
        gnss_sigma_v=sn.number("gnss_sigma_v", lo=0.0),
        imu_sigma=sn.number("imu_sigma", lo=0.0),
        seed=int(sn.number("seed", lo=0)),
    )
    specs: dict[str, Any] = {}
    types: dict[str, str] = {}
    dbcs: dict[str, str] = {}
    for name, mpath in machine_paths.items():
        description = _description(mpath)
        entry = site_model.machines.get(name)
        if entry is None:
            raise m.key_error(name, f"no machine {name!r} on the site {site_path} (known: {sorted(site_model.machines)})")
        if entry.kind != description.kind:
            raise m.key_error(name, f"{mpath} describes a {description.kind}, but {name!r} is a {entry.kind} on the "
                              f"site {site_path}")
        kind = description.type
        try:
            profile = PLANT_PROFILES.get(kind)
        except ConfigError as exc:
            raise SimConfigError(f"{mpath}: type: {exc}") from None
        specs[name], types[name] = profile.load_spec(mpath), kind
        dbcs[name] = description.dbc or profile.dbc
    first = {k: next((n for n in types if types[n] == k), "") for k in (EXCAVATOR, CRAWLER_DUMP)}
    if experiment == "dig_and_carry" and (not first[EXCAVATOR] or not first[CRAWLER_DUMP]):
        raise top.key_error("machines", "the site needs an excavator and a crawler carrier (soil is dug and carried); "
                       f"got types {types} (a plant without the soil experiment says experiment: none)")
    if top.has("initial_front"):
        if not first[EXCAVATOR]:
            raise top.key_error("initial_front", "front joints of the digging excavator, but the plant has none")  # front joints of the digging excavator at start (default: its home_pose)
        import dataclasses

        zx = specs[first[EXCAVATOR]]
        front = top.per_name("initial_front", list(zx.home_pose))
        specs[first[EXCAVATOR]] = dataclasses.replace(zx, home_pose={**zx.home_pose, **front})
    return PlantSpec(
        machines=specs,
        types=types,
        site=site_model,
        soil=soil,
        sensors=sensors,
        dt=top.number("step_s", lo=0.0005, hi=0.05),
        watchdog_s=top.number("watchdog_s", lo=0.01),
        initial_poses=poses,  # type: ignore[arg-type]
        files=(str(path), *(str(p) for p in machine_paths.values()), str(site_path)),
        excavator=first[EXCAVATOR],
        carrier=first[CRAWLER_DUMP],
        dbcs=dbcs,
        experiment=experiment,
    )
