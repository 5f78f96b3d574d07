"""The node runner every console-script node uses.

``run_node(factory)`` initialises rclpy with the process arguments (so ``--ros-args -r __ns:=...
-p key:=value --params-file f.yaml`` work as with ``ros2 run``), builds the node, spins it on the
chosen executor and shuts down cleanly on SIGINT/SIGTERM, returning a process exit code.

Every node's incompatible-QoS/-type event handlers are polled once a second instead of sitting in the
executor's wait set (:mod:`tms_common.qos_events`: 0.58-0.68 of the executor CPU per wake in four runs of
``python -m tests.bench executor_wake``). A node on simulated time gets its ``/clock`` from a helper thread
(:mod:`tms_common.sim_clock`), so its executor wakes for its timers and messages, not for every clock tick.

Executor choice: ``TMS_EXECUTOR=events|single|multi`` (default ``single``), or ``executor=`` of
:func:`run_node`. ``events`` is rclpy's EventsExecutor with the defects of rclpy 7.1.6 worked around
(:class:`tms_common.rclpy_compat.SlicedEventsExecutor`: its unbounded waits delivered nothing and ignored
SIGINT); it ignores callback groups, so a node on it keeps its QoS event handlers and its ``/clock``
subscription (the executor only runs a handler when its event happens).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from tms_common.dds import use_platform_profiles
from tms_common.errors import ConfigError, TmsError
from tms_common.qos_events import defer_qos_incompatibility_events
from tms_common.rclpy_compat import SlicedEventsExecutor, executor_thread_pool
from tms_common.sim_clock import relay_clock

if TYPE_CHECKING:  # pragma: no cover
    from rclpy.node import Node

__all__ = ["run_node", "make_executor", "uses_wait_set", "realtime_thread", "EXECUTORS", "ACTION_RESULT_TIMEOUT_S"]

EXECUTORS = ("single", "multi", "events")
#: [s] every action server of the platform keeps a finished goal (its status entry and its result) this long;
#: rclpy's default is 900 s. Every status message carries the whole array and every client converts it to
#: Python: at 10 goals a second the arrays grew by thousands of entries and the manager's 50 Hz tick lost most
#: of its periods. Our clients ask for a result as soon as a goal is accepted, and ask again at most 3 s after
#: its status said it ended (zx200_planner RESULT_GRACE_S), so a result is never fetched later than this.
ACTION_RESULT_TIMEOUT_S = 5.0


def realtime_thread(priority: int, who: str, logger) -> bool:
    """Put the calling thread under SCHED_FIFO at ``priority`` (1-99; 0 = leave it as it is; else ConfigError).

    For a thread whose wake-up latency matters more than its share (the plant loop, the manager's tick): on a
    loaded 2-core machine a normal thread woke more than 10 ms late in 5-12 % of its 50 Hz periods. Threads it
    starts later inherit the policy. Needs CAP_SYS_NICE (root); refused -> a warning naming ``who`` and normal
    scheduling, returns False.
    """
    if priority <= 0:
        return False
    if priority > 99:
        raise ConfigError(f"{who}: realtime_priority must be 0 (off) or 1-99, got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        logger.warning(f"{who}: realtime_priority {priority} refused ({exc}); normal scheduling")
        return False
    return True


def make_executor(kind: str | None = None, *, threads: int = 8, context=None):
    """Build an executor by name: ``single``, ``multi`` or ``events``; ``None``: ``$TMS_EXECUTOR``, else ``single``.

    ``multi`` gets ``threads`` threads (not rclpy's default of one per CPU: with 2 CPUs, two action goals
    waiting on downstream goals would take every thread and no cancel could be served). ``events`` is
    :class:`tms_common.rclpy_compat.SlicedEventsExecutor` (rclpy's EventsExecutor, usable): no guard
    conditions on its nodes (``call_soon`` instead), callback groups ignored (:func:`uses_wait_set` is False).
    ``context``: the rclpy context (default: rclpy's default context).
    """
    import rclpy.executors

    named = kind
    kind = kind or os.environ.get("TMS_EXECUTOR", "single")
    if kind == "single":
        return rclpy.executors.SingleThreadedExecutor(context=context)
    if kind == "multi":
        return rclpy.executors.MultiThreadedExecutor(num_threads=threads, context=context)
    if kind == "events":
        return SlicedEventsExecutor(context=context)
    source = "" if named else " (from $TMS_EXECUTOR)"
    raise ValueError(f"unknown executor {kind!r}{source}: expected one of {', '.join(EXECUTORS)}")


def uses_wait_set(executor) -> bool:
    """True for rclpy's wait-set executors (single, multi): they honour callback groups, so
    :func:`tms_common.rclpy_compat.park` keeps an entity out of them (QoS event polling, the ``/clock``
    relay) and guard conditions work; False for ``events``."""
    return not isinstance(executor, SlicedEventsExecutor)


def run_node(
    factory: Callable[..., Node],
    args: Sequence[str] | None = None,
    *,
    executor: str | None = None,
    threads: int = 8,
    stop_in_context: bool = False,
) -> int:
    """Initialise rclpy, create the node with ``factory`` and spin until shutdown.

    ``threads`` sizes the ``multi`` executor. By default rclpy's signal handler shuts the context down on
    SIGINT/SIGTERM, so ``destroy_node`` can no longer publish or call anything. A node that must act when
    it is stopped (the task manager cancels its running subtasks and engages its machines' locks) passes
    ``stop_in_context=True``: the signal then ends the spin between two callbacks and ``destroy_node`` runs
    with the context still valid (:func:`_stop_on_signals`). A node that has work to wind down first (the
    subtask servers cancel their downstream goals and wait for them to end) defines
    ``on_stop_requested() -> bool``: called when the signal arrives and every 50 ms after, the spin goes on
    while it returns True. Returns 0 on a clean shutdown (SIGINT, SIGTERM), 2 on a deliberate error
    (:class:`~tms_common.errors.TmsError`, e.g. a config file's ``file:line``, or a parameter of the wrong type:
    one line, no traceback) and 1 when the node raised anything else (printed with its traceback). Either is
    printed with the node's name so a launcher log shows which node died and why.
    """
    import logging

    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions


    # Python logging of the cores (sim_bridge, com3_can) on stderr, prefixed with the executable's name
    logging.basicConfig(level=logging.WARNING,
                        format=f"[{os.path.basename(sys.argv[0]) or 'node'}] %(levelname)s %(name)s: %(message)s")
    use_platform_profiles()
    rclpy.init(args=list(args) if args is not None else sys.argv,
               signal_handler_options=SignalHandlerOptions.NO if stop_in_context else SignalHandlerOptions.ALL)
    node = None
    spinner = None
    relay = None
    signals = contextlib.ExitStack()
    try:
        node = factory()
        spinner = make_executor(executor, threads=threads)
        if stop_in_context:
            signals.enter_context(_stop_on_signals(node, spinner))
        if uses_wait_set(spinner):  # parking takes nothing out of an events executor: nothing to gain there
            defer_qos_incompatibility_events(node)
            relay = relay_clock(node)
        spinner.add_node(node)
        spinner.spin()
    except (KeyboardInterrupt, ExternalShutdownException, _StopRequested):
        pass
    except (TmsError, ParameterException) as exc:
        # A deliberate error (bad config file or parameter): its message names the culprit (file:line,
        # key, value), so one line says it all; a traceback would bury it.
        name = node.get_name() if node is not None else _factory_name(factory)
        print(f"[{name}] {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        return 2
    except Exception as exc:  # noqa: BLE001 - report any crash with the node's name, then exit non-zero
        if not rclpy.ok():
            # Shutdown (SIGINT/SIGTERM) raced with a callback whose handles were already torn down.
            return 0
        name = node.get_name() if node is not None else _factory_name(factory)
        print(f"[{name}] fatal: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        import traceback

        traceback.print_exc()
        return 1
    finally:
        if spinner is not None:
            # the pool first: a handler still queued triggers the executor's guard condition, which
            # spinner.shutdown destroys (rclpy 7.1.6 does not catch that in a handler that finds it shut down)
            _wait_for_callback_threads(spinner, timeout_s=2.0, run_queued=node is not None and node.context.ok())
            spinner.shutdown(timeout_sec=0)
        if node is not None:
            node.destroy_node()  # the clock still runs: destroy_node may wait on simulated time
        if relay is not None:
            relay.close()
        signals.close()  # after destroy_node: a second signal meanwhile must not cut it short
        rclpy.try_shutdown()
    return 0


def _factory_name(factory: Callable[..., Node]) -> str:
    """The executable's name (what the user typed), else the factory's: for a node that failed to build."""
    return os.path.basename(sys.argv[0]) or getattr(factory, "__name__", "node")


_SETTLE_S = 0.2  # [s] spin left to a node stopped in context after its on_stop_requested hook is done


class _StopRequested(Exception):  # noqa: N818 - a request, not an error
    """Raised by the stop guard condition's callback, between two callbacks, to end the spin."""


@contextlib.contextmanager
def _stop_on_signals(node, spinner):
    """SIGINT/SIGTERM end ``node``'s spin on ``spinner`` between two callbacks, with its context still valid.

    A Python signal handler runs only when the main thread is back in Python, not while it waits in
    ``rcl_wait``; so the signal is also written to a wake-up fd, and a thread reading it triggers a guard
    condition whose callback raises :class:`_StopRequested` in the executor (on ``events``, which has no guard
    conditions: ``call_soon`` runs it and ``request_stop`` ends the spin). No callback is cut in half.
    """
    import threading

    winding_down = getattr(node, "on_stop_requested", None)

    settled = threading.Event()

    def stop() -> None:
        if winding_down is not None and winding_down():
            threading.Timer(0.05, trigger).start()  # ask again in 50 ms; the spin goes on meanwhile
            return
        if not settled.is_set():
            # One more short spin: what the last callbacks left queued (an action server's result and status
            # after its execute callback returned, a client's result response) is handled before the executor
            # stops, instead of being dropped ("coroutine ... was never awaited") or run on destroyed handles.
            settled.set()
            threading.Timer(_SETTLE_S, trigger).start()
            return
        if uses_wait_set(spinner):
            raise _StopRequested
        spinner.request_stop()

    if uses_wait_set(spinner):
        trigger = node.create_guard_condition(stop).trigger
    else:
        def trigger() -> None:
            spinner.call_soon(stop)
    with signals_to(trigger, "tms-stop-relay"):
        yield


@contextlib.contextmanager
def signals_to(trigger: Callable[[], None], thread_name: str):
    """SIGINT/SIGTERM call ``trigger`` from a relay thread, through a wake-up fd: a Python signal handler
    does not run while the main thread waits in ``rcl_wait``. Handlers are restored on exit."""
    import signal
    import threading

    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)

    def relay() -> None:
        try:
            while os.read(read_fd, 16):
                trigger()
        except Exception:  # noqa: BLE001 - the guard is gone (node destroyed): nothing left to stop
            pass
        finally:
            os.close(read_fd)

    previous = {sig: signal.signal(sig, lambda *_: None) for sig in (signal.SIGINT, signal.SIGTERM)}
    previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    threading.Thread(target=relay, name=thread_name, daemon=True).start()
    try:
        yield
    finally:
        signal.set_wakeup_fd(previous_fd)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        os.close(write_fd)  # the relay's read returns b"" and it ends


def _wait_for_callback_threads(spinner, timeout_s: float, *, run_queued: bool) -> None:
    """Let callbacks still running in a MultiThreadedExecutor's threads end before the node is destroyed.

    ``run_queued``: handlers queued but not started run too (the context is valid: stopped in context);
    otherwise they are canceled (their coroutines are then never awaited, and Python says so at exit).

    Without this, a callback in flight at SIGINT touched handles that ``destroy_node`` had just destroyed and
    a multi-threaded node printed "exception was never retrieved: cannot use Destroyable because destruction
    was requested" at shutdown. rclpy 7.1.6's ``Executor.shutdown`` does not wait for them (its wait is
    skipped once ``_is_shutdown`` is set), so the thread pool is joined here, for at most ``timeout_s``.
    """
    import threading


    pool = executor_thread_pool(spinner)
    if pool is None:
        return
    joiner = threading.Thread(
        target=pool.shutdown, kwargs={"wait": True, "cancel_futures": not run_queued}, daemon=True
    )
    joiner.start()
    joiner.join(timeout_s)
