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
pool is not joined), and the first caller logs one warning naming the version. tests/tms_common/test_rclpy_compat.py
runs each workaround against the installed rclpy and fails when an upgrade changes what it relies on.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from rclpy.callback_groups import CallbackGroup

__all__ = ["TESTED_RCLPY", "RCLPY_VERSION", "INTERNALS", "use_internals", "park", "poll_ready",
           "SubscriptionWaiter", "SubscriptionDestroyed", "executor_thread_pool", "installed_rclpy_version",
           "SlicedEventsExecutor", "EVENTS_SLICE_S", "create_deferred_service"]

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

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
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


# -- services that reply later ---------------------------------------------------------------------

def create_deferred_service(node: Any, srv_type: Any, name: str, on_request: Any, **kwargs: Any) -> Any:
    """A service whose reply is sent when it is ready, not when its callback returns.

    ``on_request(request, reply)`` runs on the executor thread and must call ``reply(response)`` exactly once,
    then or later (e.g. when a motion it started ends). An ``async`` service callback would do the same on
    the SingleThreadedExecutor, but the EventsExecutor of rclpy 7.1.6 does not await it (it sends the
    coroutine as the response: TypeError). Both executors answer a request by calling the service's
    ``send_response(response, header)`` after the callback, so the callback returns a marker and the instance's
    ``send_response`` keeps the header of a marked request until ``reply`` comes; the requests of one service
    are answered in the order the executor took them.
    """
    deferred = object()
    pending: list[dict] = []  # per request taken: its header (once known) and its reply (once given)

    def callback(request: Any, _response: Any) -> Any:
        box: dict = {"header": None, "response": None}
        pending.append(box)

        def reply(response: Any) -> None:
            if box["header"] is None:
                box["response"] = response  # replied before the executor handed over the header
            else:
                original(response, box["header"])

        on_request(request, reply)
        return deferred

    service = node.create_service(srv_type, name, callback, **kwargs)
    original = service.send_response

    def send_response(response: Any, header: Any) -> None:
        if response is not deferred:
            original(response, header)
            return
        box = pending.pop(0)
        if box["response"] is not None:
            original(box["response"], header)
        else:
            box["header"] = header

    service.send_response = send_response
    return service


# -- the EventsExecutor ------------------------------------------------------------------------------

#: [s] longest wait of one :class:`SlicedEventsExecutor` slice: how late a context shut down from outside
#: (``rclpy.shutdown`` in another thread) is noticed; signals and :meth:`SlicedEventsExecutor.request_stop`
#: end a slice at once.
EVENTS_SLICE_S = 1.0


