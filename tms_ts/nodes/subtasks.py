"""``tms_ts_subtasks``: the subtask action servers of one machine (contract E).

For ``machine`` zx200 or ic120 it serves every subtask of :mod:`tms_ts.subtask_specs` at
``/<model_name>/<subtask_name>`` (tms_msg/action/Subtask). On a goal it reads the DB record
(model_name, record_name) *at that moment*; a missing or malformed record is rejected and the reason
(record and field) is logged and published on ``/tms_ts/subtask_rejections``. An accepted goal is
sent to the planning action ``/<model_name>/<planning>`` (contract D), its feedback mirrored as
``state``, its result mirrored as success/message. A cancel is forwarded to planning, which brings
the machine to rest; the subtask reports CANCELED only after planning confirmed. If planning does not
confirm within ``stop_timeout_s`` the node latches ``/<model_name>/emg_stop`` and aborts the goal.
Heartbeat: a thread publishes the model name on ``/tms_ts/subtask_heartbeat`` (std_msgs/String) every
0.2 s of wall time, so the manager notices a dead server process (SIGKILL) in a second instead of
waiting for DDS discovery to drop it (~20 s with the default lease).
If the planning server disappears while a goal runs (its process died) for ``server_lost_s``, the
node latches ``/<model_name>/emg_stop`` (nothing may keep driving the machine blind) and aborts the
goal naming the lost server.
ZX200 change_pose / excavate_simple set the record's ``LOCK_FLG`` false when a result arrives (so
sensing may update the excavation target again), as the original subtasks did.

Parameters: ``machine`` (required), ``model_name`` (default = machine), ``planning_wait_s`` (5.0),
``stop_timeout_s`` (5.0), ``server_lost_s`` (3.0), ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import json
import threading
import time

from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Point, Pose, PoseStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from tms_common.action_client import RaceFreeActionClient
from tms_common.goals import RunningGoals
from tms_msg.action import (
    FollowWaypoints,
    NavigateThroughPoses,
    NavigateToPose,
    SetDumpAngle,
    Subtask,
    Zx200ChangePose,
    Zx200ExcavateSimple,
    Zx200ReleaseSimple,
)
from tms_msg.msg import ErrorCodes, Zx200PositionWithAngle
from tms_ts.errors import SubtaskRecordError
from tms_ts.nodes.ros_port import HEARTBEAT_PERIOD_S, HEARTBEAT_TOPIC, REJECTIONS_TOPIC
from tms_ts.subtask_specs import SubtaskSpec, subtasks_for

__all__ = ["SubtaskServers", "main", "planning_goal", "planning_ok"]

def _pose(p: dict) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = p["x"], p["y"], p["z"]
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = p["qx"], p["qy"], p["qz"], p["qw"]
    return pose


def _stamped(p: dict) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = "map"
    msg.pose = _pose(p)
    return msg


def _pwa(d: dict) -> Zx200PositionWithAngle:
    return Zx200PositionWithAngle(position=Point(x=d["x"], y=d["y"], z=d["z"]), theta_w=d["theta_w"],
                                  offset=d.get("offset", 0.0))


def planning_goal(plan: dict):  # noqa: ANN201 - one of the planning goal types
    """Plain goal data from :mod:`tms_ts.subtask_specs` -> the planning action's goal message."""
    kind = plan["kind"]
    if kind == "change_pose":
        goal = Zx200ChangePose.Goal()
        if plan["mode"] == "joints":
            goal.trajectory = JointTrajectory(joint_names=list(plan["joints"]))
            goal.trajectory.points = [JointTrajectoryPoint(positions=list(plan["joints"].values()))]
        elif plan["mode"] == "pose":
            goal.pose_sequence = [_pose(plan["pose"])]
        else:
            goal.position_with_angle_sequence = [_pwa(plan["pwa"])]
        goal.pass_through = bool(plan.get("pass_through", False))
        goal.theta_w_tolerance = float(plan.get("theta_w_tolerance", 0.0))
        return goal
    if kind == "excavate":
        return Zx200ExcavateSimple.Goal(position_with_angle=_pwa(plan["pwa"]))
    if kind == "release":
        return Zx200ReleaseSimple.Goal(target_angle=plan["target_angle"])
    if kind == "dump":
        return SetDumpAngle.Goal(target_angle=plan["target_angle"])
    if kind == "navigate_to_pose":
        return NavigateToPose.Goal(pose=_stamped(plan["pose"]))
    if kind == "follow_waypoints":
        return FollowWaypoints.Goal(poses=[_stamped(p) for p in plan["poses"]])
    return NavigateThroughPoses.Goal(poses=[_stamped(p) for p in plan["poses"]])


