"""rclpy nodes of tms_ts: the task scheduler manager and the subtask action servers."""

from __future__ import annotations

import sys
from collections.abc import Callable


def run_threaded(factory: Callable[[], object], threads: int = 16) -> int:
    """Like :func:`tms_common.node.run_node` but with a MultiThreadedExecutor of ``threads`` threads.

    Action servers whose execute callbacks wait for a downstream goal occupy one executor thread per
    goal; rclpy's default (one thread per CPU, 2 here) deadlocks as soon as two goals run at once,
    because no thread is left to deliver the downstream responses and cancel requests.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

    rclpy.init(args=sys.argv)
    node = None
    try:
        node = factory()
        executor = MultiThreadedExecutor(num_threads=threads)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:  # noqa: BLE001 - report any crash with the node's name, then exit non-zero
        name = node.get_name() if node is not None else getattr(factory, "__name__", "node")
        print(f"[{name}] fatal: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        import traceback

        traceback.print_exc()
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
