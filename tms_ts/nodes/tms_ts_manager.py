"""``tms_ts_manager``: runs many tasks at once, each its own tree and local blackboard.

Topics (contract E):

=========================  =====================  =================================================
topic                      type                   meaning
=========================  =====================  =================================================
``/tms_ts/start``          tms_msg/TaskIds        start these task ids (tree loaded from tms_db)
``/tms_ts/cancel``         std_msgs/Int32         cancel one task id
``/emergency_signal``      std_msgs/Bool          ``true`` cancels every task
``/tms_ts/status``         tms_msg/TaskStatus     every task: state, running leaves, message, tree
``/tms_ts/tick_stats``     std_msgs/String        JSON: ticks, missed ticks, tick durations (1 Hz)
``/tms_ts/confirm``        std_msgs/String        WaitForClick answers (see tms_ts.nodes.ros_port)
``/task_sequence``         std_msgs/String        the original's start path: a tree XML, or its GUI's
                                                  JSON ``{"tasks": [{task_id, task_sequence}]}``
=========================  =====================  =================================================

A task document's field ``blackboard`` (e.g. ``{machine: ic120_1}``) gives the task's initial blackboard
entries, its parameters: one tree of a machine kind runs for each machine named there (:mod:`tms_ts.loader`).

Global-blackboard reservations: every task is ticked from this one timer callback, one task after the other,
and a tree node's DB read or write completes inside its tick (the store calls are synchronous). A
read-check-write sequence of one tree (BlackboardValueReaderMongo -> ConditionalExpression ->
MongoValueWriter under one Sequence) that runs within one tick therefore runs with no other task's node in
between: two tasks of this manager can never both read a flag false and both set it. (MongoValueWriter returns
RUNNING only when the record is missing: then the claim fails anyway.) Writers in other processes (sensing, a
second manager) are not covered; the loading-point flag has none. trees/README.md, "Reservation".

Parameters: ``tick_rate_hz`` (20.0), ``status_rate_hz`` (2.0), ``server_wait_s`` (5.0),
``accept_timeout_s`` (1.0), ``halt_timeout_s`` (5.0), ``server_lost_s`` (3.0), ``db_uri`` (""),
``db_path`` ("" = tms_db default), ``db_checkpoint_period_s`` (1.0; the embedded store's WAL checkpoint runs in a
thread of its own this often instead of inside a flag write of the tick, :meth:`tms_db.store.Store.checkpoint_in_background`;
0 = SQLite's automatic checkpoint), ``realtime_priority`` (0 = off; 1-99: SCHED_FIFO for the thread that spins
the manager, needs CAP_SYS_NICE, :func:`tms_common.node.realtime_thread`); all read-only (read at start-up). ``task_id`` (-1), the original's:
which entry of a ``/task_sequence`` JSON to run (-1: every entry), and the id an XML runs under (-1: the
stored task with that tree, else an ad-hoc negative id); read on every message, as the original does
(:mod:`tms_ts.task_sequence`).
A task is ticked at the fixed rate; a tick that starts more than half a period late counts as missed.

Lost-server policy: when a task ends FAILURE because a subtask or planning server was lost mid-goal (its
machine's ``emg_stop`` is then latched, see :mod:`tms_ts.leaf`), every other running task is cancelled
("stopped by policy"): the tasks cooperate through the global blackboard and the partner would wait
for flags that never come, or act on a machine state nobody supervises.
"""

from __future__ import annotations

import json
import time

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, Int32, String

from tms_common.errors import TmsError
from tms_common.node import realtime_thread, run_node
from tms_msg.msg import TaskIds, TaskState, TaskStatus
from tms_ts.bt.core import TreeContext
from tms_ts.errors import TsError
from tms_ts.loader import load_tree
from tms_ts.nodes.ros_port import ManagerRosPort
from tms_ts.task import CANCELED, FAILED, SUCCEEDED, TaskRun
from tms_ts.task_sequence import NO_TASK_ID, TASK_SEQUENCE_TOPIC, parse_task_sequence, stored_task_id

__all__ = ["TaskManager", "main"]

_STATE = {SUCCEEDED: TaskState.SUCCESS, FAILED: TaskState.FAILURE, CANCELED: TaskState.CANCELED}


