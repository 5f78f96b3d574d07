"""A component container: several nodes of a launch file in one process, spun by one executor.

``python -m tms_launch.container <name> <json>`` is what ``tms-launch`` starts for a ``container`` of the
composed layout (:func:`tms_launch.launch_file.processes`); the JSON lists the nodes in launch-file order, each
with its package, executable and ``--ros-args`` (name, namespace, parameters, parameter files), as
``ros2 component load`` gives a component its remaps and parameters.

Each node is the module-level ``class X(Node)`` of the module its executable's console script names
(``<package>/nodes/<executable>.py``), built with ``cli_args``: a node gets exactly what its own process
would have been given on its command line. The process then does what :func:`tms_common.node.run_node`
does for one node, for all of them:

* one executor spins every node: :data:`CONTAINER_EXECUTOR` (``events``: rclpy's EventsExecutor, through
  :func:`tms_common.node.make_executor`), or ``$TMS_EXECUTOR`` (``single`` for debugging);
* on ``single`` only (EventsExecutor ignores callback groups, so nothing can be kept off it): the
  QoS-incompatibility events of every node are polled off the executor
  (:func:`tms_common.qos_events.defer_qos_incompatibility_events`), and one ``/clock`` relay thread sets the
  clock of every node on simulated time (:class:`tms_common.sim_clock.ClockRelay`); on ``events`` the first
  node on simulated time keeps its ``/clock`` subscription and its TimeSource sets the clocks of the others,
  whose own subscriptions are dropped (:func:`tms_common.sim_clock.share_time_source`);
* SIGINT/SIGTERM stop the nodes one at a time, last in the file first, with the context still valid: a
  node's ``on_stop_requested`` hook runs (the spin goes on while it returns True), a short settle spin
  handles what its last callbacks left queued, then it leaves the executor and ``destroy_node`` runs while
  the nodes before it still spin (the supervisor writes its report and the manager cancels its subtasks
  and locks the machines before the servers, controllers and plant of the same process go);
* a node whose callback raises ``SystemExit(code)`` ends the container with ``code`` (0 only for a node
  with ``on_exit: shutdown``, a job that finished); any other exception ends it with 1, a bad parameter or
  configuration (:class:`~tms_common.errors.TmsError`) while building with 2; the node is named either way.

The CAN links of the machines whose plant and converter share this process are in-process
(:func:`com3_can.bus.link_config`; tms-launch sets ``TMS_CAN_IN_PROCESS`` for the container).
"""

from __future__ import annotations

import faulthandler
import functools
import importlib
import inspect
import json
import logging
import os
import signal
import sys
import time
import traceback
from dataclasses import dataclass
from importlib import metadata
from typing import Any

from tms_common.dds import use_platform_profiles
from tms_common.errors import TmsError
from tms_common.node import make_executor, signals_to, uses_wait_set
from tms_common.qos_events import defer_qos_incompatibility_events
from tms_common.sim_clock import on_simulated_time, relay_clock, share_time_source

__all__ = ["node_class", "main"]

_SETTLE_S = 0.2  # [s] spin left to the container after a node's stop hook, before the node is destroyed
#: a container's executor unless ``$TMS_EXECUTOR`` says otherwise: rclpy's EventsExecutor (usable through
#: tms_common.rclpy_compat) ran one paper cycle composed at 0.94 core-s per simulated s against 1.36 on the
#: SingleThreadedExecutor, whose per-wake cost grows with every node's entities in its one wait set
#: (docs/performance.md, "containers on events")
CONTAINER_EXECUTOR = "events"
_HOOK_PERIOD_S = 0.05  # [s] how often a node's on_stop_requested is asked again while it winds down


class _StopRequested(Exception):  # noqa: N818 - a request, not an error
    """Raised by the stop guard condition's callback, between two callbacks, to end the spin."""


@dataclass
class _Member:
    name: str
    package: str
    executable: str
    on_exit: str
    ros_args: list[str]
    node: Any = None


