"""Task trees loaded off the manager's tick: one worker thread builds them, the tick takes them over (no rclpy).

The manager (:mod:`tms_ts.nodes.tms_ts_manager`) ticks every task from one executor thread; a tree read from the
DB or from ``/task_sequence`` is parsed, checked and built here instead, on a thread of its own, so a large
tree never holds up the tick, a cancel or an emergency stop (a 5 MB tree took 5.5 s on the executor: 181
missed ticks). The tick collects finished loads (:meth:`TreeLoadWorker.take`) and starts them there, where every
other task is driven, so a tree is touched by one thread at a time: the worker until it hands it over, then
the tick.

Loads run one after the other, in the order they were asked for; at most ``max_pending`` wait (a start beyond
that is refused, naming the limit). Anything a load raises, :class:`~tms_ts.errors.TsError` or not (a
``RecursionError``, a ``MemoryError``), ends that start with a :class:`Loaded` carrying the error: never the
worker, never the manager.

The worker shares the interpreter with the tick (one GIL): a pure-Python load that runs while the tick waits
for the GIL gives it up after the interpreter's switch interval (5 ms by default), so each time the tick
thread re-takes the GIL it may wait up to that long. ``tests/bench/bench_tms_ts_load.py`` measures what that
costs the tick.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["LoadRequest", "Loaded", "TreeLoadWorker"]


@dataclass
class LoadRequest:
    """One start to load: ``/tms_ts/start``'s ids (``data`` None: their trees from the DB; else ``data`` is the tree),
    or a ``/task_sequence`` message (``task_ids`` empty, ``data`` the message)."""

    seq: int
    task_ids: tuple[int, ...] = ()
    data: str | None = None
    #: the manager's ``task_id`` parameter when the /task_sequence message came (it is read per message)
    param_task_id: int = -1
    asked: float = field(default_factory=time.monotonic)


@dataclass
class Loaded:
    """A finished load: a tree to start under ``task_id``, or ``error`` (``task_id`` None: no id was found)."""

    seq: int
    task_id: int | None
    tree: Any = None
    error: str = ""
    seconds: float = 0.0


class TreeLoadWorker:
    """Runs ``load(request)`` (which yields :class:`Loaded`, one per tree) for each submitted request, in order."""

    def __init__(self, load: Callable[[LoadRequest], Iterable[Loaded]], *, max_pending: int = 16,
                 name: str = "tms_ts_tree_loader") -> None:
        if max_pending < 1:
            raise ValueError(f"max_pending must be >= 1, got {max_pending}")
        self._load = load
        self.max_pending = max_pending
        self._requests: queue.SimpleQueue[LoadRequest | None] = queue.SimpleQueue()
        self._done: collections.deque[Loaded] = collections.deque()
        self._lock = threading.Lock()
        self._pending = 0
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    @property
    def pending(self) -> int:
        """Requests submitted and not finished yet (their last tree not yet in :meth:`take`)."""
        with self._lock:
            return self._pending

    def submit(self, request: LoadRequest) -> bool:
        """Queue ``request``; False (nothing queued) when ``max_pending`` loads already wait or the worker is closed."""
        with self._lock:
            if self._closed or self._pending >= self.max_pending:
                return False
            self._pending += 1
        self._requests.put(request)
        return True

    def take(self) -> list[Loaded]:
        """Every load finished since the last call, in the order they finished (never blocks)."""
        out = []
        while True:
            try:
                out.append(self._done.popleft())
            except IndexError:
                return out

    def close(self) -> None:
        """Stop after the current load (a load cannot be interrupted; the thread is a daemon)."""
        with self._lock:
            self._closed = True
        self._requests.put(None)

    def join(self, timeout: float | None = None) -> bool:
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        while True:
            request = self._requests.get()
            if request is None:
                return
            handed: set[int | None] = set()
            try:
                start = time.monotonic()
                for result in self._load(request):
                    result.seconds = time.monotonic() - start
                    handed.add(result.task_id)
                    self._done.append(result)
                    start = time.monotonic()
            except BaseException as exc:  # noqa: BLE001 - whatever a load raises ends that start, not the worker
                error = f"loading raised {type(exc).__name__}: {exc}"
                left = [t for t in request.task_ids if t not in handed] or ([None] if not request.task_ids else [])
                for task_id in left:
                    what = f"task {task_id}" if task_id is not None else "/task_sequence"
                    self._done.append(Loaded(request.seq, task_id, error=f"cannot start {what}: {error}"))
            finally:
                with self._lock:
                    self._pending -= 1
