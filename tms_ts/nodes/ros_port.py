"""rclpy implementation of :class:`tms_ts.leaf.RosPort` used by the manager.

Everything is asynchronous (futures with done-callbacks) so the manager's single-threaded executor
keeps ticking while goals are accepted, run and cancelled.

Leaf -> subtask is the original's ``tms_msg_ts/action/LeafNodeBase`` at ``/<model_name>/<subtask_name>``;
a goal's typed code and text come from ``/<model_name>/subtask_outcome`` (tms_msg/SubtaskOutcome, by goal
id), read when the result is not a success (waiting up to ``OUTCOME_GRACE_S`` for it; without it the code is
UNKNOWN and the text the goal's last feedback - a subtask server of the original publishes none).

Topics: ``/tms_ts/confirm`` (std_msgs/String; WaitForClick answers, "yes" / "no" / "<task_id>:yes"),
``/tms_ts/subtask_heartbeat`` (std_msgs/String, model name of each living tms_ts_subtasks process),
``/<model_name>/emg_stop`` (std_msgs/Bool true, the escalation when a halted subtask never confirms
its stop).

Names: the loader refuses a leaf whose names are no ROS names (:mod:`tms_ts.names`); should one still get here,
creating its client or publisher raises :class:`tms_ts.errors.TreeRuntimeError` naming the name (rclpy's
``ValueError`` ended the manager's timer, and with it the process), which ends that task FAILURE only.
"""

from __future__ import annotations

import threading
import time
import uuid

from action_msgs.msg import GoalStatus
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, String
from unique_identifier_msgs.msg import UUID

from tms_common.action_client import RaceFreeActionClient
from tms_common.goals import OUTCOME_QOS
from tms_msg.msg import SubtaskOutcome
from tms_msg_ts.action import LeafNodeBase
from tms_ts.errors import TreeRuntimeError
from tms_ts.leaf import ABORTED, ACCEPTED, CANCELED, PENDING, REJECTED, SUCCEEDED
from tms_ts.outcomes import OUTCOME_GRACE_S, SUBTASK_OUTCOME_TOPIC
from tms_ts.subtask_specs import SUBTASKS

__all__ = ["RosGoal", "ManagerRosPort", "CONFIRM_TOPIC", "HEARTBEAT_TOPIC"]

CONFIRM_TOPIC = "/tms_ts/confirm"
#: std_msgs/String(model_name) from every tms_ts_subtasks process every HEARTBEAT_PERIOD_S (wall time)
HEARTBEAT_TOPIC = "/tms_ts/subtask_heartbeat"
#: 0.05 s: a machine PC's converter takes 0.2 s of silence (4 periods) as a cut site link and must still bring
#: its machine to rest within 0.5 s (docs/deployment.md, site watchdog)
HEARTBEAT_PERIOD_S = 0.05
#: a heartbeat older than this [s wall] counts as silent (the leaf then waits server_lost_s more)
HEARTBEAT_STALE_S = 0.6
_STATUS = {
    GoalStatus.STATUS_SUCCEEDED: SUCCEEDED,
    GoalStatus.STATUS_CANCELED: CANCELED,
    GoalStatus.STATUS_ABORTED: ABORTED,
}


