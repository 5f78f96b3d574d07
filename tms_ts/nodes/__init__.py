"""rclpy nodes of tms_ts: the task scheduler manager and the subtask action servers."""

from __future__ import annotations

from collections.abc import Callable

from tms_common.node import run_node


def run_threaded(factory: Callable[[], object], threads: int = 16, *, stop_in_context: bool = False) -> int:
    """:func:`tms_common.node.run_node` with a MultiThreadedExecutor of ``threads`` threads.

    Action servers whose execute callbacks wait for a downstream goal occupy one executor thread per
    goal; rclpy's default (one thread per CPU, 2 here) deadlocks as soon as two goals run at once,
    because no thread is left to deliver the downstream responses and cancel requests.
    """
    return run_node(factory, executor="multi", threads=threads, stop_in_context=stop_in_context)
