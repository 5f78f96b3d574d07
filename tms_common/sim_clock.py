"""Feed a simulated-time node's clock from a small node in a thread of its own, off the node's executor.

With ``use_sim_time`` rclpy subscribes the node itself to ``/clock``, so its executor wakes for every
``/clock`` message (50 per simulated second in the paper launch, 150 a second at 3x) and on each wake
rebuilds and checks its whole wait set: every subscription, timer, service, action client and server.
A task manager with a dozen action clients or a supervisor with seven subscriptions pays that for a
message whose only effect is to advance the clock.

:func:`relay_clock` moves that subscription to a helper node (``<name>_clock``, one subscription, no
parameter services, no rosout) that a daemon thread waits on with a bare rcl wait set. The helper sets the node's
clock (:meth:`rclpy.clock.ROSClock.set_ros_time_override`), and rcl wakes the node's executor only when
one of its timers falls due (rcl triggers a simulated-time timer's guard condition when the clock jumps
past its call time) or a message or request arrives. Timers fire at the same simulated times as before.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node

__all__ = ["ClockRelay", "relay_clock"]

_WAIT_NS = 1_000_000_000  # the relay thread re-checks its stop flag at least once a second


class ClockRelay:
    """The helper node, the thread that waits on its ``/clock`` subscription, and :meth:`close` to stop them.

    The thread waits on a two-entity rcl wait set (the subscription and a stop guard condition) directly:
    an rclpy executor costs about as much per wake as the node's own did, whatever its size.
    """

    def __init__(self, node: Node, own_subscription: Any) -> None:
        import rclpy
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rclpy.time_source import CLOCK_TOPIC
        from rosgraph_msgs.msg import Clock

        self._clock = node.get_clock()
        self._logger = node.get_logger()
        self._context = node.context
        self.helper = rclpy.create_node(
            f"{node.get_name()}_clock", namespace=node.get_namespace(), context=node.context,
            use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self.received = 0
        # rclpy's own /clock QoS (rclpy.time_source): best effort, keep the last one
        self._sub = self.helper.create_subscription(Clock, CLOCK_TOPIC, lambda _msg: None,
                                                    QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        self._wake = self.helper.create_guard_condition(lambda: None)
        self._stop = threading.Event()
        self._context.on_shutdown(self._wake_up)  # rclpy's signal handler shuts the context down: leave the wait
        # the helper subscribes first: no /clock message falls between the two subscriptions
        node.destroy_subscription(own_subscription)
        self._thread: threading.Thread | None = threading.Thread(target=self._run, name="clock_relay", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
        from rclpy.time import Time

        sub, wake, clock = self._sub, self._wake, self._clock
        try:
            while not self._stop.is_set():
                with self._context.handle, sub.handle, wake.handle:
                    wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self._context.handle)
                    wait_set.add_subscription(sub.handle)
                    wait_set.add_guard_condition(wake.handle)
                    wait_set.wait(_WAIT_NS)
                    ready = sub.handle.pointer in wait_set.get_ready_entities("subscription")
                    taken = sub.handle.take_message(sub.msg_type, False) if ready else None
                if taken is not None:
                    self.received += 1
                    clock.set_ros_time_override(Time.from_msg(taken[0].clock))
        except Exception as exc:  # the context or the helper went away under us (shutdown): stop relaying
            if not self._stop.is_set() and self._context.ok():
                self._logger.error(f"clock relay failed, simulated time no longer advances: {type(exc).__name__}: {exc}")
                raise

    def _wake_up(self) -> None:
        self._stop.set()
        if self._thread is not None:  # after close() the guard condition is destroyed
            self._wake.trigger()

    def close(self) -> None:
        """Stop the thread and destroy the helper node (idempotent)."""
        if self._thread is None:
            return
        self._wake_up()
        self._thread.join(timeout=2.0)
        self._thread = None
        self.helper.destroy_node()


def relay_clock(node: Node) -> ClockRelay | None:
    """Move ``node``'s ``/clock`` subscription to a :class:`ClockRelay`; None when the node is on wall time.

    The node's TimeSource keeps its parameter callback: ``use_sim_time`` set false later still switches the
    clock back to system time (the relay's updates are then ignored by the clock).
    """
    from rclpy.time_source import CLOCK_TOPIC

    own = [s for s in node.subscriptions if s.topic_name == CLOCK_TOPIC]
    if not own:
        return None
    return ClockRelay(node, own[0])
