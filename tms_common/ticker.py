"""A wall-clock tick that async execute callbacks await between their checks, on one executor thread.

An action server whose goals wait on a downstream goal runs them as coroutines on a single-threaded executor
(as ``excavator_arm_controller`` does) instead of parking one thread of a large pool per goal in a sleep loop.
A coroutine that must also watch things no future reports (a cancel request, a stop, a server vanishing from
the graph, a deadline) awaits :meth:`Ticker.next` between its checks: the future completes at the next tick,
or at once on :meth:`Ticker.wake` (a cancel callback calls it) or when a future given to
:meth:`Ticker.wake_on` is done (a downstream result does not wait for the tick).

The timer runs on the steady clock (a goal's waits are wall time, also under ``use_sim_time``) and only while
someone waits, so an idle node does not wake. Use from the executor's thread only. Imports rclpy.
"""

from __future__ import annotations

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future

__all__ = ["Ticker"]


class Ticker:
    """Futures completed every ``period_s`` [s wall] while any is awaited."""

    def __init__(self, node: Node, period_s: float, callback_group=None) -> None:
        if not period_s > 0:
            raise ValueError(f"Ticker: period_s must be > 0, got {period_s}")
        self._waiters: list[Future] = []
        self._timer = node.create_timer(period_s, self._fire, callback_group=callback_group,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._timer.cancel()

    def next(self) -> Future:
        """A future completed at the next tick (await it)."""
        future = Future()
        self._waiters.append(future)
        if self._timer.is_canceled():
            self._timer.reset()
        return future

    def wake(self) -> None:
        """Complete every awaited tick now (something a waiting goal looks at has changed: a cancel came)."""
        self._fire()

    def wake_on(self, future: Future) -> Future:
        """Wake the waiters as soon as ``future`` is done (a result or goal response), not at the next tick."""
        future.add_done_callback(lambda _f: self.wake())
        return future

    def _fire(self) -> None:
        pending, self._waiters = self._waiters, []
        if not pending:
            self._timer.cancel()  # nobody waited a whole period: sleep until the next next()
        for future in pending:
            if not future.done():
                future.set_result(None)