class SlicedEventsExecutor:
    """rclpy's ``EventsExecutor`` (``rclpy.experimental``) with the three defects of rclpy 7.1.6 worked around.

    1. ``spin()`` and every wait without a timeout busy-wait and deliver nothing. The wait is
       ``std::condition_variable::wait_until(steady_clock::time_point::max())``; the wheels are built against
       an old glibc (no ``pthread_cond_clockwait``), so libstdc++ converts that deadline to the system clock,
       the sum overflows into the past and every wait returns at once. The waiting thread then holds the
       event queue's mutex almost all the time; the threads that enqueue events (timers, DDS listeners, the
       SIGINT callback) starve on it: no timer fires, no message is delivered, SIGINT is not taken.
       Here every wait is bounded (``spin_until_future_complete(future, EVENTS_SLICE_S)``, a real timed
       wait), and :meth:`spin` repeats it until the context is shut down or :meth:`request_stop`.
    2. An exception that escapes a task (a coroutine, a future's done-callback, anything given to
       ``create_task``) kills the process with SIGSEGV. Tasks created through this object are guarded:
       the exception ends the spin and is raised from :meth:`spin` in the spinning thread, as the
       SingleThreadedExecutor does. The nodes' ``executor`` is pointed at this object
       (:func:`_point_node_at`), so rclpy's own tasks (action goals, action client responses) are guarded too;
       done-callbacks of client futures completed by the C++ side are not (they get the inner executor).
    3. Guard conditions are not supported (``RuntimeError: Guard conditions not supported`` from inside the
       spin). :meth:`add_node` refuses a node that has one, naming it; :meth:`call_soon` (any thread) is what
       a guard condition's trigger was used for.

    Two limits stay: callback groups are ignored (everything runs on the spinning thread, and
    :func:`park` does not keep an entity out: ``tms_common.node.run_node`` neither parks QoS event handlers
    nor relays ``/clock`` on this executor), and the coroutine callbacks of subscriptions and services are
    not awaited (rclpy 7.1.11 handles them).
    """

    def __init__(self, context: Any = None) -> None:
        import rclpy
        from rclpy.experimental import EventsExecutor

        self._context = context or rclpy.get_default_context()
        self._inner = EventsExecutor(context=self._context)
        self._stop = threading.Event()
        self._slice_lock = threading.Lock()
        self._slice_future: Any = None
        self._error: BaseException | None = None

    # the rclpy Executor API used by nodes and the runners ------------------------------------------
    @property
    def context(self) -> Any:
        return self._context

    def add_node(self, node: Any) -> bool:
        guards = list(getattr(node, "guards", []))
        if guards:
            raise ValueError(f"node {node.get_name()!r} has {len(guards)} guard condition(s): the EventsExecutor of "
                             f"rclpy {RCLPY_VERSION} cannot wait on them (use executor 'single', or call_soon)")
        added = self._inner.add_node(node)
        _point_node_at(node, self)
        return added

    def remove_node(self, node: Any) -> None:
        self._inner.remove_node(node)

    def get_nodes(self) -> list[Any]:
        return list(self._inner.get_nodes())

    def wake(self) -> None:
        self._inner.wake()

    def create_task(self, callback: Any, *args: Any, **kwargs: Any) -> Any:
        return self._inner.create_task(self._guarded(callback), *args, **kwargs)

    def create_future(self) -> Any:
        from rclpy.task import Future

        return Future(executor=self)

    def call_soon(self, callback: Any) -> None:
        """Run ``callback()`` on the spinning thread between two callbacks; callable from any thread."""
        self.create_task(callback)

    def request_stop(self) -> None:
        """End :meth:`spin` (from any thread or a callback): it returns normally; a request made while not
        spinning ends the next :meth:`spin` at once."""
        self._stop.set()
        self._end_slice()

    def spin(self) -> None:
        while self._context.ok() and not self._stop.is_set():
            self._spin_slice(EVENTS_SLICE_S, stoppable=True)
        self._stop.clear()  # the request is consumed

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """At most one callback; ``None`` waits at most :data:`EVENTS_SLICE_S` (an unbounded wait is defect 1)."""
        self._inner.spin_once(timeout_sec=EVENTS_SLICE_S if timeout_sec is None else max(0.0, timeout_sec))
        self._raise_pending()

    def spin_until_future_complete(self, future: Any, timeout_sec: float | None = None) -> None:
        import time

        end = None if timeout_sec is None else time.monotonic() + timeout_sec
        while self._context.ok() and not future.done():
            left = EVENTS_SLICE_S if end is None else min(EVENTS_SLICE_S, end - time.monotonic())
            if left <= 0:
                return
            self._spin_slice(left, future)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self.request_stop()
        return self._inner.shutdown(timeout_sec=timeout_sec)

    # internals ---------------------------------------------------------------------------------------
    def _spin_slice(self, seconds: float, future: Any = None, stoppable: bool = False) -> None:
        from rclpy.task import Future

        end_on = Future()
        with self._slice_lock:
            self._slice_future = end_on
        if stoppable and self._stop.is_set():
            # a request_stop between spin()'s check and the line above found no slice to end: without this the
            # new slice ran its whole EVENTS_SLICE_S (a test saw spin() return 1 s after the request)
            end_on.set_result(None)
        if future is not None:
            future.add_done_callback(lambda _f: end_on.done() or end_on.set_result(None))
        self._inner.spin_until_future_complete(end_on, timeout_sec=seconds)
        with self._slice_lock:
            self._slice_future = None
        self._raise_pending()

    def _end_slice(self) -> None:
        with self._slice_lock:
            end_on = self._slice_future
        if end_on is not None and not end_on.done():
            end_on.set_result(None)  # no executor set on it: its done-callback (the queue's Stop) runs here

    def _raise_pending(self) -> None:
        error, self._error = self._error, None
        if error is not None:
            raise error

    def _failed(self, exc: BaseException) -> None:
        if self._error is None:
            self._error = exc
        self._end_slice()

    def _guarded(self, callback: Any) -> Any:
        import functools
        import inspect

        if inspect.iscoroutine(callback):
            coro = callback

            async def run_coroutine() -> Any:
                try:
                    return await coro
                except Exception as exc:  # noqa: BLE001 - re-raised from spin(), not in the C++ task (SIGSEGV)
                    self._failed(exc)
            return run_coroutine()
        if inspect.iscoroutinefunction(callback):
            @functools.wraps(callback)
            async def run_async(*args: Any, **kwargs: Any) -> Any:
                try:
                    return await callback(*args, **kwargs)
                except Exception as exc:  # noqa: BLE001
                    self._failed(exc)
            return run_async

        @functools.wraps(callback)
        def run(*args: Any, **kwargs: Any) -> Any:
            try:
                return callback(*args, **kwargs)
            except Exception as exc:  # noqa: BLE001
                self._failed(exc)
        return run


def _point_node_at(node: Any, executor: Any) -> None:
    """Make ``node.executor`` return ``executor`` (rclpy 7.1.6: the name-mangled ``_Node__executor_weakref``):
    the inner EventsExecutor's ``add_node`` points it at itself, and rclpy schedules action goals and
    responses on ``node.executor``."""
    import weakref

    if use_internals("guarding EventsExecutor tasks against the SIGSEGV of a raising task"):
        node._Node__executor_weakref = weakref.ref(executor)
