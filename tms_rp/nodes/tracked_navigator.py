"""``tracked_navigator``: Nav2-named navigation actions of a tracked machine (thin rclpy wrapper of NavigatorCore).

Run in the machine's namespace: ``tracked_navigator --ros-args -r __ns:=/ic120_1`` (the machine is the
``machine`` parameter, else the namespace's last segment; ``ic120_navigator`` is this node under its former
name). The kind's nav file (:mod:`tms_rp.tracked.config`: footprint, limits, map, reversing
rule) configures it; every tracked machine's converter takes ``cmd_vel`` (centre speed + yaw rate: the
crawler carrier's ``Velocity_Cmd``, the excavator's ``Velocity_Cmd_2`` in centre mode). Action servers
``navigate_to_pose``, ``navigate_through_poses``, ``follow_waypoints`` (nav2_msgs, Nav2 jazzy's types and
action names under the machine namespace, as a Nav2 bt_navigator / waypoint_follower serves them); input
``odometry/global`` (from ic120_localization) and ``map`` (nav_msgs/OccupancyGrid, transient local: replaces
the static map, e.g. when an obstacle appears; the running path is checked and replanned); output
``cmd_vel`` (geometry_msgs/Twist) to com3_bridge. Parameters: ``machine`` (name on the site; default: the
namespace), ``nav_config`` (default config/nav/<kind>_nav.yaml over config/nav/tracked_nav.yaml), ``map_yaml`` (default:
the config's ``costmap.map``), ``pose_timeout_s`` (1.0),
``pose_lost_timeout_s`` (10.0). A pose older than ``pose_timeout_s`` makes the machine brake and hold (a
CPU-starved localisation or a DDS hiccup); it resumes when poses return, and the goal aborts with
"localisation lost" only when no pose came for ``pose_lost_timeout_s``.

One goal at a time; a new goal preempts the running one (as Nav2). Execution is an async execute
callback awaiting a future that the control timer completes, so everything runs on one thread. Cancel:
the machine is brought to rest (measured speed below 0.02 m/s and 0.02 rad/s, at most 5 s) before the
goal reports CANCELED. Failures abort with the error code a Nav2 navigator reports for that failure (the
planner's or controller's code, :mod:`tms_rp.tracked.errors`) and an ``error_msg`` naming the reason; a failed
``follow_waypoints`` reports ``UNKNOWN`` (600) with the missed waypoint, its index and that code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from geometry_msgs.msg import Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from nav2_msgs.msg import MissedWaypoint
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_model.fleet import machine_name
from tms_model.geometry import yaw_from_quaternion
from tms_rp.tracked import errors
from tms_rp.tracked.config import load_nav_config
from tms_rp.tracked.costmap import OccupancyMap
from tms_rp.tracked.navigator import validate_pose

__all__ = ["main", "TrackedNavigator"]

REST_V, REST_W, REST_TIMEOUT = 0.02, 0.02, 5.0
POSE_WAIT = 10.0  # [s, wall clock] a goal arriving before the first pose waits this long for one


@dataclass
class _Active:
    handle: Any
    kind: str
    future: Any
    poses: list
    started: float
    stopping_since: float | None = None
    result_code: int = 0
    result_msg: str = ""
    final: str = ""
    ticks: int = 0
    extra: dict = field(default_factory=dict)


kinds = {"navigate_to_pose": NavigateToPose, "navigate_through_poses": NavigateThroughPoses,
         "follow_waypoints": FollowWaypoints}


class TrackedNavigator(Node):
    def __init__(self, node_name: str = "tracked_navigator", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.machine = machine_name(str(declare_startup(self, "machine", "").value), self.get_namespace())
        nav_config = str(declare_startup(self, "nav_config", "").value)
        map_yaml = str(declare_startup(self, "map_yaml", "").value)
        self.pose_timeout = float(declare_startup(self, "pose_timeout_s", 1.0).value)
        self.pose_lost_timeout = max(self.pose_timeout,
                                     float(declare_startup(self, "pose_lost_timeout_s", 10.0).value))
        self.cfg = load_nav_config(nav_config or None, map_yaml=map_yaml or None, machine=self.machine)
        self.core = self.cfg.build_navigator()
        self.dt = 1.0 / self.cfg.controller.frequency
        self._log = self.get_logger()
        self._pose: tuple[float, float, float] | None = None
        self._pose_t = -math.inf
        self._vel = (0.0, 0.0)
        self._active: _Active | None = None
        self._pose_waiters: list = []
        self.pub_cmd = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(Odometry, "odometry/global", self._on_pose, 20)
        latched = QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
        )
        self.create_subscription(OccupancyGrid, "map", self._on_map, latched)
        self._servers = [
            ActionServer(self, action, name, execute_callback=self._executor_for(name),
                         goal_callback=lambda _g: GoalResponse.ACCEPT,
                         cancel_callback=lambda _h: CancelResponse.ACCEPT, result_timeout=ACTION_RESULT_TIMEOUT_S)
            for name, action in kinds.items()
        ]
        self.create_timer(self.dt, self._tick)
        self._log.info(
            f"navigator of {self.machine} ({self.cfg.machine.kind}, {self.cfg.file}) ready: map {self.cfg.map_yaml}, "
            f"{self.cfg.controller.frequency:g} Hz"
        )

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # --- inputs ------------------------------------------------------------------------------
    def _on_pose(self, msg: Odometry) -> None:
        p = msg.pose.pose
        q = p.orientation
        yaw = yaw_from_quaternion(q)
        self._pose = (p.position.x, p.position.y, yaw)
        self._pose_t = self._now()
        self._vel = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)
        for waiter in self._pose_waiters:
            if not waiter.done():
                waiter.set_result(True)
        self._pose_waiters.clear()

    def _on_map(self, msg: OccupancyGrid) -> None:
        info = msg.info
        if abs(info.origin.orientation.z) > 1e-9:
            self._log.error("map ignored: rotated map origins are not supported")
            return
        grid = np.array(msg.data, dtype=np.int8).reshape(info.height, info.width)
        omap = OccupancyMap(grid, float(info.resolution), (info.origin.position.x, info.origin.position.y))
        self.core.set_costmap(self.core.costmap.with_obstacles(omap))
        self._log.info(f"map updated: {info.width} x {info.height} cells at {info.resolution:g} m")

    # --- actions -----------------------------------------------------------------------------
    def _executor_for(self, kind: str):
        # rclpy awaits the execute callback only if it *is* a coroutine function (not a lambda returning one)
        async def execute(handle):
            return await self._execute(handle, kind)

        return execute

    async def _execute(self, handle, kind: str):  # rclpy goal handle / result
        goal = handle.request
        action = kinds[kind]
        fut = Future()
        if self._active is not None:
            self._finish(self._active, "abort", errors.PLANNER_UNKNOWN, "preempted by a new goal")
        pose_msgs = [goal.pose] if kind == "navigate_to_pose" else list(goal.poses)
        first = 0
        if kind == "follow_waypoints":
            first = int(goal.goal_index)
            pose_msgs = pose_msgs[first:]
        act = _Active(handle, kind, fut, [], self._now())
        act.extra.update(pose_msgs=pose_msgs, first=first)
        try:
            if not pose_msgs:
                raise errors.InvalidGoalError("no poses in the goal")
            poses = []
            for i, ps in enumerate(pose_msgs):
                if ps.header.frame_id not in ("", "map"):
                    raise errors.InvalidGoalError(f"pose {i}: frame {ps.header.frame_id!r} is not 'map'")
                o, pos = ps.pose.orientation, ps.pose.position
                poses.append(validate_pose(pos.x, pos.y, o.z, o.w, o.x, o.y, index=i))
            if self._pose is None or self._now() - self._pose_t > self.pose_timeout:
                if not await self._wait_pose(POSE_WAIT):
                    raise errors.LocalizationError(
                        f"no pose on odometry/global for {POSE_WAIT:g} s: is the localisation "
                        f"of {self.machine} running?"
                    )
            self.core.start(poses, yaw_at_each=kind != "navigate_through_poses")
        except errors.NavError as exc:
            self._log.warning(f"{kind}: rejected: {exc}")
            code = exc.code if kind != "follow_waypoints" else errors.WAYPOINTS_UNKNOWN
            handle.abort()
            return self._result(action, code, str(exc))
        act.poses = poses
        self._active = act
        self._log.info(f"{kind}: {len(poses)} pose(s), first ({poses[0][0]:.2f}, {poses[0][1]:.2f})")
        return await fut

    async def _wait_pose(self, seconds: float) -> bool:
        """Wait (without blocking the executor) for a fresh pose, e.g. just after start-up.

        The wait runs on the steady (wall) clock: it covers other processes starting up, and a sim-time
        timer created before the first /clock fired at once when /clock jumped ahead.
        """
        from rclpy.clock import Clock, ClockType

        waiter = Future()
        self._pose_waiters.append(waiter)
        timer = self.create_timer(seconds, lambda: waiter.done() or waiter.set_result(False),
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        ok = await waiter
        timer.cancel()
        self.destroy_timer(timer)
        return bool(ok)

    def _result(self, action, code: int, msg: str, missed: list | None = None):
        res = action.Result()
        res.error_code = int(code)
        res.error_msg = msg
        if missed:
            res.missed_waypoints = missed
        return res

    def _finish(self, act: _Active, how: str, code: int, msg: str) -> None:
        action = kinds[act.kind]
        missed = None
        if act.kind == "follow_waypoints" and how == "abort" and code != errors.NONE:
            # the waypoint follower stops at the first waypoint it cannot reach and names it, with the code the
            # navigation to it failed with
            i = min(self.core._index, len(act.extra["pose_msgs"]) - 1)
            missed = [
                MissedWaypoint(index=act.extra["first"] + i, goal=act.extra["pose_msgs"][i], error_code=int(code))
            ]
            code = errors.WAYPOINTS_UNKNOWN
        if act.handle.is_active:
            getattr(act.handle, {"succeed": "succeed", "abort": "abort", "cancel": "canceled"}[how])()
        if not act.future.done():
            act.future.set_result(self._result(action, code, msg, missed))
        if self._active is act:
            self._active = None
        self._log.info(f"{act.kind}: {how} ({code}) {msg}")

    def _publish_cmd(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = float(v), float(w)
        self.pub_cmd.publish(t)

    def _tick(self) -> None:
        act = self._active
        if act is None:
            if self.core.controller._v or self.core.controller._w:  # ramp down after a finished goal
                cmd = self.core.controller.compute(self._pose or (0.0, 0.0, 0.0), self.dt)
                self._publish_cmd(cmd.v, cmd.w)
            return
        now = self._now()
        act.ticks += 1
        if act.stopping_since is None and act.handle.is_cancel_requested:
            self.core.cancel()
            act.stopping_since = now
            act.final, act.result_code, act.result_msg = "cancel", errors.NONE, "canceled: machine at rest"
        stale = self._pose is None or now - self._pose_t > self.pose_timeout
        if act.stopping_since is None and stale and (self._pose is None or now - self._pose_t > self.pose_lost_timeout):
            self.core.cancel()
            act.stopping_since = now
            act.final, act.result_code = "abort", errors.LocalizationError.code
            act.result_msg = f"localisation lost: no odometry/global for more than {self.pose_lost_timeout:g} s"
        elif act.stopping_since is None and stale:
            if not act.extra.get("holding"):
                self._log.warning(f"no odometry/global for more than {self.pose_timeout:g} s: braking and holding")
            act.extra["holding"] = True
            cmd = self.core.controller.brake(self.dt)
            self._publish_cmd(cmd.v, cmd.w)
            return
        elif act.extra.pop("holding", False):
            self._log.info("odometry/global back: resuming")
        pose = self._pose or (0.0, 0.0, 0.0)
        step = self.core.step(pose, now, self.dt)
        self._publish_cmd(step.v, step.w)
        if act.stopping_since is not None:
            at_rest = abs(self._vel[0]) < REST_V and abs(self._vel[1]) < REST_W and step.v == 0.0 and step.w == 0.0
            if at_rest or now - act.stopping_since > REST_TIMEOUT:
                if not at_rest:
                    act.result_msg += f" (not at rest after {REST_TIMEOUT:g} s)"
                self._finish(act, act.final, act.result_code, act.result_msg)
            return
        if step.status == "SUCCEEDED":
            act.stopping_since = now
            act.final, act.result_code, act.result_msg = "succeed", 0, "goal reached"
            return
        if step.status == "FAILED":
            act.stopping_since = now
            act.final, act.result_code = "abort", step.error.code if step.error else errors.PLANNER_UNKNOWN
            act.result_msg = str(step.error)
            return
        if act.ticks % 4 == 0:
            self._feedback(act, step, pose, now)

    def _feedback(self, act: _Active, step, pose, now: float) -> None:
        fb = kinds[act.kind].Feedback()
        if act.kind == "follow_waypoints":
            fb.current_waypoint = int(step.current_index)
        else:
            fb.current_pose.header.frame_id = "map"
            fb.current_pose.header.stamp = self.get_clock().now().to_msg()
            fb.current_pose.pose.position.x, fb.current_pose.pose.position.y = pose[0], pose[1]
            fb.current_pose.pose.orientation.z = math.sin(pose[2] / 2)
            fb.current_pose.pose.orientation.w = math.cos(pose[2] / 2)
            elapsed = max(0.0, now - act.started)
            fb.navigation_time.sec = int(elapsed)
            fb.navigation_time.nanosec = int((elapsed % 1.0) * 1e9)
            fb.number_of_recoveries = int(self.core.replans)
            if act.kind == "navigate_through_poses":
                fb.number_of_poses_remaining = int(len(act.poses) - step.current_index)
            # Nav2's FollowWaypoints feedback carries only the waypoint index
            fb.distance_remaining = float(step.distance_remaining)
        act.handle.publish_feedback(fb)


def main() -> int:
    return run_node(TrackedNavigator)