def planning_ok(kind: str, result) -> tuple[bool, str]:  # noqa: ANN001
    """(success, message) of a planning result: ZX200 error_code.val == SUCCESS, Nav2 error_code == 0."""
    if kind in ("change_pose", "excavate", "release"):
        return result.error_code.val == ErrorCodes.SUCCESS, f"error_code {result.error_code.val}: {result.message}"
    if kind == "dump":
        return bool(result.success), result.message
    return result.error_code == 0, f"error_code {result.error_code}: {result.error_msg}"


def _feedback_text(fb) -> str:  # noqa: ANN001
    for field in ("state", "current_waypoint", "distance_remaining", "current_error"):
        if hasattr(fb, field):
            return f"{field}={getattr(fb, field)}"
    return ""


class SubtaskServers(Node):
    """All subtask action servers of one machine (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__("tms_ts_subtasks")
        machine = str(self.declare_parameter("machine", "").value)
        self.model_name = str(self.declare_parameter("model_name", machine).value) or machine
        self.planning_wait_s = float(self.declare_parameter("planning_wait_s", 5.0).value)
        self.stop_timeout_s = float(self.declare_parameter("stop_timeout_s", 5.0).value)
        self.server_lost_s = float(self.declare_parameter("server_lost_s", 3.0).value)
        db_uri = str(self.declare_parameter("db_uri", "").value)
        db_path = str(self.declare_parameter("db_path", "").value)
        specs = subtasks_for(machine)  # ValueError naming the valid machines
        from tms_db import open_store

        self.store = open_store(uri=db_uri or None, path=db_path or None)
        self.store_lock = threading.Lock()
        group = ReentrantCallbackGroup()
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.rejections = self.create_publisher(String, REJECTIONS_TOPIC, reliable)
        self.emg = self.create_publisher(Bool, f"/{self.model_name}/emg_stop", 10)
        self.planners: dict[str, RaceFreeActionClient] = {}
        self.action_servers = []
        for spec in specs:
            action_type = self._kind_type(spec)
            planning = f"/{self.model_name}/{spec.planning_action}"
            if planning not in self.planners:
                self.planners[planning] = RaceFreeActionClient(self, action_type, planning, callback_group=group)
            self.action_servers.append(ActionServer(
                self, Subtask, f"/{self.model_name}/{spec.name}",
                execute_callback=lambda gh, s=spec: self._execute(gh, s),
                goal_callback=lambda goal, s=spec: self._on_goal(goal, s),
                cancel_callback=lambda _gh: CancelResponse.ACCEPT,
                callback_group=group,
            ))
        self.heartbeat = self.create_publisher(String, HEARTBEAT_TOPIC, 10)
        self._goals = RunningGoals()  # SIGINT/SIGTERM: every running goal cancels downstream, then aborts
        self._beat_stop = threading.Event()
        threading.Thread(target=self._beat, name="subtask_heartbeat", daemon=True).start()
        self.get_logger().info(f"subtask servers for /{self.model_name}: {', '.join(s.name for s in specs)}")

    def _beat(self) -> None:
        msg = String(data=self.model_name)
        while not self._beat_stop.wait(HEARTBEAT_PERIOD_S):
            try:
                self.heartbeat.publish(msg)
            except Exception:  # noqa: BLE001 - context shut down at exit
                return

    @staticmethod
    def _kind_type(spec: SubtaskSpec):  # noqa: ANN205
        return {"tms_rp_zx200_change_pose": Zx200ChangePose, "tms_rp_zx200_excavate_simple": Zx200ExcavateSimple,
                "tms_rp_zx200_release_simple": Zx200ReleaseSimple, "set_dump_angle": SetDumpAngle,
                "navigate_to_pose": NavigateToPose, "follow_waypoints": FollowWaypoints,
                "navigate_through_poses": NavigateThroughPoses}[spec.planning_action]

    def _plan(self, goal: Subtask.Goal, spec: SubtaskSpec) -> dict:
        from tms_db.errors import RecordNotFound

        model = goal.model_name or self.model_name
        try:
            with self.store_lock:
                doc = self.store.get_parameter(model, goal.record_name)
        except RecordNotFound:
            raise SubtaskRecordError(goal.record_name, None, f"not found in parameter (model_name '{model}')") from None
        return spec.build(doc, goal.record_name)

    def _on_goal(self, goal: Subtask.Goal, spec: SubtaskSpec) -> GoalResponse:
        if self._goals.stopping.is_set():
            self.get_logger().error(f"/{self.model_name}/{spec.name}: goal rejected: the server is stopping")
            return GoalResponse.REJECT
        try:
            self._plan(goal, spec)
        except SubtaskRecordError as exc:
            action = f"/{self.model_name}/{spec.name}"
            reason = str(exc)
            self.rejections.publish(String(data=json.dumps({"action": action, "record_name": goal.record_name,
                                                            "reason": reason})))
            self.get_logger().error(f"{action}: goal rejected: {reason}")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _finish(self, gh, spec: SubtaskSpec, how: str, message: str) -> Subtask.Result:  # noqa: ANN001
        if spec.clears_lock_flg:
            try:
                with self.store_lock:
                    self.store.set_fields(gh.request.record_name, {"LOCK_FLG": False},
                                          model_name=gh.request.model_name or self.model_name)
            except Exception as exc:  # noqa: BLE001 - a bookkeeping write must not hide the result
                self.get_logger().warning(f"LOCK_FLG of '{gh.request.record_name}' not cleared: {exc}")
        getattr(gh, how)()
        self.get_logger().info(f"/{self.model_name}/{spec.name} '{gh.request.record_name}' {how}: {message}")
        return Subtask.Result(success=how == "succeed", message=message)

    def on_stop_requested(self) -> bool:
        """run_node's stop hook: cancel the running goals downstream; True while any is still running."""
        return self._goals.wind_down(self.stop_timeout_s + 1.0, lambda n: self.get_logger().warning(
            f"stopping: canceling {n} running goal(s) downstream"))

    def _execute(self, gh, spec: SubtaskSpec) -> Subtask.Result:  # noqa: ANN001
        with self._goals.running():
            return self._execute_goal(gh, spec)

    def _execute_goal(self, gh, spec: SubtaskSpec) -> Subtask.Result:  # noqa: ANN001
        record = gh.request.record_name
        try:
            plan = self._plan(gh.request, spec)
        except SubtaskRecordError as exc:
            return self._finish(gh, spec, "abort", str(exc))
        planning = f"/{self.model_name}/{spec.planning_action}"
        client = self.planners[planning]
        if not client.wait_for_server(timeout_sec=self.planning_wait_s):
            return self._finish(gh, spec, "abort", f"planning server {planning} not available")
        done = threading.Event()

        def on_feedback(msg) -> None:  # noqa: ANN001
            gh.publish_feedback(Subtask.Feedback(state=_feedback_text(msg.feedback)))

        send = client.send_goal_async(planning_goal(plan), feedback_callback=on_feedback)
        send.add_done_callback(lambda _f: done.set())
        while not done.wait(0.02):
            if gh.is_cancel_requested and not send.done():
                pass  # keep waiting: the handle is needed to cancel planning
        handle = send.result()
        if handle is None or not handle.accepted:
            return self._finish(gh, spec, "abort", f"planning {planning} rejected the goal for record '{record}'")
        done.clear()
        result_future = handle.get_result_async()
        result_future.add_done_callback(lambda _f: done.set())
        cancel_deadline = None
        lost_since = None
        next_check = time.monotonic() + 0.2
        while not done.wait(0.02):
            now = time.monotonic()
            if now >= next_check:  # the planning process may have died: its goal would never end
                next_check = now + 0.2
                if client.server_is_ready():
                    lost_since = None
                elif lost_since is None:
                    lost_since = now
                elif now - lost_since >= self.server_lost_s:
                    self.emg.publish(Bool(data=True))
                    return self._finish(gh, spec, "abort", f"planning server {planning} lost while running "
                                        f"record '{record}' (unavailable for {now - lost_since:.1f} s): "
                                        f"/{self.model_name}/emg_stop latched")
            if (gh.is_cancel_requested or self._goals.stopping.is_set()) and cancel_deadline is None:
                handle.cancel_goal_async()
                cancel_deadline = time.monotonic() + self.stop_timeout_s
            if cancel_deadline is not None and time.monotonic() > cancel_deadline:
                self.emg.publish(Bool(data=True))
                return self._finish(gh, spec, "abort", f"planning {planning} did not confirm the stop within "
                                    f"{self.stop_timeout_s:g} s: /{self.model_name}/emg_stop latched")
        res = result_future.result()
        ok, detail = planning_ok(plan["kind"], res.result)
        status = {GoalStatus.STATUS_CANCELED: "CANCELED", GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED"}.get(
            res.status, "ABORTED")
        if gh.is_cancel_requested:
            return self._finish(gh, spec, "canceled", f"canceled; planning {planning} confirmed stop ({status})")
        if self._goals.stopping.is_set():
            return self._finish(gh, spec, "abort", f"subtask server stopping (SIGINT/SIGTERM): planning {planning} "
                                f"canceled ({status})")
        if res.status == GoalStatus.STATUS_SUCCEEDED and ok:
            return self._finish(gh, spec, "succeed", f"{spec.name} '{record}' done")
        return self._finish(gh, spec, "abort", f"planning {planning} failed for record '{record}': {detail}")

    def destroy_node(self) -> None:
        self._beat_stop.set()
        self.store.close()
        super().destroy_node()


def main() -> int:
    from tms_ts.nodes import run_threaded

    # stop_in_context: on SIGINT/SIGTERM running goals cancel their planning goals and end (on_stop_requested)
    return run_threaded(SubtaskServers, threads=32, stop_in_context=True)
