"""LeafNode<Machine>: the asynchronous action client of a subtask server, and safe halting.

``<Action ID="LeafNodeZx200" model_name="zx200" subtask_name="subtask_zx200_change_pose"
record_name="{pose}"/>`` sends ``{model_name, record_name}`` to ``/<model_name>/<subtask_name>``
(the original's tms_msg_ts/action/LeafNodeBase). Every ``LeafNode*`` id (LeafNodeIc120, LeafNodeZx200, LeafNodeMst2200,
...)
is this one class; ``model_name`` and ``subtask_name`` are read once, as the original constructor did: literals,
or a ``{key}`` of the task's parameters (the task document's ``blackboard``), which the loader resolves when the
tree is loaded (:mod:`tms_ts.loader`); ``record_name`` may be a ``{key}`` resolved at each start.

Names are checked where they enter (:mod:`tms_ts.names`): ``model_name`` and ``subtask_name`` when the tree is
loaded, as ROS names by rclpy's rules (a name rclpy would refuse when the client is created, e.g. the full-width
underscore of ``d37pxi_24＿``, is a TreeLoadError naming the leaf and its line, so nothing can raise for it inside a
tick); a literal ``record_name`` then too, and a ``{key}`` one when the leaf reads it: a bad one ends the task
FAILURE (TreeRuntimeError) naming the leaf, its line, the key and the value.

Protocol (reference §4.2, made non-blocking): first tick sends the goal -> RUNNING; not accepted
within ``ctx.accept_timeout_s`` -> cancel, FAILURE; rejected (the server is stopping) -> FAILURE naming
the action and the record; SUCCEEDED -> SUCCESS; ABORTED/CANCELED -> FAILURE (as the original's leaf reads
the goal status). Logic reads only the goal's status, its typed ``error_code`` (tms_msg/SubtaskOutcome, which
our subtask servers publish beside the original's bool result) and what the leaf observes itself; the
outcome's ``error_msg`` (or, without one, the goal's last feedback) only goes into the FAILURE text.

Halt never blocks the tick: it requests the cancel and registers a :class:`PendingStop` in
``ctx.stops``. :func:`poll_stops` (called by the manager every tick) resolves it when the goal ends
CANCELED/ABORTED/SUCCEEDED, or escalates to ``/<model_name>/emg_stop`` after ``ctx.halt_timeout_s``.
A task being cancelled ends only when every pending stop is resolved, so "CANCELED" means the
machines are at rest (or their emergency stop is latched). A leaf re-started while its previous goal
is still stopping waits for that stop before sending the new goal.

Hydraulic lock: a task cancel engages ``/<model_name>/lock`` of every machine with a goal in flight
(:meth:`tms_ts.task.TaskRun.cancel`); the next goal a leaf sends to that machine releases it first.

Lost server: while a goal is accepted the leaf checks that its subtask server is still available (on
the ROS graph and, when the port offers ``subtask_server_alive``, by its heartbeat); if it stays
unavailable for ``ctx.server_lost_s`` (the process died, e.g. SIGKILL) the leaf latches
``/<model_name>/emg_stop`` (the machine's state is unknown: nothing may keep driving it; an operator
clears the latch), records the action in ``ctx.lost_servers`` and ends FAILURE naming the server.
A goal ABORTED because the subtask's *planning* server was lost (the subtask server latched emg_stop)
is recorded in ``ctx.lost_servers`` the same way, under the planning action's name (its row in
:mod:`tms_ts.subtask_specs`): when its code is SERVER_LOST, or when the leaf saw that planning server on
the graph during the goal (the port's optional ``planning_server_ready``) and no longer sees it.

The ROS side is the :class:`RosPort` protocol, implemented by the manager node with rclpy; this
module imports no rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from tms_ts.bt.core import FAILURE, RUNNING, SUCCESS, Port, StatefulNode, Status
from tms_ts.errors import TreeRuntimeError
from tms_ts.names import leaf_names_problem, record_name_problem
from tms_ts.outcomes import SERVER_LOST, code_name
from tms_ts.subtask_specs import SUBTASKS

__all__ = ["SubtaskGoal", "RosPort", "LeafNode", "PendingStop", "poll_stops"]

PENDING, ACCEPTED, REJECTED, SUCCEEDED, ABORTED, CANCELED = (
    "pending",
    "accepted",
    "rejected",
    "succeeded",
    "aborted",
    "canceled",
)
TERMINAL = frozenset({REJECTED, SUCCEEDED, ABORTED, CANCELED})


class SubtaskGoal(Protocol):
    """One goal in flight. ``state`` is pending|accepted|rejected|succeeded|aborted|canceled; ``error_code``
    the result's code (0 until a result came); ``message`` and ``feedback`` are for people only."""

    state: str
    error_code: int
    message: str
    feedback: str

    def cancel(self) -> None: ...


