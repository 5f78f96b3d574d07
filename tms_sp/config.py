"""Sensing configuration: config/tms_sp/sensing.yaml + the site and machine descriptions (tms_model).

:func:`load_sensing_config` returns a frozen :class:`SensingConfig`; any missing or wrong key raises
``ConfigError`` with ``file:line: key: problem``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tms_common.config import Where, config_path, load_yaml
from tms_common.errors import ConfigError
from tms_model.geometry import Pose2D
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR, load_machine
from tms_model.site import Mound, load_site
from tms_sp.arrival import ArrivalParams
from tms_sp.heightgrid import GridSpec
from tms_sp.mound import ExcavationParams
from tms_sp.vessel import VesselGeometry, VesselParams

__all__ = ["SensingConfig", "load_sensing_config", "carrier_vessel_geometry"]


@dataclass(frozen=True)
class SensingConfig:
    """Everything the sensing processors and node need."""

    blackboard_records: tuple[str, ...]  # global-blackboard records the SENSING_* flags go to (the first is read too)
    resolution: float
    points: dict[str, Pose2D]
    mound: Mound
    mound_grid: GridSpec
    excavation: ExcavationParams
    excavation_model: str
    excavation_record: str
    approach_record: str
    approach_height: float
    excavation_update_threshold: float
    vessel_geom: VesselGeometry
    vessel: VesselParams
    vessel_model: str
    release_record: str
    angle_record: str
    vessel_update_threshold: float
    arrival: ArrivalParams
    arrival_point: str
    swing_axis_in_base: tuple[float, float]

    @property
    def zx200_base(self) -> Pose2D:
        return self.points["zx200_base"]

    def swing_axis_map(self) -> tuple[float, float]:
        p = self.zx200_base.to_map([self.swing_axis_in_base[0], self.swing_axis_in_base[1], 0.0])
        return float(p[0]), float(p[1])


def _get(data: Any, where: Where, path: tuple[Any, ...], kind: type | tuple[type, ...] = (int, float)) -> Any:
    node = data
    for i, key in enumerate(path):
        if not isinstance(node, dict) or key not in node:
            raise where.error(path[:i], f"{'.'.join(map(str, path))}: missing key {key!r}")
        node = node[key]
    if kind in ((int, float), float) and isinstance(node, bool):
        raise where.error(path, f"{'.'.join(map(str, path))}: expected a number, got {node!r}")
    if not isinstance(node, kind):
        names = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
        raise where.error(path, f"{'.'.join(map(str, path))}: expected {names}, got {node!r}")
    return node


def _records(data: Any, where: Where) -> tuple[str, ...]:
    """``blackboard_records``: a non-empty list of distinct record names."""
    names = _get(data, where, ("blackboard_records",), list)
    if not names or not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
        raise where.error(("blackboard_records",),
                          f"blackboard_records: expected a non-empty list of distinct record names, got {names!r}")
    return tuple(names)


def load_sensing_config(
    sensing: str | Path | None = None,
    site: str | Path | None = None,
    ic120: str | Path | None = None,
    zx200: str | Path | None = None,
) -> SensingConfig:
    """Load and validate the sensing configuration (defaults: the project's config/ files)."""
    s, sw = load_yaml(sensing or config_path("tms_sp", "sensing.yaml"))
    the_site = load_site(site)
    ic = load_machine("ic120", ic120).require(CRAWLER_DUMP)
    zx = load_machine("zx200", zx200).require(EXCAVATOR)
    assert ic.vessel is not None and zx.bucket is not None

    points = dict(the_site.points)
    for needed in ("zx200_base", "P1", "P2", "P3", "P4", "P5"):
        if needed not in points:
            raise ConfigError(f"{the_site.source}: points: missing pose {needed!r} (x, y, yaw)")
    mound = the_site.mound

    res = float(_get(s, sw, ("grid_resolution",)))
    if res <= 0:
        raise sw.error(("grid_resolution",), f"grid_resolution: must be > 0, got {res}")
    e = ("excavation",)
    margin = float(_get(s, sw, e + ("roi_margin",)))
    half = mound.base_radius + margin
    grid = GridSpec(mound.cx - half, mound.cy - half, mound.cx + half, mound.cy + half, res)

    def ex(key: str) -> float:
        return float(_get(s, sw, e + (key,)))

    try:
        excavation = ExcavationParams(
            reach_min=ex("reach_min"),
            reach_max=ex("reach_max"),
            bucket_radius=ex("bucket_radius"),
            penetration_depth=ex("penetration_depth"),
            max_penetration_depth=ex("max_penetration_depth"),
            bucket_volume=zx.bucket.capacity,
            depth_steps=int(ex("depth_steps")),
            drag_length=ex("drag_length"),
            attack_angle=math.radians(ex("attack_angle_deg")),
            theta_w_min=math.radians(ex("theta_w_min_deg")),
            theta_w_max=math.radians(ex("theta_w_max_deg")),
            distance_penalty=ex("distance_penalty"),
            min_height=ex("min_height"),
            min_volume=ex("min_volume"),
            ground_z=mound.ground_z,
            target_hysteresis=ex("target_hysteresis"),
            depleted_hysteresis=ex("depleted_hysteresis"),
            min_cut=ex("min_cut"),
        )
    except ValueError as exc:
        raise sw.error(e, str(exc)) from None

    if ex("approach_height") < 0:
        raise sw.error(e + ("approach_height",), f"approach_height: must be >= 0, got {ex('approach_height')}")
    v = ("vessel",)
    geom = VesselGeometry(
        inner_length=ic.vessel.inner_length,
        inner_width=ic.vessel.inner_width,
        capacity=ic.vessel.capacity,
        hinge_xyz=ic.vessel.hinge_xyz,
        floor_above_hinge=float(_get(s, sw, v + ("floor_above_hinge",))),
        rim_above_hinge=float(_get(s, sw, v + ("rim_above_hinge",))),
    )
    try:
        vparams = VesselParams(
            wall_margin=float(_get(s, sw, v + ("wall_margin",))),
            clearance=float(_get(s, sw, v + ("clearance",))),
            carry_theta_w=math.radians(float(_get(s, sw, v + ("carry_theta_w_deg",)))),
            target_fill=float(_get(s, sw, v + ("target_fill",))),
            release_hysteresis=float(_get(s, sw, v + ("release_hysteresis",))),
            loaded_hysteresis=float(_get(s, sw, v + ("loaded_hysteresis",))),
        )
    except ValueError as exc:
        raise sw.error(v, str(exc)) from None

    a = ("arrival",)
    point = _get(s, sw, a + ("point",), str)
    if point not in points:
        raise sw.error(a + ("point",), f"arrival.point: {point!r} is not a pose in site.yaml points ({sorted(points)})")
    try:
        arrival = ArrivalParams(
            position_tolerance=float(_get(s, sw, a + ("position_tolerance",))),
            yaw_tolerance=math.radians(float(_get(s, sw, a + ("yaw_tolerance_deg",)))),
            max_speed=float(_get(s, sw, a + ("max_speed",))),
            hold_s=float(_get(s, sw, a + ("hold_s",))),
            speed_window_s=float(_get(s, sw, a + ("speed_window_s",))),
        )
    except ValueError as exc:
        raise sw.error(a, str(exc)) from None

    swing_origin = zx.joints[0].origin_xyz
    return SensingConfig(
        blackboard_records=_records(s, sw),
        resolution=res,
        points=points,
        mound=mound,
        mound_grid=grid,
        excavation=excavation,
        excavation_model=_get(s, sw, e + ("model_name",), str),
        excavation_record=_get(s, sw, e + ("record",), str),
        excavation_update_threshold=ex("update_threshold"),
        approach_record=_get(s, sw, e + ("approach_record",), str),  # "" = none (the original's trees have none)
        approach_height=ex("approach_height"),
        vessel_geom=geom,
        vessel=vparams,
        vessel_model=_get(s, sw, v + ("model_name",), str),
        release_record=_get(s, sw, v + ("release_record",), str),
        angle_record=_get(s, sw, v + ("angle_record",), str),
        vessel_update_threshold=float(_get(s, sw, v + ("update_threshold",))),
        arrival=arrival,
        arrival_point=point,
        swing_axis_in_base=(float(swing_origin[0]), float(swing_origin[1])),
    )


def carrier_vessel_geometry(cfg: SensingConfig, name: str) -> VesselGeometry:
    """The vessel of the site's machine ``name`` (config/site.yaml ``machines``; its kind's description): inner
    size, capacity and hinge from the description, floor and rim heights above the hinge from sensing.yaml (the
    IC120 mesh's figures: no other kind publishes them)."""
    import dataclasses

    from tms_model.fleet import load_named

    m = load_named(name).require(CRAWLER_DUMP)
    assert m.vessel is not None
    return dataclasses.replace(cfg.vessel_geom, inner_length=m.vessel.inner_length, inner_width=m.vessel.inner_width,
                               capacity=m.vessel.capacity, hinge_xyz=m.vessel.hinge_xyz)
