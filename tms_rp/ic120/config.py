"""Loads config/nav/ic120_nav.yaml + config/machines/ic120.yaml into the frozen parameter dataclasses.

Errors name the file, line and key (tms_common.config). The same builders run at node start-up, in the
tests and in the benchmark, so there is one source of truth for every number.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tms_common.config import Where, config_path, load_yaml
from tms_common.errors import ConfigError
from tms_model.machines import CRAWLER_DUMP, Machine, load_machine
from tms_rp.ic120.controller import ControllerParams, Limits
from tms_rp.ic120.costmap import Costmap, CostmapParams, Footprint, load_map
from tms_rp.ic120.ekf import EkfParams
from tms_rp.ic120.navigator import GoalChecker, NavigatorCore, ProgressChecker
from tms_rp.ic120.planner import GridPlanner, PlannerParams

__all__ = ["NavConfig", "load_nav_config"]

_SECTIONS = {"localization", "costmap", "planner", "controller", "goal_checker", "progress_checker", "vessel"}


@dataclass(frozen=True)
class NavConfig:
    """Everything the IC120 localisation/navigation/vessel nodes need."""

    file: str
    ekf: EkfParams
    geodetic_crs: str
    costmap: CostmapParams
    map_yaml: Path
    planner: PlannerParams
    controller: ControllerParams
    goal: dict
    progress: dict
    vessel: dict
    limits: Limits
    footprint: Footprint
    machine: Machine  # the IC120 description (tracks, footprint, vessel)

    def build_costmap(self, map_yaml: str | Path | None = None) -> Costmap:
        return Costmap(load_map(map_yaml or self.map_yaml), self.footprint, self.costmap)

    def build_navigator(self, costmap: Costmap | None = None) -> NavigatorCore:
        return NavigatorCore(
            costmap or self.build_costmap(), GridPlanner(self.planner), self.controller, self.limits,
            GoalChecker(float(self.goal["xy_goal_tolerance"]), float(self.goal["yaw_goal_tolerance"])),
            ProgressChecker(float(self.progress["required_movement"]), float(self.progress["movement_time_allowance"])),
            turn_in_place_radius=float(self.goal["xy_goal_tolerance"]),
        )


def _build(cls: type, section: dict, where: Where, name: str, extra_ok: set[str] = frozenset()) -> Any:
    known = set(cls.__dataclass_fields__)
    for key in section:
        if key not in known and key not in extra_ok:
            raise where.error((name, key), f"{name}: unknown key {key!r}; known: {sorted(known | extra_ok)}")
    try:
        return cls(**{k: v for k, v in section.items() if k in known})
    except (TypeError, ValueError) as exc:
        raise where.error((name,), f"{name}: {exc}") from None


def load_nav_config(nav_yaml: str | Path | None = None, machine_yaml: str | Path | None = None,
                    map_yaml: str | Path | None = None) -> NavConfig:
    """Read and validate the navigation config (defaults: config/nav/ic120_nav.yaml, config/machines/ic120.yaml)."""
    nav_path = Path(nav_yaml or config_path("nav", "ic120_nav.yaml"))
    data, where = load_yaml(nav_path)
    if not isinstance(data, dict):
        raise where.error((), "navigation config must be a mapping")
    for key in data:
        if key not in _SECTIONS:
            raise where.error((key,), f"unknown section {key!r}; known: {sorted(_SECTIONS)}")
    missing = _SECTIONS - set(data)
    if missing:
        raise where.error((), f"missing sections {sorted(missing)}")
    machine = load_machine("ic120", machine_yaml).require(CRAWLER_DUMP)
    limits = Limits.from_tracks(machine.tracks, machine.source)
    footprint = Footprint(machine.footprint.length, machine.footprint.width)
    loc = dict(data["localization"])
    costmap_sec = dict(data["costmap"])
    map_rel = costmap_sec.pop("map", None)
    if map_yaml is None:
        if not map_rel:
            raise where.error(("costmap",), "costmap.map: missing map file")
        map_yaml = nav_path.parent / str(map_rel)
    goal = dict(data["goal_checker"])
    ctrl = dict(data["controller"])
    ctrl.setdefault("stop_distance", goal.get("stop_distance", 0.05))
    ctrl.setdefault("yaw_goal_tolerance", goal.get("yaw_goal_tolerance", 0.1))
    for key in ("xy_goal_tolerance", "yaw_goal_tolerance"):
        if not isinstance(goal.get(key), (int, float)) or not goal[key] > 0:
            raise where.error(("goal_checker", key), f"goal_checker.{key} must be a positive number, got {goal.get(key)!r}")
    try:
        return NavConfig(
            file=str(nav_path),
            ekf=_build(EkfParams, loc, where, "localization", {"geodetic_crs"}),
            geodetic_crs=str(loc.get("geodetic_crs", "EPSG:6668")),
            costmap=_build(CostmapParams, costmap_sec, where, "costmap"),
            map_yaml=Path(map_yaml),
            planner=_build(PlannerParams, data["planner"], where, "planner"),
            controller=_build(ControllerParams, ctrl, where, "controller"),
            goal=goal,
            progress=dict(data["progress_checker"]),
            vessel=dict(data["vessel"]),
            limits=limits,
            footprint=footprint,
            machine=machine,
        )
    except ConfigError:
        raise
