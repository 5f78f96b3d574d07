"""What ``/tms_ts/status`` carries, kept bounded: finished tasks leave after a retention, tree snapshots are sent
on change (no rclpy; builds tms_msg messages).

Each ``tms_msg/TaskStatus`` lists every task the manager runs or loads, and the tasks that ended within the
retention:

* a running task: its state, running leaves and message every time; its ``tree_snapshot`` only when the
  snapshot differs from the last one this book sent for it, or when one was asked for (:meth:`StatusBook.request`),
  else empty;
* a task whose tree is still loading (:mod:`tms_ts.tree_loading`): RUNNING, message ``loading: ...``;
* a finished task: its final state and message for ``retention_s`` seconds (wall) after it ended, and always
  in at least one message; at most the ``keep_max`` that ended last. Its final snapshot goes out once, with the
  first message that reports the end (again on request while it is kept). The run itself (tree, blackboard,
  goals) is dropped when it ends.

A snapshot is one line per node (``tms_ts.loader.Tree.snapshot``'s form), at most ``snapshot_max_nodes`` lines, then
``... N more nodes``: for display, its cost per status is bounded whatever the tree's size. Before, every message
carried every run's full snapshot, finished runs were never dropped, and a 5 MB tree's manager grew 30 MB/s.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from tms_msg.msg import TaskState, TaskStatus
from tms_ts.bt.core import IDLE, RUNNING, Status
from tms_ts.task import CANCELED, FAILED, SUCCEEDED, TaskRun

__all__ = ["StatusBook", "snapshot_text", "ALL_TASKS"]

#: :meth:`StatusBook.request` for every task
ALL_TASKS = -1

_STATE = {SUCCEEDED: TaskState.SUCCESS, FAILED: TaskState.FAILURE, CANCELED: TaskState.CANCELED}
_LETTERS = {IDLE: "I", RUNNING: "R", Status.SUCCESS: "S", Status.FAILURE: "F"}


def snapshot_text(root, max_nodes: int, total: int | None = None) -> str:  # a tms_ts.bt.core.BtNode
    """One line per node, depth first (indentation, id, name, ``[I/R/S/F]``), at most ``max_nodes`` lines.

    Iterative: a tree of any depth. ``total`` (the tree's node count, when known) names how many were left out.
    """
    lines: list[str] = []
    stack = [(root, 0)]
    while stack and len(lines) < max_nodes:
        node, depth = stack.pop()
        name = f" '{node.name}'" if node.name != node.node_id else ""
        lines.append(f"{'  ' * depth}{node.node_id}{name} [{_LETTERS.get(node.status, '?')}]")
        stack.extend((child, depth + 1) for child in reversed(node.children))
    if stack:
        more = f"{total - len(lines)} more nodes" if total is not None else "more nodes"
        lines.append(f"... {more} (snapshot_max_nodes {max_nodes})")
    return "\n".join(lines)


@dataclass
class _Ended:
    state: TaskState
    ended: float
    snapshot: str = ""
    snapshot_sent: bool = False
    published: bool = False


class StatusBook:
    """The manager's status bookkeeping (see the module docstring); used from the tick's thread only."""

    def __init__(self, *, retention_s: float = 60.0, keep_max: int = 100, snapshot_max_nodes: int = 2000,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if retention_s < 0 or keep_max < 1 or snapshot_max_nodes < 1:
            raise ValueError(f"StatusBook: retention_s >= 0, keep_max >= 1, snapshot_max_nodes >= 1 "
                             f"(got {retention_s}, {keep_max}, {snapshot_max_nodes})")
        self.retention_s = retention_s
        self.keep_max = keep_max
        self.snapshot_max_nodes = snapshot_max_nodes
        self.clock = clock
        #: ended tasks, oldest end first
        self.ended: OrderedDict[int, _Ended] = OrderedDict()
        self._sent: dict[int, str] = {}  # running task id -> the snapshot last sent for it
        self._requested: set[int] = set()
        self._request_all = False

    # -- input -----------------------------------------------------------------------------------
    def snapshot(self, run: TaskRun) -> str:
        tree = run.tree
        return snapshot_text(tree.root, self.snapshot_max_nodes, len(getattr(tree, "nodes", ())) or None)

    def retire(self, run: TaskRun) -> None:
        """``run`` ended: keep its final state (and snapshot, to send once); the run itself is the caller's to drop."""
        state = TaskState(task_id=run.task_id, state=_STATE.get(run.state, TaskState.FAILURE), message=run.message)
        self._add(run.task_id, _Ended(state, self.clock(), snapshot=self.snapshot(run)))

    def record(self, task_id: int, state: int, message: str) -> None:
        """A start that ended before any run existed (its tree did not load, it was canceled while loading)."""
        self._add(task_id, _Ended(TaskState(task_id=task_id, state=state, message=message), self.clock()))

    def _add(self, task_id: int, entry: _Ended) -> None:
        self._sent.pop(task_id, None)
        self.ended.pop(task_id, None)
        self.ended[task_id] = entry
        self._prune()

    def forget(self, task_id: int) -> None:
        """``task_id`` starts again: its earlier end leaves the status."""
        self.ended.pop(task_id, None)
        self._sent.pop(task_id, None)

    def request(self, task_id: int) -> None:
        """The next status carries ``task_id``'s snapshot (:data:`ALL_TASKS`: every task's) even if unchanged."""
        if task_id == ALL_TASKS:
            self._request_all = True
        else:
            self._requested.add(task_id)

    # -- output ----------------------------------------------------------------------------------
    def _prune(self) -> None:
        while len(self.ended) > self.keep_max:  # the oldest ends leave first
            self.ended.popitem(last=False)
        now = self.clock()
        for task_id in [t for t, e in self.ended.items() if e.published and now - e.ended > self.retention_s]:
            del self.ended[task_id]

    def build(self, runs: Mapping[int, TaskRun], loading: Iterable[tuple[int, str]] = (), *,
              stamp=None) -> TaskStatus:  # builtin_interfaces/Time
        """The status message now; marks what it sends as sent."""
        self._prune()
        msg = TaskStatus()
        if stamp is not None:
            msg.stamp = stamp
        wanted = self._requested
        every = self._request_all
        self._requested, self._request_all = set(), False
        active = set()
        for task_id, run in sorted(runs.items()):
            if run.done:  # ended, not yet retired by the caller
                continue
            active.add(task_id)
            state = TaskState(task_id=task_id, state=TaskState.RUNNING)
            state.message = f"{run.state}: {run.message}" if run.message else run.state
            state.running_leaves = run.running_leaves()
            snap = self.snapshot(run)
            if every or task_id in wanted or self._sent.get(task_id) != snap:
                state.tree_snapshot = snap
                self._sent[task_id] = snap
            msg.tasks.append(state)
        for task_id, what in sorted(loading):
            if task_id not in active:
                active.add(task_id)
                msg.tasks.append(TaskState(task_id=task_id, state=TaskState.RUNNING, message=f"loading: {what}"))
        for task_id in [t for t in self._sent if t not in active]:
            del self._sent[task_id]
        for task_id, entry in sorted(self.ended.items()):
            if task_id in active:
                continue
            state = TaskState(task_id=task_id, state=entry.state.state, message=entry.state.message)
            if entry.snapshot and (not entry.snapshot_sent or every or task_id in wanted):
                state.tree_snapshot = entry.snapshot
                entry.snapshot_sent = True
            entry.published = True
            msg.tasks.append(state)
        return msg
