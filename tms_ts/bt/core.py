"""Base classes that give py_trees behaviours BehaviorTree.CPP 3.8 execution semantics.

py_trees ticks through generators and resets nodes differently from BT.CPP (a py_trees Sequence
always has memory or not per flag, its Parallel has policies instead of thresholds, its Repeat and
Retry count across ticks). Task XML written for BT.CPP must behave as it did there, so every node
here is a :class:`py_trees.behaviour.Behaviour` (status, name, children, ``feedback_message`` and
the py_trees display tools work on it) whose *execution* follows BT.CPP:

* :meth:`BtNode.execute_tick` is BT.CPP's ``executeTick``: it runs the node's ``_tick`` and stores
  the status. Parents tick children with it directly (no generators), which keeps the overhead per
  node to a few microseconds.
* :meth:`BtNode.halt` is BT.CPP's ``halt``: a RUNNING node is interrupted (``on_halted``) and every
  node ends IDLE (py_trees ``Status.INVALID``).
* Ports are declared per class in ``PORTS`` with the C++ type the original declares them with; literal
  values are converted once when the tree is built (``convertFromString``), ``{key}`` values are read from
  the blackboard at every tick as BT.CPP's ``getInput<T>`` reads them, and a ``{key}`` port declares its
  entry with that type when the tree is built (:mod:`tms_ts.blackboard` has the rules).

Do not override ``execute_tick`` or ``halt`` in subclasses; fill ``_tick`` / ``on_halted`` (or the
``on_start`` / ``on_running`` pair of :class:`StatefulNode`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

from py_trees.behaviour import Behaviour
from py_trees.common import Status

from tms_ts.blackboard import (
    BOOL,
    DOUBLE,
    INT,
    STRING,
    UINT,
    Blackboard,
    BlackboardError,
    any_cast,
    convert_from_string,
    ctype_of,
)
from tms_ts.errors import TreeRuntimeError

__all__ = [
    "Status",
    "IDLE",
    "SUCCESS",
    "FAILURE",
    "RUNNING",
    "Port",
    "TreeContext",
    "BtNode",
    "ActionNode",
    "StatefulNode",
    "ControlNode",
    "DecoratorNode",
    "convert",
]

IDLE = Status.INVALID
SUCCESS = Status.SUCCESS
FAILURE = Status.FAILURE
RUNNING = Status.RUNNING

_UNSET: Any = object()


#: Port type -> the C++ type BT.CPP reads it as (``getInput<T>``); "any" = the node reads the raw value
PORT_CPP_TYPES: dict[str, str | None] = {
    "str": STRING, "key": STRING, "int": INT, "unsigned": UINT, "float": DOUBLE, "bool": BOOL, "any": None,
}


@dataclass(frozen=True)
class Port:
    """A declared port: ``type`` is str | key | int | unsigned | float | bool | any; ``default`` _UNSET = required.

    ``key`` ports name a blackboard entry and are read as ``std::string`` as the original reads them
    (``getInput<std::string>``): ``key="X"`` names X, ``key="{X}"`` names the entry whose *name* is held in X.
    ``typed=False`` is BT.CPP's untyped port (``InputPort("value")``, ``BidirectionalPort("output_key")``): a
    ``{key}`` on it declares its entry untyped.
    """

    type: str = "str"
    default: Any = _UNSET
    description: str = ""
    typed: bool = True

    @property
    def required(self) -> bool:
        return self.default is _UNSET

    @property
    def cpp_type(self) -> str | None:
        """The type a ``{key}`` on this port declares its entry with (None: untyped)."""
        return PORT_CPP_TYPES[self.type] if self.typed else None


def convert(value: Any, type_: str) -> Any:
    """A port's value as ``type_`` (text literal: ``convertFromString``; a typed value: ``Any::cast``); ValueError."""
    target = PORT_CPP_TYPES.get(type_, _UNSET)
    if target is _UNSET:
        raise ValueError(f"unknown port type {type_!r}")
    if target is None:
        return value
    if isinstance(value, str):
        return convert_from_string(value, target)
    return any_cast(value, ctype_of(value), target)


