"""Per-kind navigation config: ``config/nav/<kind>_nav.yaml`` over ``config/nav/tracked_nav.yaml``.

One stack serves every tracked machine; what differs per kind is data:

* the machine's description (``tms_model.fleet.load_named(name)``): footprint, ``tracks`` speed limits (and
  accelerations where the description gives them), the vessel of a carrier, the tf prefix of the name;
* its nav file ``config/nav/<kind>_nav.yaml`` (the IC120's is ``ic120_nav.yaml``): the algorithm tuning. A
  kind without one uses the documented default ``config/nav/tracked_nav.yaml``; a kind's file may hold only
  what differs from the default: each of its sections is merged key by key over the default's.

Sections (unknown ones and unknown keys are errors naming the file and line): ``localization``, ``costmap``,
``planner``, ``controller``, ``goal_checker``, ``progress_checker``, ``vessel`` (carriers; tms_rc.carrier) and
the optional per-kind ones:

* ``tracks: {max_accel, max_yaw_accel}``: the accelerations navigation needs, for a description without them
  (the excavators' descriptions give speeds only); the description's values win where it has them;
* ``footprint: {length, width}``: the navigation footprint, when it is not the undercarriage's (an
  excavator's upper body swings over its tracks);
* ``legs: {reverse}``: ``true`` (default) drives a leg in reverse when the pose's heading is opposite to the
  leg's bearing (the paper's route rule); ``false`` always drives forward and turns at the pose.

Errors name the file, line and key (tms_common.config). The same builders run at node start-up, in the
tests and in the benchmark, so there is one source of truth for every number.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tms_common.config import Where, config_path, load_yaml
from tms_common.errors import ConfigError
from tms_model.machines import Machine, load_machine
from tms_rp.tracked.controller import ControllerParams, Limits
from tms_rp.tracked.costmap import Costmap, CostmapParams, Footprint, load_map
from tms_rp.tracked.ekf import EkfParams
from tms_rp.tracked.navigator import GoalChecker, NavigatorCore, ProgressChecker
from tms_rp.tracked.planner import GridPlanner, PlannerParams

__all__ = ["NavConfig", "load_nav_config", "nav_path_for", "DEFAULT_NAV"]

#: the default nav file of a kind without ``config/nav/<kind>_nav.yaml``
DEFAULT_NAV = "tracked_nav.yaml"
_SECTIONS = {"localization", "costmap", "planner", "controller", "goal_checker", "progress_checker", "vessel"}
_OPTIONAL = {"tracks", "footprint", "legs"}


@dataclass(frozen=True)
class NavConfig:
    """Everything the localisation, navigator and vessel nodes of one machine need."""

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
    machine: Machine  # the machine's (named) description: tracks, footprint, vessel, tf prefix
    reverse: bool = True  # legs.reverse

    def build_costmap(self, map_yaml: str | Path | None = None) -> Costmap:
        return Costmap(load_map(map_yaml or self.map_yaml), self.footprint, self.costmap)

    def build_navigator(self, costmap: Costmap | None = None) -> NavigatorCore:
        return NavigatorCore(
            costmap or self.build_costmap(), GridPlanner(self.planner), self.controller, self.limits,
            GoalChecker(float(self.goal["xy_goal_tolerance"]), float(self.goal["yaw_goal_tolerance"])),
            ProgressChecker(float(self.progress["required_movement"]), float(self.progress["movement_time_allowance"])),
            turn_in_place_radius=float(self.goal["xy_goal_tolerance"]),
            reverse=self.reverse,
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


def nav_path_for(kind: str) -> Path:
    """``config/nav/<kind>_nav.yaml`` when it exists, else the default ``config/nav/tracked_nav.yaml``."""
    own = config_path("nav", f"{kind}_nav.yaml")
    return Path(own) if Path(own).is_file() else Path(config_path("nav", DEFAULT_NAV))


def _read(path: Path) -> tuple[dict, Where]:
    data, where = load_yaml(path)
    if not isinstance(data, dict):
        raise where.error((), "navigation config must be a mapping")
    for key in data:
        if key not in _SECTIONS | _OPTIONAL:
            raise where.error((key,), f"unknown section {key!r}; known: {sorted(_SECTIONS | _OPTIONAL)}")
        if not isinstance(data[key], dict):
            raise where.error((key,), f"section {key!r} must be a mapping")
    return data, where


def _number(section: dict, where: Where, name: str, key: str) -> float:
    value = section.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise where.error((name, key), f"{name}.{key} must be a positive number, got {value!r}")
    return float(value)


def load_nav_config(nav_yaml: str | Path | None = None, machine_yaml: str | Path | None = None,
                    map_yaml: str | Path | None = None, *, machine: str = "ic120") -> NavConfig:
    """Read and validate the navigation config of the machine called ``machine`` (a name of the site).

    ``nav_yaml`` (default :func:`nav_path_for` its kind) is merged section by section over
    ``config/nav/tracked_nav.yaml``; ``machine_yaml`` replaces the kind's description file.
    """
    from tms_model.fleet import load_named

    try:
        description = load_named(machine, machine_yaml)
    except ConfigError:
        if machine_yaml is None and not Path(config_path("machines", f"{machine}.yaml")).is_file():
            raise
        description = load_machine(machine, machine_yaml)  # a kind's name, not on the site
    nav_path = Path(nav_yaml) if nav_yaml else nav_path_for(description.kind)
    default_path = Path(config_path("nav", DEFAULT_NAV))
    data, where = _read(nav_path)
    wheres = dict.fromkeys(data, where)
    if nav_path.resolve() != default_path.resolve():
        base, base_where = _read(default_path)
        for key, section in base.items():
            if key in data:
                data[key] = {**section, **data[key]}
            else:
                data[key], wheres[key] = dict(section), base_where
    missing = _SECTIONS - set(data)
    if missing:
        raise where.error((), f"missing sections {sorted(missing)}")
    tracks = description.tracks
    acc = data.get("tracks", {})
    for key in acc:
        if key not in ("max_accel", "max_yaw_accel"):
            raise wheres["tracks"].error(("tracks", key), f"tracks: unknown key {key!r}; known: ['max_accel', 'max_yaw_accel']")
    try:
        limits = Limits(tracks.max_speed, tracks.max_yaw_rate,
                        tracks.max_accel if tracks.max_accel is not None else _number(acc, wheres.get("tracks", where), "tracks", "max_accel"),
                        tracks.max_yaw_accel if tracks.max_yaw_accel is not None
                        else _number(acc, wheres.get("tracks", where), "tracks", "max_yaw_accel"))
    except ValueError as exc:
        raise ConfigError(f"{description.source}: {exc}") from None
    footprint = Footprint(description.footprint.length, description.footprint.width)
    if "footprint" in data:
        fp = data["footprint"]
        for key in fp:
            if key not in ("length", "width"):
                raise wheres["footprint"].error(("footprint", key), f"footprint: unknown key {key!r}; known: ['length', 'width']")
        footprint = Footprint(_number(fp, wheres["footprint"], "footprint", "length"),
                              _number(fp, wheres["footprint"], "footprint", "width"))
    reverse = True
    if "legs" in data:
        for key, value in data["legs"].items():
            if key != "reverse":
                raise wheres["legs"].error(("legs", key), f"legs: unknown key {key!r}; known: ['reverse']")
            if not isinstance(value, bool):
                raise wheres["legs"].error(("legs", key), f"legs.reverse must be true or false, got {value!r}")
            reverse = value
    loc = dict(data["localization"])
    costmap_sec = dict(data["costmap"])
    map_rel = costmap_sec.pop("map", None)
    if map_yaml is None:
        if not map_rel:
            raise wheres["costmap"].error(("costmap",), "costmap.map: missing map file")
        map_yaml = nav_path.parent / str(map_rel)
    goal = dict(data["goal_checker"])
    ctrl = dict(data["controller"])
    ctrl.setdefault("stop_distance", goal.get("stop_distance", 0.05))
    ctrl.setdefault("yaw_goal_tolerance", goal.get("yaw_goal_tolerance", 0.1))
    for key in ("xy_goal_tolerance", "yaw_goal_tolerance"):
        if not isinstance(goal.get(key), (int, float)) or not goal[key] > 0:
            raise wheres["goal_checker"].error(("goal_checker", key),
                                               f"goal_checker.{key} must be a positive number, got {goal.get(key)!r}")
    return NavConfig(
        file=str(nav_path),
        ekf=_build(EkfParams, loc, wheres["localization"], "localization", {"geodetic_crs"}),
        geodetic_crs=str(loc.get("geodetic_crs", "EPSG:6668")),
        costmap=_build(CostmapParams, costmap_sec, wheres["costmap"], "costmap"),
        map_yaml=Path(map_yaml),
        planner=_build(PlannerParams, data["planner"], wheres["planner"], "planner"),
        controller=_build(ControllerParams, ctrl, wheres["controller"], "controller"),
        goal=goal,
        progress=dict(data["progress_checker"]),
        vessel=dict(data["vessel"]),
        limits=limits,
        footprint=footprint,
        machine=description,
        reverse=reverse,
    )
