"""The goals an action server is executing, for its ``run_node`` stop hook (``on_stop_requested``).

A server stopped in context (``run_node(stop_in_context=True)``) cancels what its running goals wait on and
keeps spinning until they have ended. :class:`RunningGoals` holds what that takes: a count of running goals
(``with goals.running():`` around each execute callback), the ``stopping`` event the goals' waits look at,
and the deadline after which the node stops anyway.

:data:`OUTCOME_QOS` is the profile of the topics where our servers publish each goal's typed outcome beside
a peer's poorer result type (``/<model>/subtask_outcome``, ``/<model>/tms_rp_zx200_outcome``).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["RunningGoals", "OUTCOME_QOS"]

#: reliable, and kept for a subscriber matched late: the first goal after start-up may end before discovery
#: has matched the client's subscription (publisher and subscriber must both use it: durability must match)
OUTCOME_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class RunningGoals:
    """Running-goal count and stop state of one node (thread-safe)."""

    def __init__(self) -> None:
        self.stopping = threading.Event()  # set on the first stop request; never cleared
        self._count = 0
        self._lock = threading.Lock()
        self._deadline = 0.0

    @contextlib.contextmanager
    def running(self) -> Iterator[None]:
        """Count the goal executed inside the block."""
        with self._lock:
            self._count += 1
        try:
            yield
        finally:
            with self._lock:
                self._count -= 1

    def wind_down(self, timeout_s: float, on_first: Callable[[int], None] | None = None) -> bool:
        """The stop hook's answer: True while a goal still runs and ``timeout_s`` since the first call has not passed.

        The first call sets :attr:`stopping` and calls ``on_first(n)`` with the number of running goals when
        there are any (to log what is being canceled).
        """
        if not self.stopping.is_set():
            self._deadline = time.monotonic() + timeout_s
            self.stopping.set()
            with self._lock:
                count = self._count
            if count and on_first is not None:
                on_first(count)
        with self._lock:
            return self._count > 0 and time.monotonic() < self._deadline
