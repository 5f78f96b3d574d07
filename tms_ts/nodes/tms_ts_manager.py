"""``tms_ts_manager``: runs many tasks at once, each its own tree and local blackboard.

Topics (contract E):

=========================  =====================  =================================================
topic                      type                   meaning
=========================  =====================  =================================================
``/tms_ts/start``          tms_msg/TaskIds        start these task ids (tree loaded from tms_db)
``/tms_ts/cancel``         std_msgs/Int32         cancel one task id
``/emergency_signal``      std_msgs/Bool          ``true`` cancels every task
``/tms_ts/status``         tms_msg/TaskStatus     every task: state, running leaves, message; its tree snapshot
                                                  only when it changed (tms_ts.status)
``/tms_ts/snapshot_request``  std_msgs/Int32      the next status carries this task's snapshot (-1: every task's)
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
thread of its own this often instead of inside a flag write of the tick,
:meth:`tms_db.store.Store.checkpoint_in_background`;
0 = SQLite's automatic checkpoint), ``realtime_priority`` (0 = off; 1-99: SCHED_FIFO for the thread that spins
the manager, needs CAP_SYS_NICE, :func:`tms_common.node.realtime_thread`); all read-only (read at start-up). ``task_id``
(-1), the original's:
which entry of a ``/task_sequence`` JSON to run (-1: every entry), and the id an XML runs under (-1: the
stored task with that tree, else an ad-hoc negative id); read on every message, as the original does
(:mod:`tms_ts.task_sequence`).
A task is ticked at the fixed rate; a tick that starts more than half a period late counts as missed.

Loading off the tick: a start (``/tms_ts/start``, ``/task_sequence``) is handed to a worker thread
(:mod:`tms_ts.tree_loading`) that reads the DB, parses, checks and builds the tree; the tick takes the built tree
over and starts it. Meanwhile the task is reported RUNNING ``loading: ...``; a cancel or an emergency stop
that comes while it loads ends it CANCELED as soon as the load finishes, without running it; a load that fails
ends that start FAILURE naming why. ``max_pending_loads`` (16) starts may wait; more are refused.
Status: ``finished_retention_s`` (60.0, wall seconds a finished task stays in ``/tms_ts/status``; always
at least one message), ``finished_max`` (100, the last N finished tasks at most), ``snapshot_max_nodes``
(2000, lines of a tree snapshot), :mod:`tms_ts.status`.

Groot (:mod:`tms_ts.groot`): ``groot`` (true) publishes one running tree as BehaviorTree.CPP 3.x's ``PublisherZMQ``
does: status changes on ``groot_port`` (1666, PUB), the tree on request on ``groot_port`` + 1 (1667, REP), bound on
``groot_address`` ("*") at start-up (a port that cannot be bound ends the start naming it); ``groot_max_msg_per_second``
(100, the original's). Which tree: ``groot_task_id`` (-1: the earliest started task still running, then the next;
else that task; writable, read every tick); the published tree stays after its task ends until another is chosen.

Lost-server policy: when a task ends FAILURE because a subtask or planning server was lost mid-goal (its
machine's ``emg_stop`` is then latched, see :mod:`tms_ts.leaf`), every other running task is cancelled
("stopped by policy"): the tasks cooperate through the global blackboard and the partner would wait
for flags that never come, or act on a machine state nobody supervises.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool, Int32, String

from tms_common.errors import TmsError
from tms_common.node import realtime_thread, run_node
from tms_common.params import StartupParams
from tms_db import RecordNotFound, open_store
from tms_msg.msg import TaskIds, TaskState, TaskStatus
from tms_ts.bt.core import TreeContext
from tms_ts.errors import TsError
from tms_ts.groot import GrootPublisher
from tms_ts.loader import load_tree
from tms_ts.nodes.ros_port import ManagerRosPort
from tms_ts.status import StatusBook
from tms_ts.task import CANCELED, FAILED, SUCCEEDED, TaskRun
from tms_ts.task_sequence import NO_TASK_ID, TASK_SEQUENCE_TOPIC, parse_task_sequence, stored_task_id
from tms_ts.tree_loading import Loaded, LoadRequest, TreeLoadWorker

__all__ = ["TaskManager", "main"]


class TaskManager(Node):
    """The task scheduler manager node (see the module docstring)."""

    def __init__(self, node_name: str = "tms_ts_manager", **kwargs) -> None:  # rclpy Node kwargs
        super().__init__(node_name, **kwargs)
        p = StartupParams(self)  # every parameter is read once, here (read-only)
        self.tick_rate = p.number("tick_rate_hz", 20.0, lo=0.0, above=True)
        status_rate = p.number("status_rate_hz", 2.0, lo=0.0, above=True)
        self.server_wait_s = p.number("server_wait_s", 5.0, lo=0.0)
        self.accept_timeout_s = p.number("accept_timeout_s", 1.0, lo=0.0)
        self.halt_timeout_s = p.number("halt_timeout_s", 5.0, lo=0.0)
        self.server_lost_s = p.number("server_lost_s", 3.0, lo=0.0)
        db_uri = p.text("db_uri")
        db_path = p.text("db_path")
        # flag writes happen inside the tick: the embedded store's WAL checkpoint goes to a thread of its own
        checkpoint_s = p.number("db_checkpoint_period_s", 1.0, lo=0.0)
        retention_s = p.number("finished_retention_s", 60.0, lo=0.0)
        keep_max = p.integer("finished_max", 100, lo=1)
        snapshot_max = p.integer("snapshot_max_nodes", 2000, lo=1)
        max_loads = p.integer("max_pending_loads", 16, lo=1)
        groot_on = p.value("groot", True)
        if not isinstance(groot_on, bool):
            raise TsError(f"parameter groot: must be true or false, got {groot_on!r}")
        groot_port = p.integer("groot_port", 1666, lo=1)
        groot_address = p.text("groot_address", "*")
        groot_rate = p.number("groot_max_msg_per_second", 100.0, lo=0.0, above=True)
        self.store = open_store(uri=db_uri or None, path=db_path or None)
        if checkpoint_s > 0:
            self.store.checkpoint_in_background(checkpoint_s)
        self.ros = ManagerRosPort(self)
        # bound here, before anything runs: a port in use ends the start naming it (GrootError), no silent fallback
        self.groot = (GrootPublisher(groot_port, groot_port + 1, address=groot_address,
                                     max_msg_per_second=groot_rate) if groot_on else None)
        self._groot_run: TaskRun | None = None  # the run whose tree Groot sees
        # which task's tree Groot sees; read every tick, so `ros2 param set` switches it
        self.declare_parameter("groot_task_id", -1)
        #: tasks being run (ended runs are retired into ``self.status`` at the next tick or status)
        self.runs: dict[int, TaskRun] = {}
        self.status = StatusBook(retention_s=retention_s, keep_max=keep_max, snapshot_max_nodes=snapshot_max)
        # trees load on a worker thread; the tick takes them over (module docstring, "Loading off the tick")
        self.loader = TreeLoadWorker(self._load, max_pending=max_loads)
        self._seq = 0  # numbers the load requests, in the order they came
        self._loading: dict[int, int] = {}  # task id -> seq of its /tms_ts/start load
        self._load_cancels: dict[int | None, tuple[int, str]] = {}  # id (None: every load) -> (up to seq, reason)
        self._adhoc_lock = threading.Lock()
        self._next_adhoc = NO_TASK_ID
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(TaskIds, "/tms_ts/start", self._on_start, reliable)
        # the original's start path; its task_id is read per message, so it stays writable
        self.declare_parameter("task_id", NO_TASK_ID)
        self.create_subscription(String, TASK_SEQUENCE_TOPIC, self._on_task_sequence, reliable)
        self.create_subscription(Int32, "/tms_ts/cancel", self._on_cancel, reliable)
        self.create_subscription(Bool, "/emergency_signal", self._on_emergency, reliable)
        self.create_subscription(Int32, "/tms_ts/snapshot_request", self._on_snapshot_request, reliable)
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
        realtime_thread(p.integer("realtime_priority", 0), "tms_ts_manager", self.get_logger())
        self.get_logger().info(f"tms_ts_manager ready: {self.tick_rate:g} Hz, db {self.store!r}")

    # commands ----------------------------------------------------------------------------------
    def _on_start(self, msg: TaskIds) -> None:
        self.start_tasks([int(task_id) for task_id in msg.task_ids])
        self._publish_status()

    def _on_task_sequence(self, msg: String) -> None:
        # parsed, its ids resolved and its trees built on the loader's thread (_load)
        self._submit(LoadRequest(self._next_seq(), data=msg.data,
                                 param_task_id=int(self.get_parameter("task_id").value)), "/task_sequence")

    def start_task(self, task_id: int, xml: str | None = None) -> None:
        """Start ``task_id`` with its tree from the DB, or with ``xml`` when given; the tree loads off the tick."""
        self.start_tasks([task_id], xml)

    def start_tasks(self, task_ids: list[int], xml: str | None = None) -> None:
        """Start these tasks (trees from the DB, or ``xml`` for each): one load request, its trees loaded in turn."""
        wanted = []
        for task_id in task_ids:
            run = self.runs.get(task_id)
            if (run is not None and not run.done) or task_id in self._loading or task_id in wanted:
                self.get_logger().warning(f"task {task_id} is already running; start ignored")
                continue
            wanted.append(task_id)
        if not wanted:
            return
        seq = self._next_seq()
        what = "task " + ", ".join(map(str, wanted))
        if self._submit(LoadRequest(seq, task_ids=tuple(wanted), data=xml), what):
            self._loading.update((task_id, seq) for task_id in wanted)

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _submit(self, request: LoadRequest, what: str) -> bool:
        if self.loader.submit(request):
            return True
        message = (f"cannot start {what}: {self.loader.max_pending} trees are already waiting to load "
                   f"(parameter max_pending_loads)")
        self.get_logger().error(message)
        for task_id in request.task_ids:
            self.status.record(task_id, TaskState.FAILURE, message)
        return False

    # runs on the loader's thread: nothing here touches the runs or the status
    def _load(self, request: LoadRequest) -> Iterator[Loaded]:
        if request.task_ids:  # /tms_ts/start, or start_task(id, xml)
            for task_id in request.task_ids:
                yield self._load_one(request.seq, task_id, request.data)
            return
        try:
            wanted = parse_task_sequence(request.data, request.param_task_id)
        except TmsError as exc:  # TaskSequenceError naming what is wrong with the message
            yield Loaded(request.seq, None, error=str(exc))
            return
        for task in wanted:
            task_id = task.task_id
            try:
                if task_id is None:
                    task_id = stored_task_id(task.xml, self.store.list_tasks())
            except TmsError as exc:  # TaskSequenceError, or the store failing to list the tasks
                yield Loaded(request.seq, None, error=str(exc))
                continue
            if task_id is None:  # a tree the DB does not hold: an id no stored task can have
                task_id = self._adhoc_id()
                self.get_logger().info(f"/task_sequence: tree not in the database, run as ad-hoc task {task_id}")
            yield self._load_one(request.seq, task_id, task.xml)

    def _load_one(self, seq: int, task_id: int, xml: str | None) -> Loaded:
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
        except (TsError, KeyError, ValueError) as exc:  # the tree's or the task's own error: its text names it
            return Loaded(seq, task_id, error=f"cannot start task {task_id}: {exc}")
        except Exception as exc:  # noqa: BLE001 - anything else (RecursionError, MemoryError, the store) too
            return Loaded(seq, task_id, error=f"cannot start task {task_id}: {type(exc).__name__}: {exc}")
        return Loaded(seq, task_id, tree=tree)

    def _stored_blackboard(self, task_id: int):
        try:
            return self.store.get_task(task_id).get("blackboard")
        except RecordNotFound:
            return None

    def _adhoc_id(self) -> int:
        """A negative id no run, load or kept end has (called on the loader's thread; membership tests only)."""
        with self._adhoc_lock:
            while (self._next_adhoc in self.runs or self._next_adhoc in self._loading
                   or self._next_adhoc in self.status.ended):
                self._next_adhoc -= 1
            task_id, self._next_adhoc = self._next_adhoc, self._next_adhoc - 1
            return task_id

    def _take_loads(self) -> bool:
        """Start the trees the loader finished (on the tick's thread); True when a task's state changed."""
        idle = self.loader.pending == 0  # read before take(): a load finishes (appends) before it stops counting
        changed = False
        done = self.loader.take()
        if done:
            self._retire_ended()
        for loaded in done:
            changed = True
            task_id = loaded.task_id
            if task_id is not None and self._loading.get(task_id) == loaded.seq:
                del self._loading[task_id]
            if task_id is None:  # a /task_sequence message or entry that names no task
                self.get_logger().error(loaded.error)
                continue
            cancels = [c for c in (self._load_cancels.get(task_id), self._load_cancels.get(None))
                       if c is not None and loaded.seq <= c[0]]
            if loaded.error:
                self.get_logger().error(loaded.error)
                if task_id not in self.runs:  # else that run goes on, and reports its own end
                    self.status.record(task_id, TaskState.FAILURE, loaded.error)
            elif cancels:
                cancel = cancels[0]
                message = f"{cancel[1]} while its tree loaded (not started)"
                self.get_logger().warning(f"task {task_id}: {message}")
                self.status.record(task_id, TaskState.CANCELED, message)
            elif (run := self.runs.get(task_id)) is not None and not run.done:
                self.get_logger().warning(f"task {task_id} is already running; start ignored")
            else:
                tree = loaded.tree
                self.status.forget(task_id)
                self.runs[task_id] = TaskRun(task_id, tree, server_wait_s=self.server_wait_s)
                self.get_logger().info(f"task {task_id} started ({len(tree.nodes)} nodes, {len(tree.leaves)} leaves; "
                                       f"loaded in {loaded.seconds:.2f} s off the tick)")
        if idle:
            self._load_cancels.clear()  # no load asked before them is left
        return changed

    def _on_cancel(self, msg: Int32) -> None:
        task_id = int(msg.data)
        run = self.runs.get(task_id)
        if run is None or run.done:
            if task_id in self._loading or self.loader.pending:
                # a tree loading for it (a /task_sequence one's id is known only once it loaded): it never starts
                self._load_cancels[task_id] = (self._seq, "canceled by /tms_ts/cancel")
                self.get_logger().info(
                    f"cancel: task {task_id} is not running; if a tree loading now is task {task_id}, it will not start"
                )
                self._publish_status()
                return
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
        if self.loader.pending:  # no tree loading now may start after the emergency stop
            self._load_cancels[None] = (self._seq, "canceled by /emergency_signal")
        if active or self.loader.pending:
            self.get_logger().warning(f"emergency signal: canceling tasks {[r.task_id for r in active]}"
                                      f" and {self.loader.pending} tree load(s) under way")
            self._publish_status()

    def _on_snapshot_request(self, msg: Int32) -> None:
        self.status.request(int(msg.data))
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
        changed |= self._take_loads()
        if self.groot is not None:
            self._groot_follow()
            self.groot.end_of_tick()  # this tick's changes go out now (within the publisher's rate)
        took = (time.monotonic() - start) * 1000.0
        self._stats["ticks"] += 1
        self._stats["sum_tick_ms"] += took
        self._stats["max_tick_ms"] = max(self._stats["max_tick_ms"], took)
        if changed:
            self._publish_status()

    def _groot_follow(self) -> None:
        """Attach Groot to the chosen task's run (``groot_task_id``; -1: the earliest started still running)."""
        wanted = int(self.get_parameter("groot_task_id").value)
        current = self._groot_run
        if wanted != -1:
            run = self.runs.get(wanted)
            target = run if run is not None and (run is current or not run.done) else None
        elif current is not None and not current.done:
            target = current
        else:  # self.runs keeps the order the tasks started in
            target = next((r for r in self.runs.values() if not r.done), None)
        if target is None or target is current:
            return
        if current is not None and self.groot.listener in current.ctx.status_listeners:
            current.ctx.status_listeners.remove(self.groot.listener)
        self.groot.attach(target.tree.root)
        target.ctx.status_listeners.append(self.groot.listener)
        self._groot_run = target
        self.get_logger().info(f"Groot: task {target.task_id}'s tree ({len(target.tree.nodes)} nodes) on ports "
                               f"{self.groot.publisher_port} (publisher) / {self.groot.server_port} (server)")

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

    def _retire_ended(self) -> None:
        """Ended runs leave ``self.runs`` (tree, blackboard, goals dropped); their end stays in the status book."""
        for task_id, run in list(self.runs.items()):
            if run.done:
                self.status.retire(run)
                del self.runs[task_id]

    def _publish_status(self) -> None:
        self._retire_ended()
        loading = [(task_id, "tree being loaded off the tick") for task_id in self._loading]
        self.status_pub.publish(self.status.build(self.runs, loading, stamp=self.get_clock().now().to_msg()))

    def destroy_node(self) -> None:
        self.loader.close()  # a load under way finishes on its daemon thread; nothing starts it
        if any(not r.done for r in self.runs.values()):
            self.ros.wait_for_lock_listeners(timeout_s=1.0)  # the locks below must reach the converters
        for run in self.runs.values():
            if not run.done:
                run.cancel("manager shutting down")
        if self.groot is not None:
            self.groot.close()  # sends the last transitions (the cancels above), then releases both ports
        self.store.close()
        super().destroy_node()


def main() -> int:
    # stop_in_context: on SIGINT/SIGTERM destroy_node still cancels running tasks and engages their machines' locks.
    # events: the tick timer and the action clients' responses cost a fraction of the SingleThreadedExecutor's
    # wake (docs/performance.md, "Scheduler: 10 tasks at 50 Hz").
    return run_node(TaskManager, executor="events", stop_in_context=True)