class RosPort(Protocol):
    """What tree nodes need from ROS (implemented by the manager node)."""

    def subtask_server_ready(self, model_name: str, subtask_name: str) -> bool: ...

    def send_subtask_goal(self, model_name: str, subtask_name: str, record_name: str) -> SubtaskGoal: ...

    def emergency_stop(self, model_name: str, reason: str) -> None: ...

    # optional: ``lock(model_name, engaged, reason)`` (hydraulic lock; ports without it skip locking),
    # ``subtask_server_alive(model_name) -> bool | None`` (heartbeat) and
    # ``planning_server_ready(model_name, subtask_name) -> bool | None`` (the subtask's planning server on the graph)

    def confirm_seq(self) -> int: ...

    def confirmations(self, since: int) -> list[tuple[int, str]]: ...


@dataclass
class PendingStop:
    """A halted goal whose CANCELED/ABORTED confirmation is awaited until ``deadline``."""

    leaf: LeafNode
    goal: SubtaskGoal
    deadline: float
    resolved: bool = False
    escalated: bool = False
    outcome: str = ""


def poll_stops(ctx) -> bool:  # TreeContext (avoid import cycle in annotations)
    """Resolve confirmed stops, escalate overdue ones; True when none is left pending."""
    now = ctx.clock()
    for stop in ctx.stops:
        if stop.resolved:
            continue
        if stop.goal.state in TERMINAL:
            stop.resolved = True
            stop.outcome = f"{stop.leaf.action} confirmed stop ({stop.goal.state})"
        elif now >= stop.deadline:
            stop.resolved = stop.escalated = True
            stop.outcome = (
                f"{stop.leaf.action} did not confirm stop within {ctx.halt_timeout_s:g} s: emergency stop sent"
            )
            if ctx.ros is not None:
                ctx.ros.emergency_stop(stop.leaf.model_name, stop.outcome)
    return all(stop.resolved for stop in ctx.stops)


