"""Per-kind navigation config: ``config/nav/<kind>_nav.yaml`` over ``config/nav/tracked_nav.yaml``.

One stack serves every tracked machine; what differs per kind is data:

* the machine's description (``tms_model.fleet.load_named(name)``): footprint, ``tracks`` speed limits (and
  accelerations where the description gives them), the vessel of a carrier, the tf prefix of the name;
* its nav file ``config/nav/<kind>_nav.yaml`` (the IC120 has none: the default is tuned on it): the algorithm tuning. A
  kind without one uses the documented default ``config/nav/tracked_nav.yaml``; a kind's file may hold only
  what differs from the default: each of its sections is merged key by key over the default's.

The files are found and merged by :mod:`tms_model.nav_files` (the vessel controller of tms_rc reads the same
files' ``vessel`` section there); every section is read here with :mod:`tms_common.schema` (a frozen dataclass
per section: unknown keys and bad values are errors naming the file, line and key). Sections:
``localization`` (:class:`~tms_rp.tracked.ekf.EkfParams` + ``geodetic_crs``), ``costmap``
(:class:`~tms_rp.tracked.costmap.CostmapParams` + ``map``), ``planner``, ``controller``, ``goal_checker``,
``progress_checker``, ``vessel`` (carriers; read by tms_rc.carrier) and the optional per-kind ones:

* ``tracks: {max_accel, max_yaw_accel}``: the accelerations navigation needs, for a description without them
  (the excavators' descriptions give speeds only); the description's values win where it has them;
* ``footprint: {length, width}``: the navigation footprint, when it is not the undercarriage's (an
  excavator's upper body swings over its tracks);
* ``legs: {reverse}``: ``true`` (default) drives a leg in reverse when the pose's heading is opposite to the
  leg's bearing (the paper's route rule); ``false`` always drives forward and turns at the pose.

The same builders run at node start-up, in the
tests and in the benchmark, so there is one source of truth for every number.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from tms_common.errors import ConfigError
from tms_common.schema import setting
from tms_model.fleet import load_named
from tms_model.machines import Machine
from tms_model.nav_files import DEFAULT_NAV, load_nav_files, nav_path_for
from tms_rp.tracked.controller import ControllerParams, Limits
from tms_rp.tracked.costmap import Costmap, CostmapParams, Footprint, load_map
from tms_rp.tracked.ekf import EkfParams
from tms_rp.tracked.navigator import GoalChecker, NavigatorCore, ProgressChecker
from tms_rp.tracked.planner import GridPlanner, PlannerParams

__all__ = ["NavConfig", "load_nav_config", "nav_path_for", "DEFAULT_NAV", "GoalSection", "ProgressSection"]


@dataclass(frozen=True)
class LocalizationSection(EkfParams):
    """``localization``: the EKF's parameters and the CRS a NavSatFix's latitude and longitude are read in."""

    geodetic_crs: str = "EPSG:6668"


@dataclass(frozen=True)
class CostmapSection(CostmapParams):
    """``costmap``: inflation parameters and the map file (relative to the nav file's directory)."""

    map: str | None = None


@dataclass(frozen=True)
class GoalSection:
    """``goal_checker``: when a goal is reached (Nav2's goal checker tolerances)."""

    xy_goal_tolerance: float = setting(lo=1e-6, doc="[m]")
    yaw_goal_tolerance: float = setting(lo=1e-6, doc="[rad]")
    stop_distance: float = setting(0.05, lo=0.0, doc="[m] translation stops inside this distance")


@dataclass(frozen=True)
class ProgressSection:
    """``progress_checker``: a goal fails when the machine moves less than this in this time (Nav2's)."""

    required_movement: float = setting(lo=0.0, doc="[m]")
    movement_time_allowance: float = setting(lo=1e-6, doc="[s]")


@dataclass(frozen=True)
class TracksSection:
    """``tracks``: accelerations for a description that gives none (the description's win where it has them)."""

    max_accel: float | None = setting(None, lo=1e-9, doc="[m/s^2]")
    max_yaw_accel: float | None = setting(None, lo=1e-9, doc="[rad/s^2]")


@dataclass(frozen=True)
class FootprintSection:
    """``footprint``: the navigation footprint when it is not the undercarriage's [m]."""

    length: float = setting(lo=0.1)
    width: float = setting(lo=0.1)


@dataclass(frozen=True)
class LegsSection:
    """``legs``: ``reverse`` drives a leg in reverse when the pose's heading is opposite to the leg's bearing."""

    reverse: bool = True


@dataclass(frozen=True)
class NavConfig:
    """Everything the localisation and navigator nodes of one machine need."""

    file: str
    ekf: EkfParams
    geodetic_crs: str
    costmap: CostmapParams
    map_yaml: Path
    planner: PlannerParams
    controller: ControllerParams
    goal: GoalSection
    progress: ProgressSection
    limits: Limits
    footprint: Footprint
    machine: Machine  # the machine's (named) description: tracks, footprint, vessel, tf prefix
    reverse: bool = True  # legs.reverse

    def build_costmap(self, map_yaml: str | Path | None = None) -> Costmap:
        return Costmap(load_map(map_yaml or self.map_yaml), self.footprint, self.costmap)

    def build_navigator(self, costmap: Costmap | None = None) -> NavigatorCore:
        return NavigatorCore(
            costmap or self.build_costmap(), GridPlanner(self.planner), self.controller, self.limits,
            GoalChecker(self.goal.xy_goal_tolerance, self.goal.yaw_goal_tolerance),
            ProgressChecker(self.progress.required_movement, self.progress.movement_time_allowance),
            turn_in_place_radius=self.goal.xy_goal_tolerance,
            reverse=self.reverse,
        )


def _fields(cls: type, section: object) -> dict:
    """The fields of the dataclass ``cls`` taken from ``section`` (an instance of a subclass of ``cls``)."""
    return {f.name: getattr(section, f.name) for f in dataclasses.fields(cls)}


def load_nav_config(nav_yaml: str | Path | None = None, machine_yaml: str | Path | None = None,
                    map_yaml: str | Path | None = None, *, machine: str) -> NavConfig:
    """Read and validate the navigation config of the machine called ``machine`` (a name of the site).

    ``nav_yaml`` (default :func:`nav_path_for` its kind) is merged section by section over
    ``config/nav/tracked_nav.yaml`` (:func:`tms_model.nav_files.load_nav_files`); ``machine_yaml`` replaces the
    kind's description file.
    """
    description = load_named(machine, machine_yaml)  # a name resolves to its kind through the site only
    files = load_nav_files(description.kind, nav_yaml)
    for name in ("localization", "costmap", "planner", "controller", "goal_checker", "progress_checker"):
        if not files.has(name):
            raise files.own_where.error((), f"missing section {name!r}")
    tracks = description.tracks
    acc = files.section(TracksSection, "tracks")
    where_tracks = files.where("tracks")
    max_accel = tracks.max_accel if tracks.max_accel is not None else acc.max_accel
    max_yaw_accel = tracks.max_yaw_accel if tracks.max_yaw_accel is not None else acc.max_yaw_accel
    if max_accel is None or max_yaw_accel is None:
        raise where_tracks.error(("tracks",), f"tracks: {description.source} gives no accelerations: the nav file's "
                                 "tracks section must give max_accel and max_yaw_accel")
    try:
        limits = Limits(tracks.max_speed, tracks.max_yaw_rate, max_accel, max_yaw_accel)
    except ValueError as exc:
        raise ConfigError(f"{description.source}: {exc}") from None
    footprint = Footprint(description.footprint.length, description.footprint.width)
    if files.has("footprint"):
        fp = files.section(FootprintSection, "footprint")
        footprint = Footprint(fp.length, fp.width)
    reverse = files.section(LegsSection, "legs").reverse
    loc = files.section(LocalizationSection, "localization")
    costmap = files.section(CostmapSection, "costmap")
    if map_yaml is None:
        if not costmap.map:
            raise files.where("costmap").error(("costmap",), "costmap.map: missing map file")
        map_yaml = files.path.parent / costmap.map
    goal = files.section(GoalSection, "goal_checker")
    ctrl = files.section(ControllerParams, "controller")
    given = files.merged("controller")
    # the controller stops and turns to the goal heading within the goal checker's figures unless told otherwise
    ctrl = dataclasses.replace(ctrl, **{k: getattr(goal, k) for k in ("stop_distance", "yaw_goal_tolerance")
                                        if k not in given})
    return NavConfig(
        file=str(files.path),
        ekf=EkfParams(**_fields(EkfParams, loc)),
        geodetic_crs=loc.geodetic_crs,
        costmap=CostmapParams(**_fields(CostmapParams, costmap)),
        map_yaml=Path(map_yaml),
        planner=files.section(PlannerParams, "planner"),
        controller=ctrl,
        goal=goal,
        progress=files.section(ProgressSection, "progress_checker"),
        limits=limits,
        footprint=footprint,
        machine=description,
        reverse=reverse,
    )