@dataclass
class TreeContext:
    """What the nodes of one task share: its blackboard, the DB store, the ROS side and a clock.

    ``store`` is a tms_db store (``open_store()``) or None for trees without DB nodes; ``ros`` is the
    ROS port of the manager (:class:`tms_ts.leaf.RosPort`) or None offline. ``clock`` returns
    monotonic seconds (injectable for tests) and times the transport: goal acceptance, halts, lost
    servers, DB retries. ``task_clock`` times the task itself (Delay, Timeout, Sleep; :meth:`task_time`):
    the manager passes its ROS clock, so under ``use_sim_time`` a 1.5 s Delay is 1.5 s of the plant's
    time, not of the wall (it was wall time: 3.75 s of simulation at 2.5x real time);
    None = ``clock``. ``sync_loop_budget`` bounds how many
    synchronous iterations a Repeat/RetryUntilSuccessful runs inside one tick before yielding RUNNING
    (BT.CPP loops forever there, which made the original manager deaf to the emergency stop).
    """

    blackboard: Blackboard = field(default_factory=Blackboard)
    store: Any = None
    ros: Any = None
    clock: Callable[[], float] = time.monotonic
    task_clock: Callable[[], float] | None = None
    task_id: int = -1
    sync_loop_budget: int = 1000
    accept_timeout_s: float = 1.0
    halt_timeout_s: float = 5.0
    #: an accepted goal whose subtask server stays unavailable this long ends FAILURE (server lost)
    server_lost_s: float = 3.0
    #: every LeafNode of the tree (filled by the loader; the manager checks their servers at start)
    leaves: list[Any] = field(default_factory=list)
    #: halted subtask goals still waiting for CANCELED/ABORTED (see tms_ts.leaf.PendingStop)
    stops: list[Any] = field(default_factory=list)
    #: failure reasons reported by leaves, newest last (the task's FAILURE message uses them)
    failures: list[str] = field(default_factory=list)
    #: actions whose server was lost while serving a goal of this task (the manager's stop policy)
    lost_servers: list[str] = field(default_factory=list)
    #: called ``(node, prev, status)`` on every status change, as BT.CPP's ``subscribeToStatusChange`` (Groot)
    status_listeners: list[Callable[[Any, Status, Status], None]] = field(default_factory=list)

    def task_time(self) -> float:
        """Seconds on the task's clock (``task_clock``, else ``clock``)."""
        return (self.task_clock or self.clock)()

    def child(self, blackboard: Blackboard) -> TreeContext:
        """Same context with another blackboard (non-shared SubTree)."""
        return TreeContext(
            blackboard=blackboard,
            store=self.store,
            ros=self.ros,
            clock=self.clock,
            task_clock=self.task_clock,
            task_id=self.task_id,
            sync_loop_budget=self.sync_loop_budget,
            accept_timeout_s=self.accept_timeout_s,
            halt_timeout_s=self.halt_timeout_s,
            server_lost_s=self.server_lost_s,
            leaves=self.leaves,
            stops=self.stops,
            failures=self.failures,
            lost_servers=self.lost_servers,
            status_listeners=self.status_listeners,
        )


