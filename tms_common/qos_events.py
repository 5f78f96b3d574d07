"""Poll a node's QoS-incompatibility event handlers once a second instead of on every executor wake.

rclpy gives every publisher and subscription default handlers for the "incompatible QoS" and "incompatible
type" events (they log a warning when a peer cannot be matched). Each is a waitable that the
SingleThreadedExecutor enters, counts, adds to a fresh wait set and checks again on *every* wake, whether or
not anything happened. A converter node with 5 publishers and 7 subscriptions carries 28 of them; on this
2-core VM, at 300 wakes/s, taking them out left 0.58-0.68 of its executor CPU in four runs (e.g. 37 % -> 22 %
of a core; ``python -m tests.bench executor_wake``).

:func:`defer_qos_incompatibility_events` takes those handlers, and only those (deadline, liveliness,
message-lost and matched events keep their place in the wait set: their timing can matter), out of the
executor's wait set and checks them from one steady-clock timer, so the warnings still appear, at most ``period_s``
late.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any

from tms_common import rclpy_compat

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node

__all__ = ["defer_qos_incompatibility_events", "INCOMPATIBILITY_EVENTS"]

INCOMPATIBILITY_EVENTS = (
    "RCL_SUBSCRIPTION_REQUESTED_INCOMPATIBLE_QOS",
    "RCL_SUBSCRIPTION_INCOMPATIBLE_TYPE",
    "RCL_PUBLISHER_OFFERED_INCOMPATIBLE_QOS",
    "RCL_PUBLISHER_INCOMPATIBLE_TYPE",
)


class _DeferredEvents:
    """The handlers taken out of one node's wait set and the timer that polls them with a zero-timeout wait set.

    The handlers stay among the node's waitables (``destroy_publisher``/``destroy_subscription`` remove them
    from there); they are only parked (:func:`tms_common.rclpy_compat.park`), so the executor skips them at
    the cost of one ``can_execute`` call each.
    """

    def __init__(self, node: Node, period_s: float) -> None:
        from rclpy.clock import Clock, ClockType

        self._node = node
        self.handlers: list[Any] = []
        self.timer = node.create_timer(period_s, self.poll, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def take_from_node(self) -> int:
        import inspect

        from rclpy.event_handler import EventHandler

        moved = 0
        for waitable in list(self._node.waitables):
            if (isinstance(waitable, EventHandler)
                    and not rclpy_compat.is_parked(waitable)
                    and getattr(waitable.event_type, "name", "") in INCOMPATIBILITY_EVENTS
                    and not inspect.iscoroutinefunction(waitable.callback)):  # poll() calls it synchronously
                rclpy_compat.park(waitable)
                self.handlers.append(waitable)
                moved += 1
        return moved

    def poll(self) -> None:
        """Wait on the handlers for zero time and run the callback of each that is ready."""
        alive = {id(w) for w in self._node.waitables}
        self.handlers = [h for h in self.handlers if id(h) in alive]  # destroyed with their publisher/subscription
        for handler in rclpy_compat.poll_ready(self._node.context, self.handlers):
            data = handler.take_data()
            if data:
                handler.callback(data)


_pollers: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # node -> its _DeferredEvents


def defer_qos_incompatibility_events(node: Node, period_s: float = 1.0) -> int:
    """Take ``node``'s incompatible-QoS/-type handlers out of its executor's wait set; poll them every ``period_s``.

    Returns how many handlers were moved (0 on an rclpy other than the tested one: the handlers stay where
    rclpy put them). Handlers created later (a publisher made after this call) stay where rclpy put them;
    call again to move them too.
    """
    if not rclpy_compat.use_internals("polling QoS-incompatibility events off the executor"):
        return 0
    deferred = _pollers.get(node)
    if deferred is None:
        deferred = _pollers[node] = _DeferredEvents(node, period_s)
    return deferred.take_from_node()