def _one_line(exc: Exception) -> str:
    """rclpy's name errors span lines (name, caret): the first one."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0].rstrip(":") if lines else type(exc).__name__


class RosGoal:
    """One LeafNodeBase goal: ``state`` follows the action protocol through future callbacks; a result that
    is not a success becomes the state once its outcome (``outcomes``, by goal id) is in or the grace ran out."""

    def __init__(self, client: RaceFreeActionClient, goal: LeafNodeBase.Goal, outcomes: dict | None = None) -> None:
        self._state = PENDING
        self._ended: tuple[str, float] | None = None  # (state, monotonic time) of a result not yet resolved
        self._outcomes = outcomes if outcomes is not None else {}
        self.error_code = 0
        self.message = ""
        self.feedback = ""
        self._handle = None
        self._cancel_wanted = False
        self._client = client
        #: our own goal id, so a goal whose response never arrives can still be cancelled by id
        self.goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        #: True once a cancel was sent by goal id while no goal response had arrived
        self.cancelled_unanswered = False
        future = client.send_goal_async(goal, feedback_callback=self._on_feedback, goal_uuid=self.goal_id)
        future.add_done_callback(self._on_response)

    @property
    def state(self) -> str:
        if self._ended is not None:
            ended, at = self._ended
            outcome = self._outcomes.pop(bytes(self.goal_id.uuid), None)
            if outcome is not None:
                self.error_code, self.message = outcome.error_code, outcome.error_msg
            elif time.monotonic() - at < OUTCOME_GRACE_S:
                return ACCEPTED  # the result is in; its outcome may trail it
            else:
                self.error_code, self.message = SubtaskOutcome.UNKNOWN, ""
            self._ended = None
            self._state = ended
        return self._state

    @state.setter
    def state(self, value: str) -> None:
        self._state = value

    def _on_feedback(self, msg) -> None:
        self.feedback = msg.feedback.status

    def _on_response(self, future) -> None:
        handle = future.result()
        if handle is None or not handle.accepted:
            self._state = REJECTED
            return
        self._handle = handle
        self._state = ACCEPTED
        handle.get_result_async().add_done_callback(self._on_result)
        if self._cancel_wanted:
            handle.cancel_goal_async()

    def _on_result(self, future) -> None:
        res = future.result()
        state = _STATUS.get(res.status, ABORTED)
        if state == SUCCEEDED:  # the goal status decides, as the original's leaf reads it (not the bool)
            self._outcomes.pop(bytes(self.goal_id.uuid), None)
            self._state = SUCCEEDED
        else:  # resolved by ``state`` once the typed outcome is in (or its grace ran out)
            self._ended = (state, time.monotonic())

    def cancel(self) -> None:
        self._cancel_wanted = True
        if self._handle is not None and self._state == ACCEPTED and self._ended is None:
            self._handle.cancel_goal_async()
        elif self._state == PENDING and not self.cancelled_unanswered:
            # No response yet (e.g. the accept timeout): the server may have accepted the goal and its reply
            # been dropped (config/dds/fastdds_profiles.xml) - cancel by id so it cannot run on unseen.
            self.cancelled_unanswered = True
            self._client.cancel_goal_by_id(self.goal_id)


class ManagerRosPort:
    """Action clients, confirm inbox, heartbeats and emergency-stop publishers of one node."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._clients: dict[str, RaceFreeActionClient] = {}
        self._emg: dict[str, object] = {}
        self._lock_pubs: dict[str, object] = {}
        self.locked: dict[str, bool] = {}
        self._confirm: list[tuple[int, str]] = []
        self._seq = 0
        self._lock = threading.Lock()
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        node.create_subscription(String, CONFIRM_TOPIC, self._on_confirm, reliable)
        self._beats: dict[str, float] = {}
        node.create_subscription(String, HEARTBEAT_TOPIC, self._on_beat, 50)
        #: goal id bytes -> SubtaskOutcome not yet claimed by its goal (bounded: the newest 200)
        self._outcomes: dict[bytes, SubtaskOutcome] = {}
        self._outcome_subs: dict[str, object] = {}

    def _client(self, model_name: str, subtask_name: str) -> RaceFreeActionClient:
        name = f"/{model_name}/{subtask_name}"
        client = self._clients.get(name)
        try:
            if client is None:
                client = self._clients[name] = RaceFreeActionClient(self.node, LeafNodeBase, name)
            if model_name not in self._outcome_subs:
                self._outcome_subs[model_name] = self.node.create_subscription(
                    SubtaskOutcome, f"/{model_name}/{SUBTASK_OUTCOME_TOPIC}", self._on_outcome, OUTCOME_QOS)
        except ValueError as exc:  # rclpy: "Failed to create action client due to invalid topic name"
            raise TreeRuntimeError(f"action {name!r} (model_name {model_name!r}): {_one_line(exc)}") from None
        return client

    def _on_outcome(self, msg: SubtaskOutcome) -> None:
        self._outcomes[bytes(msg.goal_id.uuid)] = msg
        if len(self._outcomes) > 200:
            del self._outcomes[next(iter(self._outcomes))]

    # RosPort -----------------------------------------------------------------------------------
    def subtask_server_ready(self, model_name: str, subtask_name: str) -> bool:
        return self._client(model_name, subtask_name).server_is_ready()

    def planning_server_ready(self, model_name: str, subtask_name: str) -> bool | None:
        """The subtask's planning action server on the ROS graph (None for a subtask without a row).

        A graph query, not an action client: the manager need not receive every planning action's feedback
        and status. An action server offers the service ``<action>/_action/send_goal`` (ROS 2 action design).
        """
        spec = SUBTASKS.get(subtask_name)
        if spec is None:
            return None
        return self.node.count_services(f"/{model_name}/{spec.planning_action}/_action/send_goal") > 0

    def subtask_server_alive(self, model_name: str) -> bool | None:
        """Heartbeat of ``model_name``'s tms_ts_subtasks: True fresh, False silent, None never heard
        (servers without a heartbeat are judged by the ROS graph alone)."""
        with self._lock:
            last = self._beats.get(model_name)
        if last is None:
            return None
        return time.monotonic() - last < HEARTBEAT_STALE_S

    def _on_beat(self, msg: String) -> None:
        with self._lock:
            self._beats[msg.data] = time.monotonic()

    def send_subtask_goal(self, model_name: str, subtask_name: str, record_name: str) -> RosGoal:
        goal = LeafNodeBase.Goal(model_name=model_name, record_name=record_name)
        return RosGoal(self._client(model_name, subtask_name), goal, self._outcomes)

    def _machine_pubs(self, model_name: str) -> tuple:
        """``/<model>/lock`` and ``/<model>/emg_stop`` publishers, created at the first goal to that machine
        so discovery has matched the converter long before a stop must get through (a publisher created
        at the moment of the stop would drop its first message)."""
        if model_name not in self._emg:
            reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
            try:
                lock = self.node.create_publisher(Bool, f"/{model_name}/lock", reliable)
                emg = self.node.create_publisher(Bool, f"/{model_name}/emg_stop", reliable)
            except ValueError as exc:  # an invalid name (the loader refuses them; never a crash here)
                raise TreeRuntimeError(f"machine topics of model_name {model_name!r}: {_one_line(exc)}") from None
            self._lock_pubs[model_name], self._emg[model_name] = lock, emg
        return self._lock_pubs[model_name], self._emg[model_name]

    def emergency_stop(self, model_name: str, reason: str) -> None:
        _, pub = self._machine_pubs(model_name)
        pub.publish(Bool(data=True))
        self.node.get_logger().error(f"emergency stop /{model_name}/emg_stop: {reason}")

    def wait_for_lock_listeners(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` [s wall] until every ``/<model>/lock`` publisher made so far has a matched
        subscriber: one created at a goal sent a moment before a stop may not be discovered yet, and its lock
        would be dropped. A machine without a listener (its converter is down) costs the whole wait, once."""
        end = time.monotonic() + timeout_s
        while any(p.get_subscription_count() == 0 for p in self._lock_pubs.values()) and time.monotonic() < end:
            time.sleep(0.01)

    def lock(self, model_name: str, engaged: bool, reason: str) -> None:
        """Engage / release ``/<model_name>/lock`` (the converter's pilot cut-off); a release is sent only
        when this manager engaged the lock."""
        pub, _ = self._machine_pubs(model_name)
        if not engaged and not self.locked.get(model_name):
            return
        pub.publish(Bool(data=engaged))
        self.locked[model_name] = engaged
        log = self.node.get_logger()
        # one call site per severity (rclpy refuses a severity change at the same line)
        if engaged:
            log.warning(f"/{model_name}/lock engaged: {reason}")
        else:
            log.info(f"/{model_name}/lock released: {reason}")

    def confirm_seq(self) -> int:
        with self._lock:
            return self._seq

    def confirmations(self, since: int) -> list[tuple[int, str]]:
        with self._lock:
            return [(s, t) for s, t in self._confirm if s > since]

    # subscriptions -----------------------------------------------------------------------------
    def _on_confirm(self, msg: String) -> None:
        with self._lock:
            self._seq += 1
            self._confirm.append((self._seq, msg.data))
            del self._confirm[:-100]