class BtNode(Behaviour):
    """A tree node with BT.CPP semantics (see module docstring). Subclasses fill ``_tick``."""

    PORTS: ClassVar[dict[str, Port]] = {}
    #: (min, max) number of children; max None = unbounded
    CHILDREN: ClassVar[tuple[int, int | None]] = (0, 0)
    #: the XML tag family Groot uses for this node (Action, Condition, Control, Decorator, SubTree)
    KIND: ClassVar[str] = "Action"

    def __init__(
        self,
        name: str,
        *,
        node_id: str,
        ports: dict[str, tuple[bool, Any]] | None = None,
        ctx: TreeContext | None = None,
        where: str = "",
    ) -> None:
        super().__init__(name)
        self.node_id = node_id
        #: port name -> (is_blackboard_key, literal value already converted | key name)
        self._ports = ports or {}
        self.ctx = ctx if ctx is not None else TreeContext()
        self.where = where
        self.children: list[BtNode] = []

    # -- identity -------------------------------------------------------------------------------
    def describe(self) -> str:
        """``ID 'name' (line L, column C)``, the form used in every error message."""
        label = f"{self.node_id} '{self.name}'" if self.name != self.node_id else self.node_id
        return f"{label} ({self.where})" if self.where else label

    # -- ports ----------------------------------------------------------------------------------
    def get_input(self, port: str, default: Any = _UNSET) -> Any:
        """``getInput<T>`` (T from the port's type): the converted literal, or the ``{key}`` entry converted.

        A ``{key}`` entry holding a string is ``convertFromString<T>`` of it (unless T is a string), any other
        value is ``Any::cast<T>``; a missing or never-set entry, or a refused conversion, is a TreeRuntimeError
        naming this node, its line, the port and the key.
        """
        spec = self.PORTS.get(port)
        entry = self._ports.get(port)
        if entry is None:
            if default is not _UNSET:
                return default
            if spec is not None and not spec.required:
                return spec.default
            raise TreeRuntimeError(f"{self.describe()}: port '{port}' is not set")
        is_key, value = entry
        if not is_key:
            return value
        found = self.ctx.blackboard.get_any(value)
        if found is None or found.empty:
            if default is not _UNSET:
                return default
            if found is None:
                raise TreeRuntimeError(
                    f"{self.describe()}: port '{port}' reads blackboard key '{value}', which is not set"
                )
            raise TreeRuntimeError(
                f"{self.describe()}: port '{port}' reads blackboard key '{value}', which a port declared "
                f"({found.port_type or 'untyped'}) "
                'but nothing has set yet (BT.CPP 3.8: "was found, but its content was not initialized correctly")'
            )
        target = PORT_CPP_TYPES[spec.type] if spec is not None else None
        if target is None:
            return found.value
        try:
            if target != STRING and found.vtype == STRING:
                return convert_from_string(found.value, target)
            return any_cast(found.value, found.vtype or STRING, target)
        except ValueError as exc:
            how = "convertFromString" if target != STRING and found.vtype == STRING else "Any::cast"
            raise TreeRuntimeError(
                f"{self.describe()}: port '{port}' reads blackboard key '{value}' = {found.vtype} {found.value!r} as "
                f"{target} (BT.CPP getInput: {how}): {exc}") from None

    def port_key(self, port: str) -> str:
        """The blackboard key a ``key`` port names: its text (``X``), or the text held in entry X (``{X}``)."""
        return self.get_input(port)

    def bb_set(self, key: str, value: Any, ctype: str | None = None) -> None:
        """``blackboard->set(key, value)``; what BT.CPP refuses is a TreeRuntimeError naming node, line and key."""
        try:
            self.ctx.blackboard.set(key, value, ctype)
        except BlackboardError as exc:
            raise TreeRuntimeError(f"{self.describe()}: blackboard key '{key}': {exc}") from None

    def set_output(self, port: str, value: Any, ctype: str | None = None) -> None:
        """Write ``value`` to the blackboard entry named by ``port`` (see :meth:`port_key`)."""
        self.bb_set(self.port_key(port), value, ctype)

    # -- execution (BT.CPP executeTick / halt) --------------------------------------------------
    def execute_tick(self) -> Status:
        """Tick this node once and remember its status (do not override)."""
        prev = self.status
        status = self._tick()
        self.status = status
        if status != prev and self.ctx.status_listeners:
            self._notify(prev, status)
        return status

    def _notify(self, prev: Status, status: Status) -> None:
        for listener in self.ctx.status_listeners:
            listener(self, prev, status)

    def _tick(self) -> Status:  # pragma: no cover - abstract
        raise NotImplementedError

    def update(self) -> Status:
        """py_trees' update hook: the node's BT.CPP tick logic."""
        return self._tick()

    def halt(self) -> None:
        """Interrupt a RUNNING node and reset it to IDLE (do not override; fill ``on_halted``)."""
        prev = self.status
        if prev == RUNNING:
            self.on_halted()
        self._reset()
        self.status = IDLE
        if prev != IDLE and self.ctx.status_listeners:
            self._notify(prev, IDLE)

    def on_halted(self) -> None:
        """Hook: the node was RUNNING and is being interrupted (cancel goals, stop timers)."""

    def _reset(self) -> None:
        """Hook: clear per-run state (indices, counters); composites also halt their children."""

    # -- py_trees compatibility -----------------------------------------------------------------
    def tick(self):  # py_trees generator protocol
        """py_trees' generator protocol: one BT.CPP tick of this subtree, yielding the root."""
        self.execute_tick()
        yield self

    def stop(self, new_status: Status = IDLE) -> None:
        """py_trees' stop: a halt in BT.CPP terms."""
        self.halt()

    def iter_nodes(self):
        """Depth-first iteration over this subtree."""
        yield self
        for child in self.children:
            yield from child.iter_nodes()


class ActionNode(BtNode):
    """A synchronous action/condition: ``_tick`` returns SUCCESS or FAILURE at once."""


class StatefulNode(BtNode):
    """An asynchronous action (BT.CPP StatefulActionNode): ``on_start`` then ``on_running`` per tick."""

    def _tick(self) -> Status:
        if self.status != RUNNING:
            return self.on_start()
        return self.on_running()

    def on_start(self) -> Status:  # pragma: no cover - abstract
        raise NotImplementedError

    def on_running(self) -> Status:  # pragma: no cover - abstract
        raise NotImplementedError


class ControlNode(BtNode):
    """A node with one or more children. ``halt`` halts every child and resets the node's index."""

    KIND = "Control"
    CHILDREN = (1, None)

    def halt_child(self, index: int) -> None:
        """BT.CPP haltChild: halt a RUNNING child, leave every child IDLE."""
        self.children[index].halt()

    def halt_children(self, start: int = 0) -> None:
        for child in self.children[start:]:
            child.halt()

    def _reset(self) -> None:
        self.halt_children()


class DecoratorNode(BtNode):
    """A node with exactly one child."""

    KIND = "Decorator"
    CHILDREN = (1, 1)

    @property
    def child(self) -> BtNode:
        return self.children[0]

    def halt_child(self) -> None:
        self.children[0].halt()

    def _reset(self) -> None:
        self.halt_child()