def node_class(package: str, executable: str) -> type:
    """The rclpy Node subclass of ``executable``: the one defined in the module its console script names.

    Raises:
        LookupError: no console script of that name, it is not in ``package``, or its module does not define
            exactly one Node subclass.
    """
    from rclpy.node import Node

    found = [ep for ep in metadata.entry_points(group="console_scripts") if ep.name == executable]
    if not found:
        raise LookupError(f"no console script {executable!r} is installed (pyproject.toml [project.scripts])")
    module_name = found[0].module
    if module_name.partition(".")[0] != package:
        raise LookupError(f"executable {executable!r} is {module_name}, not in package {package!r}")
    module = importlib.import_module(module_name)
    classes = [obj for obj in vars(module).values()
               if inspect.isclass(obj) and issubclass(obj, Node) and obj.__module__ == module_name]
    if len(classes) != 1:
        raise LookupError(f"{module_name} defines {len(classes)} Node classes ({[c.__name__ for c in classes]}); "
                          "a node in a container needs exactly one")
    return classes[0]


def _culprit(exc: BaseException, members: list[_Member]) -> _Member | None:
    """The member whose method raised ``exc`` (the innermost frame whose ``self`` is one of the nodes)."""
    by_id = {id(m.node): m for m in members if m.node is not None}
    found = None
    tb = exc.__traceback__
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        if owner is not None and id(owner) in by_id:
            found = by_id[id(owner)]
        tb = tb.tb_next
    return found


