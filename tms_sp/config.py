"""Sensing configuration: config/tms_sp/sensing.yaml + the site and machine descriptions (tms_model).

:func:`load_sensing_config` returns a frozen :class:`SensingConfig`. The sensing YAML is read through
:mod:`tms_common.schema` (the private dataclasses below are its schema): a missing, unknown or wrong key raises
``ConfigError`` with ``file:line: key.path: problem``.

Machines are known by their site names (config/site.yaml ``machines``): ``excavator`` digs and loads,
``carriers`` are the crawler carriers it loads. Their facts come from their kinds' descriptions
(config/machines/<kind>.yaml): the bucket's capacity and width, the swing axis, each carrier's vessel
(inner size, capacity, hinge, floor and rim above the hinge).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader, read_schema, setting
from tms_model.fleet import load_named
from tms_model.geometry import Pose2D
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR
from tms_model.site import Mound, Site, load_site
from tms_sp.arrival import ArrivalParams
from tms_sp.heightgrid import GridSpec
from tms_sp.mound import ExcavationParams
from tms_sp.vessel import VesselGeometry, VesselParams

__all__ = ["SensingConfig", "load_sensing_config", "carrier_vessel_geometry", "planner_approach_height"]


# ---- the schema of config/tms_sp/sensing.yaml (documented inline there) -----------------------------------------
@dataclass(frozen=True)
class _Excavation:
    record: str
    approach_record: str | None  # null = none (the original's trees have no approach record)
    roi_margin: float = setting(lo=0.0)
    reach_min: float = setting(lo=0.0)
    reach_max: float = setting(lo=0.0)
    penetration_depth: float = setting(lo=0.0)
    max_penetration_depth: float = setting(lo=0.0)
    depth_steps: int = setting(lo=1)
    drag_length: float = setting(lo=0.0)
    attack_angle_deg: float = setting(lo=0.0, hi=90.0)
    theta_w_min_deg: float = setting(lo=-90.0, hi=180.0)
    theta_w_max_deg: float = setting(lo=-90.0, hi=180.0)
    distance_penalty: float = setting(lo=0.0)
    min_height: float = setting(lo=0.0)
    min_volume: float = setting(lo=0.0)
    depleted_hysteresis: float = setting(lo=0.0)
    min_cut: float = setting(lo=0.0)
    update_threshold: float = setting(lo=0.0)
    target_hysteresis: float = setting(lo=0.0)


@dataclass(frozen=True)
class _Vessel:
    release_record: str
    angle_record: str
    wall_margin: float
    clearance: float
    carry_theta_w_deg: float
    target_fill: float
    loaded_hysteresis: float
    update_threshold: float = setting(lo=0.0)
    release_hysteresis: float = setting(lo=0.0)


@dataclass(frozen=True)
class _Arrival:
    point: str
    position_tolerance: float
    yaw_tolerance_deg: float
    max_speed: float
    speed_window_s: float
    hold_s: float


@dataclass(frozen=True)
class _Sensing:
    blackboard_records: tuple[str, ...]
    grid_resolution: float = setting(lo=0.001)
    excavator: str = setting(doc="site machine name of the excavator")
    excavator_base: str = setting(doc="site.yaml points key of the excavator's base_link pose")
    carriers: tuple[str, ...] = setting(doc="site machine names of the carriers it loads")
    excavation: _Excavation = setting()
    vessel: _Vessel = setting()
    arrival: _Arrival = setting()

    def __post_init__(self) -> None:
        for key in ("blackboard_records", "carriers"):
            names = getattr(self, key)
            if not names or len(set(names)) != len(names):
                raise ValueError(f"{key}: expected a non-empty list of distinct names, got {list(names)}")


# ---- the configuration the processors and the node use ---------------------------------------------------------
@dataclass(frozen=True)
class SensingConfig:
    """Everything the sensing processors and node need."""

    blackboard_records: tuple[str, ...]  # global-blackboard records the SENSING_* flags go to (the first is read too)
    resolution: float
    site: Site
    points: Mapping[str, Pose2D]
    mound: Mound
    mound_grid: GridSpec
    excavator: str  # site name of the excavator: model_name of the records sensing writes
    excavator_base_point: str  # its base pose in ``points`` (used until a measured pose arrives)
    excavation: ExcavationParams
    excavation_record: str
    approach_record: str  # "" = none
    approach_height: float  # the excavator's planner's (:func:`planner_approach_height`); 0.0 without approach_record
    excavation_update_threshold: float
    carriers: tuple[str, ...]
    vessels: Mapping[str, VesselGeometry]  # per carrier name: its kind's vessel
    vessel: VesselParams
    release_record: str
    angle_record: str
    vessel_update_threshold: float
    arrival: ArrivalParams
    arrival_point: str
    swing_axis_in_base: tuple[float, float]
    source: str = dataclasses.field(default="", compare=False)

    @property
    def excavator_base(self) -> Pose2D:
        return self.points[self.excavator_base_point]

    @property
    def vessel_geom(self) -> VesselGeometry:
        """The first carrier's vessel (the paper's single carrier)."""
        return self.vessels[self.carriers[0]]

    def swing_axis_map(self) -> tuple[float, float]:
        p = self.excavator_base.to_map([self.swing_axis_in_base[0], self.swing_axis_in_base[1], 0.0])
        return float(p[0]), float(p[1])

    def vessel_geometry(self, name: str) -> VesselGeometry:
        """The vessel of the site's carrier ``name``: that of one of ``carriers``, else read from its kind's
        description."""
        if name in self.vessels:
            return self.vessels[name]
        try:
            return _vessel_geometry(name, self.site)
        except ConfigError as exc:
            raise ConfigError(f"carrier {name!r}: {exc}") from None


def _vessel_geometry(name: str, site: Site) -> VesselGeometry:
    v = load_named(name, site=site).require(CRAWLER_DUMP).vessel
    assert v is not None
    return VesselGeometry(inner_length=v.inner_length, inner_width=v.inner_width, capacity=v.capacity,
                          hinge_xyz=v.hinge_xyz, floor_above_hinge=v.floor_above_hinge,
                          rim_above_hinge=v.rim_above_hinge)


def planner_approach_height(kind: str) -> float:
    """``approach_height`` of excavator ``kind``'s planner, ``config/tms_rp/<kind>_planner.yaml``: the height above
    the target of the excavate's first point. The approach record sensing writes is the target this much higher, so
    the tree's return over the mound ends where the excavate begins: one value, the planner's (tms_sp may not import
    tms_rp, a package of its level, so it reads that one key of the planner's file; tms_rp.arm.planner's schema
    checks the whole file and requires the key)."""
    data, where = load_yaml(config_path("tms_rp", f"{kind}_planner.yaml"))
    return Reader(data, where).number("approach_height", lo=0.0)


def load_sensing_config(
    sensing: str | Path | None = None,
    site: str | Path | None = None,
    *,
    excavator: str = "",
    carriers: tuple[str, ...] | list[str] = (),
) -> SensingConfig:
    """Load and validate the sensing configuration (defaults: the project's config/ files).

    ``excavator`` and ``carriers`` (site machine names) replace the YAML's when given (node parameters).
    """
    data, where = load_yaml(sensing or config_path("tms_sp", "sensing.yaml"))
    s = read_schema(_Sensing, data, where)
    top = Reader(data, where)
    the_site = load_site(site)

    def fail(path: tuple[str, ...], problem: str) -> ConfigError:
        return top.error(path, problem)

    excavator = excavator or s.excavator
    carriers = tuple(carriers) or s.carriers
    if len(set(carriers)) != len(carriers):
        raise fail(("carriers",), f"a carrier is named twice: {list(carriers)}")
    try:
        zx = load_named(excavator, site=the_site).require(EXCAVATOR)
    except ConfigError as exc:
        raise fail(("excavator",), f"{excavator!r}: {exc}") from None
    vessels = {}
    for c in carriers:
        try:
            vessels[c] = _vessel_geometry(c, the_site)
        except ConfigError as exc:
            raise fail(("carriers",), f"{c!r}: {exc}") from None
    assert zx.bucket is not None

    points = dict(the_site.points)
    for key, name in (("excavator_base", s.excavator_base), ("arrival", s.arrival.point)):
        if name not in points:
            path = (key,) if key == "excavator_base" else ("arrival", "point")
            raise fail(path, f"{name!r} is not a pose in {the_site.source} points ({sorted(points)})")
    mound = the_site.mound

    e = s.excavation
    half = mound.base_radius + e.roi_margin
    grid = GridSpec(mound.cx - half, mound.cy - half, mound.cx + half, mound.cy + half, s.grid_resolution)
    try:
        excavation = ExcavationParams(
            reach_min=e.reach_min,
            reach_max=e.reach_max,
            bucket_radius=zx.bucket.width / 2.0,  # the scored footprint is the bucket's cutting edge
            penetration_depth=e.penetration_depth,
            max_penetration_depth=e.max_penetration_depth,
            bucket_volume=zx.bucket.capacity,
            depth_steps=e.depth_steps,
            drag_length=e.drag_length,
            attack_angle=math.radians(e.attack_angle_deg),
            theta_w_min=math.radians(e.theta_w_min_deg),
            theta_w_max=math.radians(e.theta_w_max_deg),
            distance_penalty=e.distance_penalty,
            min_height=e.min_height,
            min_volume=e.min_volume,
            ground_z=mound.ground_z,
            target_hysteresis=e.target_hysteresis,
            depleted_hysteresis=e.depleted_hysteresis,
            min_cut=e.min_cut,
        )
    except ValueError as exc:
        raise fail(("excavation",), str(exc)) from None

    v = s.vessel
    try:
        vparams = VesselParams(
            wall_margin=v.wall_margin,
            clearance=v.clearance,
            carry_theta_w=math.radians(v.carry_theta_w_deg),
            target_fill=v.target_fill,
            release_hysteresis=v.release_hysteresis,
            loaded_hysteresis=v.loaded_hysteresis,
        )
    except ValueError as exc:
        raise fail(("vessel",), str(exc)) from None

    a = s.arrival
    try:
        arrival = ArrivalParams(
            position_tolerance=a.position_tolerance,
            yaw_tolerance=math.radians(a.yaw_tolerance_deg),
            max_speed=a.max_speed,
            hold_s=a.hold_s,
            speed_window_s=a.speed_window_s,
        )
    except ValueError as exc:
        raise fail(("arrival",), str(exc)) from None

    approach_height = 0.0
    if e.approach_record:
        try:
            approach_height = planner_approach_height(zx.kind)
        except ConfigError as exc:
            raise fail(("excavation", "approach_record"), f"the approach record is the target the planner's "
                       f"approach_height higher: {exc}") from None

    swing_origin = zx.joints[0].origin_xyz  # the swing joint comes first in bus order
    return SensingConfig(
        blackboard_records=s.blackboard_records,
        resolution=s.grid_resolution,
        site=the_site,
        points=MappingProxyType(points),
        mound=mound,
        mound_grid=grid,
        excavator=excavator,
        excavator_base_point=s.excavator_base,
        excavation=excavation,
        excavation_record=e.record,
        approach_record=e.approach_record or "",
        approach_height=approach_height,
        excavation_update_threshold=e.update_threshold,
        carriers=carriers,
        vessels=MappingProxyType(vessels),
        vessel=vparams,
        release_record=v.release_record,
        angle_record=v.angle_record,
        vessel_update_threshold=v.update_threshold,
        arrival=arrival,
        arrival_point=a.point,
        swing_axis_in_base=(float(swing_origin[0]), float(swing_origin[1])),
        source=str(where.file),
    )


def carrier_vessel_geometry(cfg: SensingConfig, name: str) -> VesselGeometry:
    """The vessel of the site's carrier ``name`` (:meth:`SensingConfig.vessel_geometry`)."""
    return cfg.vessel_geometry(name)
