"""One task run: a built tree plus the start / tick / cancel / stop life cycle (no rclpy).

States: ``starting`` (waiting, bounded, for every leaf's subtask server), ``running`` (ticked once per
scheduler period), ``stopping`` (halted after a cancel or an error; waiting until every halted subtask
confirms its stop, see :func:`tms_ts.leaf.poll_stops`), then one of ``success``, ``failure``,
``canceled``. A cancelled task ends ``canceled`` (never ``failure``) once its machines are at rest.
A cancel first engages the hydraulic lock (``/<model>/lock``) of every machine with a goal in flight,
so the machine stops within the lock response instead of the command path's dead time.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from tms_ts.bt.core import FAILURE, SUCCESS
from tms_ts.errors import TsError
from tms_ts.leaf import TERMINAL, poll_stops
from tms_ts.loader import Tree

__all__ = ["TaskRun", "STARTING", "RUNNING", "STOPPING", "SUCCEEDED", "FAILED", "CANCELED", "FINAL"]

log = logging.getLogger(__name__)

STARTING, RUNNING, STOPPING = "starting", "running", "stopping"
SUCCEEDED, FAILED, CANCELED = "success", "failure", "canceled"
FINAL = frozenset({SUCCEEDED, FAILED, CANCELED})


class TaskRun:
    """Drives one tree; call :meth:`step` once per scheduler tick."""

    def __init__(self, task_id: int, tree: Tree, *, server_wait_s: float = 5.0,
                 clock: Callable[[], float] | None = None) -> None:
        self.task_id = task_id
        self.tree = tree
        self.ctx = tree.ctx
        self.clock = clock or self.ctx.clock
        self.state = STARTING
        self.message = "waiting for subtask servers"
        self.started = self.clock()
        self.start_deadline = self.started + server_wait_s
        self.ticks = 0
        self._after_stop = CANCELED

    @property
    def done(self) -> bool:
        return self.state in FINAL

    def missing_servers(self) -> list[str]:
        """``/<model>/<subtask> (leaf)`` for each leaf whose server is not (yet) available."""
        ros = self.ctx.ros
        missing: dict[str, str] = {}
        for leaf in self.ctx.leaves:
            if leaf.action in missing:
                continue
            if ros is None or not ros.subtask_server_ready(leaf.model_name, leaf.subtask_name):
                missing[leaf.action] = f"{leaf.action} (used by {leaf.describe()})"
        return list(missing.values())

    def step(self) -> str:
        """Advance one tick; returns the state afterwards. Nothing it raises leaves it: an error of this task (its
        servers' check, its stops, the ROS side) ends this task FAILURE, never another task or the manager."""
        try:
            return self._step()
        except TsError as exc:
            log.error("task %s: %s: %s", self.task_id, type(exc).__name__, exc)
            self._abort(f"{type(exc).__name__}: {exc}")
        except Exception as exc:  # one task's error must not end the manager's timer
            log.exception("task %s: step raised", self.task_id)
            self._abort(f"{type(exc).__name__}: {exc}")
        return self.state

    def _abort(self, message: str) -> None:
        """End FAILURE after an error outside the tree's tick: halted as after a failed tick (halted goals still
        confirm their stop), or, when the error came while stopping, at once."""
        if self.state != STOPPING:
            try:
                self._stop(FAILED, message)
                return
            except Exception:  # the task ends anyway; the halt's error is logged
                log.exception("task %s: halt after an error raised", self.task_id)
        self.ctx.stops.clear()
        self._finish(FAILED, message)

    def _step(self) -> str:
        if self.state == STARTING:
            missing = self.missing_servers()
            if missing:
                if self.clock() >= self.start_deadline:
                    self._finish(FAILED, "subtask server not available: " + "; ".join(missing))
                return self.state
            self.state, self.message = RUNNING, ""
        if self.state == RUNNING:
            self._tick()
        if self.state == STOPPING and poll_stops(self.ctx):
            outcomes = [s.outcome for s in self.ctx.stops if s.outcome]
            self.ctx.stops.clear()
            detail = f" ({'; '.join(outcomes)})" if outcomes else ""
            self._finish(self._after_stop, self.message + detail)
        return self.state

    def _tick(self) -> None:
        self.ticks += 1
        try:
            status = self.tree.tick()
        except TsError as exc:  # a tree's own error (as BehaviorTree.CPP's nodes throw): its message says it all
            log.error("task %s: %s: %s", self.task_id, type(exc).__name__, exc)
            self._stop(FAILED, f"{type(exc).__name__}: {exc}")
            return
        except Exception as exc:  # any node error ends the task, never the manager
            log.exception("task %s: tick raised", self.task_id)
            self._stop(FAILED, f"{type(exc).__name__}: {exc}")
            return
        poll_stops(self.ctx)  # halts inside the tree (ReactiveSequence, Timeout...) resolve here too
        if status is SUCCESS:
            self._stop(SUCCEEDED, "task finished")
        elif status is FAILURE:
            reason = self.ctx.failures[-1] if self.ctx.failures else "the root returned FAILURE"
            self._stop(FAILED, reason)

    def cancel(self, reason: str = "canceled") -> None:
        """Halt the tree; the run ends CANCELED once every halted subtask confirmed its stop."""
        if self.done or self.state == STOPPING:
            return
        if self.state == STARTING:
            self._finish(CANCELED, reason)
            return
        try:
            self.lock_active_machines(reason)
            self._stop(CANCELED, reason)
        except Exception as exc:  # a cancel comes from a subscription callback: never end the manager
            log.exception("task %s: cancel raised", self.task_id)
            self.ctx.stops.clear()
            self._finish(FAILED, f"{reason}; halting the tree raised {type(exc).__name__}: {exc}")

    def active_machines(self) -> list[str]:
        """Model names of the leaves with a goal in flight (sent, not finished)."""
        return sorted({leaf.model_name for leaf in self.ctx.leaves
                       if leaf.goal is not None and leaf.goal.state not in TERMINAL})

    def lock_active_machines(self, reason: str) -> None:
        """Engage the hydraulic lock of every machine this task is driving (ports without ``lock``: no-op)."""
        lock = getattr(self.ctx.ros, "lock", None)
        if lock is None:
            return
        for model in self.active_machines():
            lock(model, True, f"task {self.task_id}: {reason}")

    def _stop(self, final: str, message: str) -> None:
        self.tree.halt()
        self._after_stop, self.message, self.state = final, message, STOPPING
        if poll_stops(self.ctx):
            self.ctx.stops.clear()
            self._finish(final, message)

    def _finish(self, final: str, message: str) -> None:
        self.state, self.message = final, message
        log.info("task %s ended %s: %s", self.task_id, final, message)

    def running_leaves(self) -> list[str]:
        leaves = self.tree.running_leaves()
        if self.state == STOPPING:
            leaves += [f"stopping {s.leaf.action}" for s in self.ctx.stops if not s.resolved]
        return leaves