def _spin_for(executor: Any, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        executor.spin_once(timeout_sec=min(left, _HOOK_PERIOD_S))


class _CallSoon:
    """The stop trigger on an executor without guard conditions: ``trigger()`` queues ``callback`` on it."""

    def __init__(self, executor: Any, callback: Any) -> None:
        self._executor, self._callback = executor, callback

    def trigger(self) -> None:
        self._executor.call_soon(self._callback)


def _signals_to(guard_holder: list[Any]):
    """SIGINT/SIGTERM trigger the stop guard condition once it exists. No callback is cut in half."""
    def trigger() -> None:
        if guard_holder:
            guard_holder[0].trigger()
    return signals_to(trigger, "tms-container-stop")


def _say(name: str, text: str) -> None:
    print(f"[{name}] {text}", file=sys.stderr, flush=True)


def run_container(name: str, members: list[_Member]) -> int:
    """Build every member's node, spin them on one executor until a stop signal or an exit, stop them in reverse."""
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    logging.basicConfig(level=logging.WARNING, format=f"[{name}] %(levelname)s %(name)s: %(message)s")
    use_platform_profiles()
    rclpy.init(args=["tms_container"], signal_handler_options=SignalHandlerOptions.NO)
    guard: list[Any] = []
    relay = None
    relay_owner: _Member | None = None
    clock_leader: Any = None  # events: the first node on simulated time, whose /clock sets every node's clock
    built: list[_Member] = []
    current: _Member | None = None
    executor = None
    code = 0
    with _signals_to(guard):
        try:
            executor = make_executor(os.environ.get("TMS_EXECUTOR") or CONTAINER_EXECUTOR)
            # rclpy's EventsExecutor ignores callback groups: parked QoS handlers and a relayed /clock would
            # still be served by it, so on ``events`` every node keeps its own (as run_node does)
            wait_set = uses_wait_set(executor)
            for member in members:
                current = member
                cls = node_class(member.package, member.executable)
                member.node = cls(cli_args=member.ros_args)
                built.append(member)
                if not wait_set:
                    if clock_leader is None:
                        clock_leader = member.node if on_simulated_time(member.node) else None
                    else:
                        share_time_source(clock_leader, member.node)
                    continue
                defer_qos_incompatibility_events(member.node)
                if relay is None:
                    relay = relay_clock(member.node)
                    relay_owner = member if relay is not None else None
                else:
                    relay.follow(member.node)
            current = None
            stopping: list[bool] = []

            def stop() -> None:
                if not stopping:  # a second signal while the nodes stop one by one changes nothing
                    stopping.append(True)
                    if not wait_set:
                        executor.request_stop()  # spin() returns; the nodes stop as after the exception
                        return
                    raise _StopRequested

            if wait_set:  # on the first node: destroyed last, so a signal is taken until the end
                guard.append(built[0].node.create_guard_condition(stop))
            else:  # no guard conditions on events: the relay thread queues the stop on the spinning thread
                guard.append(_CallSoon(executor, stop))
            for member in built:
                if not wait_set:
                    _exit_through_executor(member.node, executor)
                executor.add_node(member.node)
            print(f"container of {len(built)} node(s) in process {os.getpid()}: "
                  f"{', '.join(m.node.get_fully_qualified_name() for m in built)}", flush=True)
            executor.spin()
        except (_StopRequested, KeyboardInterrupt, ExternalShutdownException):
            pass
        except (TmsError, ParameterException, LookupError) as exc:
            who = current or _culprit(exc, built)
            _say(who.name if who else name, f"{type(exc).__name__}: {exc}")
            code = 2
        except SystemExit as exc:
            who = _culprit(exc, built)
            code = exc.code if isinstance(exc.code, int) else 1
            label = who.name if who else "a node"
            if code == 0 and (who is None or who.on_exit != "shutdown"):
                _say(name, f"{label} exited with 0 but is not a job (on_exit: shutdown): the container stops with 1")
                code = 1
            else:
                _say(name, f"{label} exited with {code}; stopping the container")
        except Exception as exc:  # noqa: BLE001 - report any crash with the node's name, then stop the others
            who = current or _culprit(exc, built)
            _say(who.name if who else name, f"fatal: {type(exc).__name__}: {exc}")
            traceback.print_exc()
            code = 1
        finally:
            _stop_members(built, executor, relay, relay_owner)
            rclpy.try_shutdown()
    return code


def _exit_through_executor(node: Any, executor: Any) -> None:
    """On the events executor, a ``SystemExit`` raised in one of ``node``'s timer callbacks (a job that has
    finished, e.g. the supervisor) is re-raised from the spin through ``call_soon``: rclpy's EventsExecutor would
    log it as a FATAL "Exception in 'timers' callback" first. The SingleThreadedExecutor raises it as it is."""

    def reraise(exc: SystemExit) -> None:
        raise exc

    for timer in node.timers:
        callback = timer.callback

        def guarded(callback: Any = callback) -> Any:
            try:
                return callback()
            except SystemExit as exc:
                executor.call_soon(functools.partial(reraise, exc))
                return None
        timer.callback = guarded


def _stop_members(built: list[_Member], executor: Any, relay: Any, relay_owner: _Member | None) -> None:
    """Stop the nodes last-built first: stop hook (spinning), settle, leave the executor, destroy."""
    events = executor is not None and not uses_wait_set(executor)
    for member in reversed(built):
        node = member.node
        try:
            hook = getattr(node, "on_stop_requested", None)
            if executor is not None:
                began = time.monotonic()
                while hook is not None and hook() and time.monotonic() - began < 60.0:
                    _spin_for(executor, _HOOK_PERIOD_S)
                _spin_for(executor, _SETTLE_S)
                if events:
                    for timer in node.timers:
                        timer.cancel()
                executor.remove_node(node)
                if events:
                    # rclpy's EventsExecutor runs what it queued for a node after remove_node: a timer of the
                    # IC120 vessel and a subscription of the /tf node ran after destroy_node and raised
                    # InvalidHandle in the next node's stop. Their timers are cancelled, and what is queued runs
                    # now, while the node still exists.
                    _spin_for(executor, _HOOK_PERIOD_S)
            if relay is not None and member is not relay_owner:
                relay.unfollow(node)
        except BaseException as exc:  # noqa: BLE001 - one node's failing stop must not keep the others running
            _say(member.name, f"while stopping: {type(exc).__name__}: {exc}")
        if member is relay_owner:
            relay.close()
        try:
            node.destroy_node()
        except BaseException as exc:  # noqa: BLE001
            _say(member.name, f"destroy_node failed: {type(exc).__name__}: {exc}")
    if executor is not None:
        executor.shutdown(timeout_sec=0)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        print("usage: python -m tms_launch.container <name> <json list of nodes>", file=sys.stderr)
        return 2
    name, payload = args
    # `kill -USR1 <pid>` prints every thread's stack: what a container that does not stop is waiting for
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    members = [_Member(name=n["name"], package=n["package"], executable=n["executable"],
                       on_exit=n.get("on_exit", "error"), ros_args=list(n["ros_args"])) for n in json.loads(payload)]
    return run_container(name, members)


if __name__ == "__main__":
    exit_code = main()
    # Every node is destroyed and the context shut down; what is left is interpreter teardown, where the garbage
    # collection of rclpy's remaining handles was seen to hang (a stopped machine-PC container sat "Garbage-collecting"
    # until SIGTERM). Nothing needs finalising, so leave at once.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(exit_code)
