"""Feed a simulated-time node's clock from a small node in a thread of its own, off the node's executor.

With ``use_sim_time`` rclpy subscribes the node itself to ``/clock``, so its executor wakes for every
``/clock`` message (50 per simulated second in the paper launch, 150 a second at 3x) and on each wake
rebuilds and checks its whole wait set: every subscription, timer, service, action client and server.
A task manager with a dozen action clients or a supervisor with seven subscriptions pays that for a
message whose only effect is to advance the clock.

:func:`relay_clock` parks that subscription outside the node's executor and a daemon thread waits on it
with a bare rcl wait set (no helper node: ``ros2 node list`` shows only the node). The thread sets the node's
clock (:meth:`rclpy.clock.ROSClock.set_ros_time_override`), and rcl wakes the node's executor only when
one of its timers falls due (rcl triggers a simulated-time timer's guard condition when the clock jumps
past its call time) or a message or request arrives. Timers fire at the same simulated times as before.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

from tms_common import rclpy_compat

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node

__all__ = ["ClockRelay", "on_simulated_time", "relay_clock", "share_time_source"]

_WAIT_NS = 1_000_000_000  # the relay thread re-checks its stop flag at least once a second


class ClockRelay:
    """The thread that waits on a node's ``/clock`` subscription and sets its clock, and :meth:`close` to stop it.

    The subscription stays the node's own (rclpy's TimeSource made it) but is parked outside the node's
    executor (:func:`tms_common.rclpy_compat.park`); the thread waits on it and a wake-up guard condition
    with a two-entity rcl wait set (:class:`tms_common.rclpy_compat.SubscriptionWaiter`): an rclpy executor
    costs about as much per wake as the node's own did, whatever its size. No helper node: the graph shows
    only the node itself.
    """

    def __init__(self, node: Node, subscription: Any) -> None:
        self._clocks = [node.get_clock()]
        self._logger = node.get_logger()
        self._context = node.context
        self.subscription = subscription
        self.received = 0
        self._waiter = rclpy_compat.SubscriptionWaiter(subscription, node.context)
        self._stop = threading.Event()
        self._context.on_shutdown(self._wake_up)  # rclpy's signal handler shuts the context down: leave the wait
        rclpy_compat.park(subscription)
        self._thread: threading.Thread | None = threading.Thread(target=self._run, name="clock_relay", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from rclpy.time import Time

        waiter, clocks = self._waiter, self._clocks
        try:
            while not self._stop.is_set():
                msg = waiter.wait_take(_WAIT_NS)
                if msg is not None:
                    self.received += 1
                    now = Time.from_msg(msg.clock)
                    for clock in tuple(clocks):
                        clock.set_ros_time_override(now)
        except rclpy_compat.SubscriptionDestroyed:
            pass  # the node is being destroyed, or use_sim_time was set false (the clock ignores overrides then)
        except Exception as exc:  # the context or the subscription went away under us (shutdown): stop relaying
            if not self._stop.is_set() and self._context.ok():
                self._logger.error(
                    f"clock relay failed, simulated time no longer advances: {type(exc).__name__}: {exc}"
                )
                raise

    def follow(self, node: Node) -> bool:
        """Also set ``node``'s clock (another node of this process on simulated time) and park its own ``/clock``
        subscription: one relay and one ``/clock`` subscription per process, however many nodes it hosts.
        False (nothing changed) when ``node`` is on wall time."""
        from rclpy.time_source import CLOCK_TOPIC

        own = [s for s in node.subscriptions if s.topic_name == CLOCK_TOPIC]
        if not own:
            return False
        rclpy_compat.park(own[0])
        self._clocks.append(node.get_clock())
        return True

    def unfollow(self, node: Node) -> None:
        """Stop setting ``node``'s clock (before it is destroyed)."""
        clock = node.get_clock()
        self._clocks[:] = [c for c in self._clocks if c is not clock]

    def _wake_up(self) -> None:
        self._stop.set()
        if self._thread is not None:  # after close() the guard condition is destroyed
            self._waiter.wake()

    def close(self) -> None:
        """Stop the thread (idempotent); the subscription stays the node's, destroyed with it."""
        if self._thread is None:
            return
        self._wake_up()
        self._thread.join(timeout=2.0)
        self._thread = None
        self._waiter.destroy()


def relay_clock(node: Node) -> ClockRelay | None:
    """Move ``node``'s ``/clock`` subscription to a :class:`ClockRelay`; None when the node is on wall time.

    The node's TimeSource keeps its parameter callback: ``use_sim_time`` set false later still switches the
    clock back to system time (the relay's updates are then ignored by the clock).
    """
    from rclpy.time_source import CLOCK_TOPIC

    own = [s for s in node.subscriptions if s.topic_name == CLOCK_TOPIC]
    if not own or not rclpy_compat.use_internals("relaying /clock off the executor"):
        return None
    return ClockRelay(node, own[0])


def on_simulated_time(node: Node) -> bool:
    """True when ``node`` holds its own ``/clock`` subscription (rclpy's TimeSource made it: use_sim_time)."""
    from rclpy.time_source import CLOCK_TOPIC

    return any(s.topic_name == CLOCK_TOPIC for s in node.subscriptions)


def share_time_source(leader: Node, follower: Node) -> bool:
    """Drop ``follower``'s own ``/clock`` subscription and let ``leader``'s TimeSource set its clock.

    For nodes spun by one EventsExecutor, where :class:`ClockRelay` cannot park a subscription: every node on
    simulated time otherwise holds a ``/clock`` subscription of its own, and every one of them is a DDS reader
    the clock's publisher serves and a callback this process runs, 50 times per simulated second each. Both
    must be on simulated time; False (nothing changed) when either is not. The follower's TimeSource keeps its
    parameter callback (``use_sim_time`` set false still switches its clock to system time).
    """
    if leader is follower or not (on_simulated_time(leader) and on_simulated_time(follower)):
        return False
    if not rclpy_compat.use_internals("one /clock subscription per container"):
        return False
    follower._time_source.detach_node()  # rclpy gives no accessor; destroys its subscription
    leader._time_source.attach_clock(follower.get_clock())
    return True