class LeafNode(StatefulNode):
    """Action client of ``/<model_name>/<subtask_name>``; see the module docstring."""

    PORTS = {
        "model_name": Port(
            "str", description="machine name = namespace of its subtask servers (literal, or a task parameter {key})"
        ),
        "subtask_name": Port("str", description="subtask action name (literal, or a task parameter {key})"),
        "record_name": Port("str", description="DB record the subtask reads ({key} allowed)"),
    }
    LITERAL_PORTS = ("model_name", "subtask_name")

    @classmethod
    def check_ports(cls, attrs: dict[str, str]) -> str | None:
        for port in cls.LITERAL_PORTS:
            value = attrs.get(port, "")
            if value.startswith("{"):
                return f"port '{port}' must be a literal or a task parameter, got {value!r}"
            if not value.strip():
                return f"port '{port}' must not be empty"
        model, subtask = attrs["model_name"].strip("/"), attrs["subtask_name"].strip("/")
        problem = leaf_names_problem(model, subtask)
        if problem:
            return problem
        record = attrs.get("record_name", "")
        if not (record.startswith("{") and record.endswith("}")):  # a {key}: checked when the leaf reads it
            return record_name_problem(record, required=cls._reads_record(subtask))
        return None

    @staticmethod
    def _reads_record(subtask_name: str) -> bool:
        """The subtask reads a DB record (every subtask but those whose row says not; unknown ones: yes)."""
        spec = SUBTASKS.get(subtask_name)
        return spec is None or spec.reads_record

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.model_name = self.get_input("model_name").strip("/")
        self.subtask_name = self.get_input("subtask_name").strip("/")
        self.action = f"/{self.model_name}/{self.subtask_name}"
        self.goal: SubtaskGoal | None = None
        self.record = ""
        self.lost_since: float | None = None
        spec = SUBTASKS.get(self.subtask_name)
        #: the planning action this subtask drives (None for a subtask this build has no row for)
        self.planning_action = f"/{self.model_name}/{spec.planning_action}" if spec is not None else None
        self.planning_seen = False
        self.ctx.leaves.append(self)

    def _ros(self):
        if self.ctx.ros is None:
            raise TreeRuntimeError(f"{self.describe()}: no ROS side to reach {self.action}")
        return self.ctx.ros

    def _previous_stop_pending(self) -> bool:
        return any(not s.resolved and s.leaf is self for s in self.ctx.stops)

    def on_start(self) -> Status:
        self.goal = None
        self.record = self.get_input("record_name")
        problem = record_name_problem(self.record, required=self._reads_record(self.subtask_name))
        if problem:  # a {key} read now (a literal was checked at load): the task ends FAILURE naming it
            is_key, key = self._ports.get("record_name", (False, ""))
            source = f" (from blackboard key '{key}')" if is_key else ""
            raise TreeRuntimeError(f"{self.describe()}: {problem}{source}")
        if self._previous_stop_pending():
            self.feedback_message = f"waiting for the previous goal of {self.action} to stop"
            return RUNNING
        return self._send()

    def _send(self) -> Status:
        ros = self._ros()
        lock = getattr(ros, "lock", None)
        if lock is not None:
            lock(self.model_name, False, f"new goal {self.action}")
        self.lost_since = None
        self.planning_seen = False
        self.goal = ros.send_subtask_goal(self.model_name, self.subtask_name, self.record)
        self.sent_at = self.ctx.clock()
        self.feedback_message = f"sent {self.action} record '{self.record}'"
        return RUNNING

    def _fail(self, message: str) -> Status:
        self.feedback_message = message
        self.ctx.failures.append(f"{self.describe()}: {message}")
        self.goal = None
        return FAILURE

    def on_running(self) -> Status:
        goal = self.goal
        if goal is None:
            if self._previous_stop_pending():
                return RUNNING
            return self._send()
        state = goal.state
        if state == PENDING:
            if self.ctx.clock() - self.sent_at > self.ctx.accept_timeout_s:
                goal.cancel()
                return self._fail(
                    f"{self.action} did not accept the goal for record '{self.record}' "
                    f"within {self.ctx.accept_timeout_s:g} s (cancel sent by goal id, in case the server runs it)"
                )
            return RUNNING
        if state == ACCEPTED:
            ros = self._ros()
            alive = getattr(ros, "subtask_server_alive", None)
            beating = alive(self.model_name) if alive is not None else None
            if beating is False or not ros.subtask_server_ready(self.model_name, self.subtask_name):
                now = self.ctx.clock()
                if self.lost_since is None:
                    self.lost_since = now
                elif now - self.lost_since >= self.ctx.server_lost_s:
                    reason = (f"subtask server {self.action} lost while running record '{self.record}' "
                              f"(unavailable for {now - self.lost_since:.1f} s)")
                    self.ctx.lost_servers.append(self.action)
                    self._ros().emergency_stop(self.model_name, reason)
                    return self._fail(reason + f": /{self.model_name}/emg_stop latched")
            else:
                self.lost_since = None
            if not self.planning_seen:
                self.planning_seen = self._planning_ready() is True
            self.feedback_message = f"{self.action} '{self.record}': {goal.feedback or 'running'}"
            return RUNNING
        if state == SUCCEEDED:
            self.feedback_message = f"{self.action} '{self.record}' succeeded"
            self.goal = None
            return SUCCESS
        if state == REJECTED:
            return self._fail(f"{self.action} rejected the goal for record '{self.record}'")
        if state == ABORTED and self._planning_lost(goal):
            self.ctx.lost_servers.append(self.planning_action or f"planning server of {self.action}")
        reason = goal.message or goal.feedback
        label = f"{code_name(goal.error_code)}: " if goal.error_code else ""
        return self._fail(f"{self.action} {state} record '{self.record}': {label}{reason}")

    def _planning_ready(self) -> bool | None:
        ready = getattr(self._ros(), "planning_server_ready", None)
        return ready(self.model_name, self.subtask_name) if ready is not None else None

    def _planning_lost(self, goal: SubtaskGoal) -> bool:
        """The subtask's planning server was lost: its typed code says so, or the leaf saw it go."""
        return goal.error_code == SERVER_LOST or (self.planning_seen and self._planning_ready() is False)

    def on_halted(self) -> None:
        goal = self.goal
        self.goal = None
        if goal is None or goal.state in TERMINAL:
            return
        goal.cancel()
        self.ctx.stops.append(PendingStop(self, goal, self.ctx.clock() + self.ctx.halt_timeout_s))
        self.feedback_message = f"cancel requested for {self.action}"