class TaskManager(Node):
    """The task scheduler manager node (see the module docstring)."""

    def __init__(self, node_name: str = "tms_ts_manager", **kwargs) -> None:  # noqa: ANN003 - rclpy Node kwargs
        super().__init__(node_name, **kwargs)
        read_only = ParameterDescriptor(read_only=True)  # every parameter is read once, here

        def p(name: str, default):  # noqa: ANN001, ANN202
            return self.declare_parameter(name, default, read_only)
        self.tick_rate = float(p("tick_rate_hz", 20.0).value)
        status_rate = float(p("status_rate_hz", 2.0).value)
        self.server_wait_s = float(p("server_wait_s", 5.0).value)
        self.accept_timeout_s = float(p("accept_timeout_s", 1.0).value)
        self.halt_timeout_s = float(p("halt_timeout_s", 5.0).value)
        self.server_lost_s = float(p("server_lost_s", 3.0).value)
        db_uri = str(p("db_uri", "").value)
        db_path = str(p("db_path", "").value)
        for name, value in (("tick_rate_hz", self.tick_rate), ("status_rate_hz", status_rate)):
            if not value > 0:
                raise ValueError(f"tms_ts_manager: parameter {name} must be > 0, got {value}")
        from tms_db import open_store

        self.store = open_store(uri=db_uri or None, path=db_path or None)
        # flag writes happen inside the tick: the embedded store's WAL checkpoint goes to a thread of its own
        checkpoint_s = float(p("db_checkpoint_period_s", 1.0).value)
        if checkpoint_s < 0:
            raise ValueError(f"tms_ts_manager: parameter db_checkpoint_period_s must be >= 0, got {checkpoint_s}")
        if checkpoint_s > 0:
            self.store.checkpoint_in_background(checkpoint_s)
        self.ros = ManagerRosPort(self)
        self.runs: dict[int, TaskRun] = {}
        self.finished: dict[int, TaskState] = {}
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(TaskIds, "/tms_ts/start", self._on_start, reliable)
        # the original's start path; its task_id is read per message, so it stays writable
        self.declare_parameter("task_id", NO_TASK_ID)
        self.create_subscription(String, TASK_SEQUENCE_TOPIC, self._on_task_sequence, reliable)
        self.create_subscription(Int32, "/tms_ts/cancel", self._on_cancel, reliable)
        self.create_subscription(Bool, "/emergency_signal", self._on_emergency, reliable)
        self.status_pub = self.create_publisher(TaskStatus, "/tms_ts/status", reliable)
        self.stats_pub = self.create_publisher(String, "/tms_ts/tick_stats", 10)
        self.period = 1.0 / self.tick_rate
        self._stats = {"ticks": 0, "missed": 0, "max_tick_ms": 0.0, "sum_tick_ms": 0.0, "max_late_ms": 0.0}
        self._last_tick: float | None = None
        self.create_timer(self.period, self._tick)
        self.create_timer(1.0 / status_rate, self._publish_status)
        self.create_timer(1.0, self._publish_stats)
        # SCHED_FIFO for the thread that builds the node: the one that spins it, under run_node and in a container
        # (whose other nodes then share the priority)
        realtime_thread(int(p("realtime_priority", 0).value), "tms_ts_manager", self.get_logger())
        self.get_logger().info(f"tms_ts_manager ready: {self.tick_rate:g} Hz, db {db_uri or db_path or 'default'}")

    # commands ----------------------------------------------------------------------------------
    def _on_start(self, msg: TaskIds) -> None:
        for task_id in msg.task_ids:
            self.start_task(int(task_id))
        self._publish_status()

    def _on_task_sequence(self, msg: String) -> None:
        try:
            wanted = parse_task_sequence(msg.data, int(self.get_parameter("task_id").value))
            for task in wanted:
                task_id = task.task_id
                if task_id is None:
                    task_id = stored_task_id(task.xml, self.store.list_tasks())
                if task_id is None:  # a tree the DB does not hold: an id no stored task can have
                    task_id = min([NO_TASK_ID + 1, *self.runs, *self.finished]) - 1
                    self.get_logger().info(f"/task_sequence: tree not in the database, run as ad-hoc task {task_id}")
                self.start_task(task_id, task.xml)
        except TmsError as exc:  # TaskSequenceError, or the store failing to list the tasks
            self.get_logger().error(str(exc))
        self._publish_status()

    def start_task(self, task_id: int, xml: str | None = None) -> None:
        """Start ``task_id`` with its tree from the DB, or with ``xml`` when given (``/task_sequence``)."""
        run = self.runs.get(task_id)
        if run is not None and not run.done:
            self.get_logger().warning(f"task {task_id} is already running; start ignored")
            return
        try:
            blackboard = None  # the task's parameters: its document's initial blackboard entries
            if xml is None:
                doc = self.store.get_task(task_id)
                xml, blackboard = doc.get("task_sequence", ""), doc.get("blackboard")
            elif task_id >= 0:  # /task_sequence naming a stored task: its parameters too
                blackboard = self._stored_blackboard(task_id)
            # Delay / Timeout / Sleep run on the node's clock (simulated time under use_sim_time)
            ctx = TreeContext(store=self.store, ros=self.ros, task_id=task_id,
                              task_clock=lambda: self.get_clock().now().nanoseconds * 1e-9,
                              accept_timeout_s=self.accept_timeout_s, halt_timeout_s=self.halt_timeout_s,
                              server_lost_s=self.server_lost_s)
            tree = load_tree(xml, ctx, source=f"task {task_id}", blackboard=blackboard)
        except (TsError, KeyError, ValueError) as exc:
            message = f"cannot start task {task_id}: {exc}"
            self.get_logger().error(message)
            self.runs.pop(task_id, None)
            self.finished[task_id] = TaskState(task_id=task_id, state=TaskState.FAILURE, message=message)
            return
        self.finished.pop(task_id, None)
        self.runs[task_id] = TaskRun(task_id, tree, server_wait_s=self.server_wait_s)
        self.get_logger().info(f"task {task_id} started ({len(tree.nodes)} nodes, {len(tree.leaves)} leaves)")

    def _stored_blackboard(self, task_id: int):  # noqa: ANN202
        from tms_db.errors import RecordNotFound

        try:
            return self.store.get_task(task_id).get("blackboard")
        except RecordNotFound:
            return None

    def _on_cancel(self, msg: Int32) -> None:
        run = self.runs.get(int(msg.data))
        if run is None or run.done:
            self.get_logger().warning(f"cancel: task {msg.data} is not running")
            return
        run.cancel("canceled by /tms_ts/cancel")
        self._publish_status()

    def _on_emergency(self, msg: Bool) -> None:
        if not msg.data:
            return
        active = [r for r in self.runs.values() if not r.done]
        for run in active:
            run.cancel("canceled by /emergency_signal")
        if active:
            self.get_logger().warning(f"emergency signal: canceling tasks {[r.task_id for r in active]}")
            self._publish_status()

    # ticking -----------------------------------------------------------------------------------
    def _tick(self) -> None:
        start = time.monotonic()
        if self._last_tick is not None:
            late = start - self._last_tick - self.period
            if late > 0.5 * self.period:
                self._stats["missed"] += int(late / self.period + 0.5)
            self._stats["max_late_ms"] = max(self._stats["max_late_ms"], late * 1000.0)
        self._last_tick = start
        changed = False
        for run in list(self.runs.values()):
            if run.done:
                continue
            before = run.state
            run.step()
            changed |= run.state != before
            if run.done:
                self._log_end(run)
            if run.state == FAILED and before != FAILED and run.ctx.lost_servers:
                self._stop_others(run)
        took = (time.monotonic() - start) * 1000.0
        self._stats["ticks"] += 1
        self._stats["sum_tick_ms"] += took
        self._stats["max_tick_ms"] = max(self._stats["max_tick_ms"], took)
        if changed:
            self._publish_status()

    def _log_end(self, run: TaskRun) -> None:
        # One call site per severity: rclpy refuses a log call whose severity differs from its last call
        # at the same line ("Logger severity cannot be changed between calls"), which killed the tick.
        text = f"task {run.task_id} ended {run.state}" + (f": {run.message}" if run.message else "")
        if run.state == SUCCEEDED:
            self.get_logger().info(text)
        elif run.state == CANCELED:
            self.get_logger().warning(text)
        else:
            self.get_logger().error(text)

    def _stop_others(self, failed: TaskRun) -> None:
        """Lost-server policy (module docstring): cancel every other running task."""
        reason = f"stopped by policy: task {failed.task_id} lost {', '.join(failed.ctx.lost_servers)}"
        for other in self.runs.values():
            if other is not failed and not other.done:
                self.get_logger().error(f"task {other.task_id}: {reason}")
                other.cancel(reason)

    def _publish_stats(self) -> None:
        s = dict(self._stats)
        s["active_tasks"] = sum(1 for r in self.runs.values() if not r.done)
        s["mean_tick_ms"] = s.pop("sum_tick_ms") / max(1, s["ticks"])
        s["tick_rate_hz"] = self.tick_rate
        self.stats_pub.publish(String(data=json.dumps(s)))

    def _publish_status(self) -> None:
        msg = TaskStatus()
        msg.stamp = self.get_clock().now().to_msg()
        for task_id, run in sorted(self.runs.items()):
            state = TaskState(task_id=task_id, message=run.message)
            state.state = _STATE.get(run.state, TaskState.RUNNING)
            if not run.done:
                state.message = f"{run.state}: {run.message}" if run.message else run.state
            state.running_leaves = run.running_leaves()
            state.tree_snapshot = run.tree.snapshot()
            msg.tasks.append(state)
        msg.tasks.extend(s for tid, s in sorted(self.finished.items()) if tid not in self.runs)
        self.status_pub.publish(msg)

    def destroy_node(self) -> None:
        if any(not r.done for r in self.runs.values()):
            self.ros.wait_for_lock_listeners(timeout_s=1.0)  # the locks below must reach the converters
        for run in self.runs.values():
            if not run.done:
                run.cancel("manager shutting down")
        self.store.close()
        super().destroy_node()


def main() -> int:
    # stop_in_context: on SIGINT/SIGTERM destroy_node still cancels running tasks and engages their machines' locks.
    # events: the tick timer and the action clients' responses cost a fraction of the SingleThreadedExecutor's
    # wake (docs/performance.md, "Scheduler: 10 tasks at 50 Hz").
    return run_node(TaskManager, executor="events", stop_in_context=True)
