"""Every reach into rclpy internals, in one place, guarded by the rclpy version it was written against.

The platform saves executor work in three places by going below rclpy's public API:

* :mod:`tms_common.qos_events` polls event handlers with a bare rcl wait set (:func:`poll_ready`);
* :mod:`tms_common.sim_clock` waits on a ``/clock`` subscription with a bare rcl wait set and takes its
  messages directly (:class:`SubscriptionWaiter`);
* :mod:`tms_common.node` joins a MultiThreadedExecutor's thread pool at shutdown (:func:`executor_thread_pool`).

All three also rely on one documented-but-implicit behaviour: an executor leaves out of its wait set every
entity whose callback group's ``can_execute`` returns False (:func:`park`).

On the rclpy version these were verified against (:data:`TESTED_RCLPY`, the ``ros-jazzy-rclpy`` pin of
constraints.txt) :data:`INTERNALS` is True and the callers take the fast path. On any other version they
take the public path (handlers stay in the executor, the node keeps its own ``/clock`` subscription, the
pool is not joined), and the first caller logs one warning naming the version. tests/unit/test_rclpy_compat.py
runs each workaround against the installed rclpy and fails when an upgrade changes what it relies on.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from rclpy.callback_groups import CallbackGroup

__all__ = ["TESTED_RCLPY", "RCLPY_VERSION", "INTERNALS", "use_internals", "park", "poll_ready",
           "SubscriptionWaiter", "SubscriptionDestroyed", "executor_thread_pool", "installed_rclpy_version"]

TESTED_RCLPY = "7.1.6"  # the ros-jazzy-rclpy version pinned in constraints.txt

_log = logging.getLogger(__name__)
_warned: set[str] = set()
_warn_lock = threading.Lock()


def installed_rclpy_version() -> str:
    """The installed rclpy's version: from the ROS wheels' metadata, else the ament package.xml; "" if unknown."""
    from importlib import metadata

    for dist in ("ros-jazzy-rclpy", "ros-rclpy"):
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    try:  # a ROS installed from apt or source: rclpy's package.xml in the ament share directory
        import re
        from pathlib import Path

        from ament_index_python.packages import get_package_share_directory

        text = (Path(get_package_share_directory("rclpy")) / "package.xml").read_text()
        found = re.search(r"<version>([^<]+)</version>", text)
        return found.group(1).strip() if found else ""
    except Exception:  # noqa: BLE001 - no ament index either: unknown version, public path
        return ""


RCLPY_VERSION = installed_rclpy_version()
INTERNALS = RCLPY_VERSION == TESTED_RCLPY


def use_internals(feature: str) -> bool:
    """True on the tested rclpy; otherwise False, with one warning (per process) naming the version."""
    if INTERNALS:
        return True
    with _warn_lock:
        first = not _warned
        _warned.add(feature)
    if first:
        _log.warning("rclpy %s is not the tested %s: %s and the other rclpy workarounds of tms_common take the "
                     "public path (more executor CPU, same behaviour)", RCLPY_VERSION or "(unknown version)",
                     TESTED_RCLPY, feature)
    return False


# -- parking entities outside the executor's wait set ----------------------------------------------

class _Parked(CallbackGroup):
    """A callback group no executor ever finds ready (see :func:`park`)."""

    def can_execute(self, entity: Any) -> bool:  # noqa: ARG002
        return False

    def beginning_execution(self, entity: Any) -> bool:  # noqa: ARG002
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


_PARKED = _Parked()


def park(entity: Any) -> None:
    """Move ``entity`` (a subscription, guard condition or waitable of a node) to a callback group that no
    executor ever finds ready, so the executor leaves it out of its wait set; its owner waits on it instead.

    rclpy 7.1.6 ``Executor.can_execute`` (executors.py) filters every entity through
    ``entity.callback_group.can_execute(entity)`` before building the wait set.
    """
    entity.callback_group = _PARKED


def is_parked(entity: Any) -> bool:
    return entity.callback_group is _PARKED


# -- bare rcl wait sets -----------------------------------------------------------------------------

def _wait_set(context: Any, *, subscriptions: int = 0, guard_conditions: int = 0, waitables: int = 0) -> Any:
    # rclpy 7.1.6: _rclpy.WaitSet(subscriptions, guard_conditions, timers, clients, services, events, context)
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    return _rclpy.WaitSet(subscriptions, guard_conditions, 0, 0, 0, waitables, context.handle)


def poll_ready(context: Any, waitables: list[Any]) -> list[Any]:
    """Wait on ``waitables`` (rclpy Waitables, e.g. EventHandlers) for zero time; return those that are ready."""
    if not waitables:
        return []
    with context.handle:
        wait_set = _wait_set(context, waitables=len(waitables))
        for waitable in waitables:
            waitable.add_to_wait_set(wait_set)
        wait_set.wait(0)
        return [w for w in waitables if w.is_ready(wait_set)]


class SubscriptionDestroyed(Exception):  # noqa: N818 - an end, not an error
    """The subscription a :class:`SubscriptionWaiter` waits on was destroyed (its node, or rclpy's TimeSource)."""


class SubscriptionWaiter:
    """Waits on one subscription (and a wake-up guard condition) with a bare rcl wait set, off any executor.

    ``wait_take(timeout_ns)`` returns the next message, or None on a timeout or a :meth:`wake`, and raises
    :class:`SubscriptionDestroyed` once the subscription is gone. The guard condition is not a node's, so no
    executor sees it.
    """

    def __init__(self, subscription: Any, context: Any) -> None:
        from rclpy.guard_condition import GuardCondition

        self._sub = subscription
        self._context = context
        self._guard = GuardCondition(None, None, context=context)

    def wake(self) -> None:
        self._guard.trigger()

    def wait_take(self, timeout_ns: int) -> Any | None:
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        try:
            return self._wait_take(timeout_ns)
        except _rclpy.InvalidHandle as exc:  # destruction requested, e.g. by destroy_node during the wait
            raise SubscriptionDestroyed(str(exc)) from None

    def _wait_take(self, timeout_ns: int) -> Any | None:
        sub, guard = self._sub, self._guard
        with self._context.handle, sub.handle, guard.handle:
            wait_set = _wait_set(self._context, subscriptions=1, guard_conditions=1)
            wait_set.add_subscription(sub.handle)
            wait_set.add_guard_condition(guard.handle)
            wait_set.wait(timeout_ns)
            if sub.handle.pointer not in wait_set.get_ready_entities("subscription"):
                return None
            taken = sub.handle.take_message(sub.msg_type, False)  # (message, info) or None
        return taken[0] if taken is not None else None

    def destroy(self) -> None:
        self._guard.destroy()


# -- executors --------------------------------------------------------------------------------------

def executor_thread_pool(executor: Any) -> Any | None:
    """The ThreadPoolExecutor of an rclpy MultiThreadedExecutor (rclpy 7.1.6: ``_executor``); None otherwise
    or on another rclpy version."""
    from concurrent.futures import ThreadPoolExecutor

    if not use_internals("joining the executor's thread pool at shutdown"):
        return None
    pool = getattr(executor, "_executor", None)
    return pool if isinstance(pool, ThreadPoolExecutor) else None
