"""Nav2 navigate_to_pose / navigate_through_poses / follow_waypoints semantics as a pure step function.

:class:`NavigatorCore` owns the costmap, the planner, the controller, the goal checker and a progress
checker. The node feeds it the fused pose every control period and publishes the returned velocity; all
decisions (leg direction, replanning, failure reasons) are made here so they are unit-testable.

Legs: the machine drives from where it is to each pose in turn. A pose at the machine's position (closer
than ``turn_in_place_radius``) is a *turn in place* to its heading. Otherwise the leg is driven in
reverse when the pose's heading is opposite (> 90 deg) to the bearing from the leg start to the pose, else
forward (the rule of config/site.yaml's route); a kind whose nav config says ``legs: {reverse: false}``
drives every leg forward. Intermediate poses of navigate_through_poses are reached
in position only; the last pose (and every pose of navigate_to_pose / follow_waypoints) also in heading.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from tms_model.geometry import wrap_angle, yaw_from_quaternion
from tms_rp.tracked.controller import ControllerParams, Limits, TrackedPurePursuit
from tms_rp.tracked.costmap import Costmap
from tms_rp.tracked.errors import (
    GoalOccupiedError,
    GoalOutsideMapError,
    InvalidGoalError,
    NavError,
    NavTimeoutError,
    NoValidPathError,
)
from tms_rp.tracked.planner import GridPlanner

__all__ = ["GoalChecker", "ProgressChecker", "NavigatorCore", "NavStep", "validate_pose", "leg_direction"]

LOGGER = logging.getLogger(__name__)


@dataclass
class GoalChecker:
    """Nav2 SimpleGoalChecker: position within ``xy_goal_tolerance``, heading within ``yaw_goal_tolerance``.

    Stateful like Nav2's default: once the position was inside the tolerance only the heading is checked.
    """

    xy_goal_tolerance: float = 0.2
    yaw_goal_tolerance: float = 0.1
    stateful: bool = True
    _xy_reached: bool = False

    def reset(self) -> None:
        self._xy_reached = False

    def is_reached(
        self, pose: tuple[float, float, float], goal: tuple[float, float, float], *, check_yaw: bool = True
    ) -> bool:
        if not self._xy_reached or not self.stateful:
            if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) > self.xy_goal_tolerance:
                return False
            self._xy_reached = True
        return not check_yaw or abs(wrap_angle(goal[2] - pose[2])) <= self.yaw_goal_tolerance


@dataclass
class ProgressChecker:
    """Nav2 SimpleProgressChecker: at least ``required_movement`` (m, or rad of turning) per
    ``movement_time_allowance`` s."""

    required_movement: float = 0.2
    movement_time_allowance: float = 20.0
    _ref: tuple[float, float, float] | None = None
    _t: float = 0.0

    def reset(self) -> None:
        self._ref = None

    def check(self, pose: tuple[float, float, float], now: float) -> bool:
        if self._ref is None:
            self._ref, self._t = pose, now
            return True
        moved = math.hypot(pose[0] - self._ref[0], pose[1] - self._ref[1])
        turned = abs(wrap_angle(pose[2] - self._ref[2]))
        if moved >= self.required_movement or turned >= self.required_movement:
            self._ref, self._t = pose, now
            return True
        return now - self._t <= self.movement_time_allowance


def validate_pose(
    x: float, y: float, qz: float, qw: float, qx: float = 0.0, qy: float = 0.0, *, index: int = 0
) -> tuple[float, float, float]:
    """A goal pose as (x, y, yaw); NaN/inf or a zero / non-unit quaternion raise :class:`InvalidGoalError`."""
    values = {
        "position.x": x,
        "position.y": y,
        "orientation.x": qx,
        "orientation.y": qy,
        "orientation.z": qz,
        "orientation.w": qw,
    }
    for name, v in values.items():
        if not math.isfinite(v):
            raise InvalidGoalError(f"pose {index}: {name} is not finite ({v})")
    norm = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    if norm < 1e-6:
        raise InvalidGoalError(f"pose {index}: orientation is a zero quaternion")
    if abs(norm - 1.0) > 0.01:
        raise InvalidGoalError(f"pose {index}: orientation quaternion is not normalised (norm {norm:.4f})")
    qx, qy, qz, qw = (q / norm for q in (qx, qy, qz, qw))
    yaw = yaw_from_quaternion((qx, qy, qz, qw))
    return float(x), float(y), yaw


def leg_direction(start: tuple[float, float, float], goal: tuple[float, float, float]) -> int:
    """1 = forward, -1 = reverse: reverse when the goal heading is opposite (> 90 deg) to the leg bearing."""
    bearing = math.atan2(goal[1] - start[1], goal[0] - start[0])
    return -1 if abs(wrap_angle(goal[2] - bearing)) > math.pi / 2 else 1


@dataclass
class NavStep:
    """Result of one step: command, status (RUNNING/SUCCEEDED/FAILED), feedback and failure."""

    v: float
    w: float
    status: str
    current_index: int
    distance_remaining: float
    error: NavError | None = None
    info: dict = field(default_factory=dict)


class NavigatorCore:
    """Runs one navigation goal at a time: ``start(poses)`` then ``step(pose, now)`` until not RUNNING."""

    def __init__(self, costmap: Costmap, planner: GridPlanner, controller_params: ControllerParams, limits: Limits,
                 goal_checker: GoalChecker, progress_checker: ProgressChecker, *, turn_in_place_radius: float = 0.3,
                 reverse: bool = True) -> None:
        self.costmap = costmap
        self.planner = planner
        self.controller = TrackedPurePursuit(controller_params, limits)
        self.goal_checker = goal_checker
        self.progress = progress_checker
        self.turn_in_place_radius = turn_in_place_radius
        #: the kind's ``legs.reverse``: False drives every leg forward (and turns at the pose)
        self.reverse = reverse
        self._poses: list[tuple[float, float, float]] = []
        self._yaw_each = False
        self._index = 0
        self._leg_started = False
        self.path = np.zeros((0, 2))
        self.replans = 0
        self.max_retries = 3
        self._retries = 0
        self._map_changed = False
        self.active = False

    # --- goals ---------------------------------------------------------------------------------
    def check_goal(self, pose: tuple[float, float, float], index: int = 0) -> None:
        """Reject a pose outside the map, in an obstacle, or whose footprint would overlap one."""
        x, y, yaw = pose
        cm = self.costmap
        if cm.map.world_to_cell(x, y) is None:
            ox, oy = cm.map.origin
            sx, sy = cm.map.size_m
            raise GoalOutsideMapError(
                f"pose {index} ({x:.2f}, {y:.2f}) is outside the map [{ox:.1f}, {ox + sx:.1f}] x [{oy:.1f}, "
                f"{oy + sy:.1f}]"
            )
        if cm.obstacles[cm.map.world_to_cell(x, y)]:
            raise GoalOccupiedError(f"pose {index} ({x:.2f}, {y:.2f}) lies inside an obstacle")
        if bool(cm.footprint_hits(x, y, yaw)[0]):
            raise GoalOccupiedError(
                f"pose {index} ({x:.2f}, {y:.2f}, yaw {yaw:.2f}): the machine footprint would overlap an obstacle"
            )
        if cm.blocked[cm.map.world_to_cell(x, y)]:
            raise GoalOccupiedError(
                f"pose {index} ({x:.2f}, {y:.2f}) lies within the inflated footprint of an obstacle (cost "
                f"{cm.cost_at(x, y)})"
            )

    def start(self, poses: list[tuple[float, float, float]], *, yaw_at_each: bool) -> None:
        """Accept a goal: validates every pose first (nothing moves if one is bad)."""
        if not poses:
            raise InvalidGoalError("no poses given")
        for i, p in enumerate(poses):
            self.check_goal(p, i)
        self._poses = list(poses)
        self._yaw_each = yaw_at_each
        self._index = 0
        self._leg_started = False
        self._retries = 0
        self.replans = 0
        self.progress.reset()
        self.active = True

    def cancel(self) -> None:
        """Stop following; subsequent steps command zero velocity (ramped by the acceleration limits)."""
        self.active = False
        self.controller.stop()

    def set_costmap(self, costmap: Costmap) -> None:
        """A new map (e.g. an obstacle appeared); the running leg is checked and replanned on the next step."""
        self.costmap = costmap
        self._map_changed = True

    # --- stepping ------------------------------------------------------------------------------
    def _start_leg(self, pose: tuple[float, float, float]) -> None:
        goal = self._poses[self._index]
        last = self._index == len(self._poses) - 1
        check_yaw = self._yaw_each or last
        self.goal_checker.reset()
        if math.hypot(goal[0] - pose[0], goal[1] - pose[1]) < self.turn_in_place_radius:
            self.path = np.array([[pose[0], pose[1]]])
            self.controller.set_path(self.path, 1, goal[2])
        else:
            direction = leg_direction(pose, goal) if self.reverse else 1
            if check_yaw:
                self.path = self.planner.plan_with_approach(self.costmap, (pose[0], pose[1]), goal, direction)
            else:
                self.path = self.planner.plan(self.costmap, (pose[0], pose[1]), (goal[0], goal[1]))
            self.controller.set_path(self.path, direction, goal[2] if check_yaw else None)
        self._leg_started = True
        self._map_changed = False

    def _path_blocked(self) -> tuple[float, float] | None:
        if self.path.shape[0] < 2:
            return None
        ahead = self.path[self.controller._idx:]
        cols = np.floor((ahead[:, 0] - self.costmap.map.origin[0]) / self.costmap.resolution).astype(int)
        rows = np.floor((ahead[:, 1] - self.costmap.map.origin[1]) / self.costmap.resolution).astype(int)
        h, w = self.costmap.blocked.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        hit = np.zeros(len(ahead), dtype=bool)
        hit[ok] = self.costmap.blocked[rows[ok], cols[ok]]
        hit[:3] = False  # the machine's own cell
        if hit.any():
            i = int(np.argmax(hit))
            return float(ahead[i, 0]), float(ahead[i, 1])
        return None

    def step(self, pose: tuple[float, float, float], now: float, dt: float) -> NavStep:
        """One control period: returns the velocity command and the goal status."""
        if not self.active:
            cmd = self.controller.compute(pose, dt)
            return NavStep(cmd.v, cmd.w, "IDLE", self._index, 0.0)
        try:
            if not self._leg_started:
                self._start_leg(pose)
            elif getattr(self, "_map_changed", False):
                self._map_changed = False
                blocked_at = self._path_blocked()
                if blocked_at is not None:
                    self.replans += 1
                    goal = self._poses[self._index]
                    try:
                        new_path = self.planner.plan(self.costmap, (pose[0], pose[1]), (goal[0], goal[1]))
                    except NavError as exc:
                        raise NoValidPathError(
                            f"path blocked at ({blocked_at[0]:.2f}, {blocked_at[1]:.2f}) and replanning failed: {exc}"
                        ) from exc
                    self.path = new_path
                    self.controller.replace_path(new_path)
                    LOGGER.info("path blocked at (%.2f, %.2f): replanned", *blocked_at)
            if not self.progress.check(pose, now):
                raise NavTimeoutError(
                    f"no progress: moved less than {self.progress.required_movement} m in "
                    f"{self.progress.movement_time_allowance} s"
                )
            cmd = self.controller.compute(pose, dt)
            goal = self._poses[self._index]
            last = self._index == len(self._poses) - 1
            remaining = cmd.distance_remaining + sum(
                math.hypot(b[0] - a[0], b[1] - a[1])
                for a, b in zip(self._poses[self._index :], self._poses[self._index + 1 :], strict=False)
            )
            if cmd.done:
                reached = self.goal_checker.is_reached(pose, goal, check_yaw=self._yaw_each or last)
                if not reached:
                    # drifted out of tolerance while stopping: drive the leg again from here
                    self._retries += 1
                    if self._retries > self.max_retries:
                        err = math.hypot(goal[0] - pose[0], goal[1] - pose[1])
                        raise NavTimeoutError(
                            f"pose {self._index} not reached within tolerance after {self.max_retries} retries (error "
                            f"{err:.3f} m)"
                        )
                    LOGGER.info("leg %d ended outside tolerance: retrying", self._index)
                    self._start_leg(pose)
                    return NavStep(cmd.v, cmd.w, "RUNNING", self._index, remaining)
                if last:
                    self.active = False
                    return NavStep(cmd.v, cmd.w, "SUCCEEDED", self._index, 0.0)
                self._index += 1
                self._retries = 0
                self._leg_started = False
                self.progress.reset()
            return NavStep(cmd.v, cmd.w, "RUNNING", self._index, remaining, info={"state": cmd.state})
        except NavError as exc:
            self.active = False
            self.controller.stop()
            stop = self.controller.compute(pose, dt)
            return NavStep(stop.v, stop.w, "FAILED", self._index, 0.0, error=exc)
