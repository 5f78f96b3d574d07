"""Groot 1 monitoring: BehaviorTree.CPP 3.x's ``PublisherZMQ`` protocol for our trees (no ROS).

What BT.CPP 3.8.7 does (``src/loggers/bt_zmq_publisher.cpp``, ``flatbuffers/bt_flatbuffer_helper.h``,
``flatbuffers/BT_logger.fbs``) and this module repeats byte for byte:

* a REP socket (server port, Groot's default 1667) answers any request with the tree: a flatbuffer whose root is
  the ``Serialization.BehaviorTree`` table (``root_uid``, ``nodes`` [TreeNode: uid, children_uid, status,
  instance_name, registration_name, port_remaps], ``node_models`` [NodeModel: registration_name, type, ports]);
* a PUB socket (publisher port, 1666) sends the status changes: ``uint32`` size of the header, the header (per
  node, depth first: ``uint16`` uid, ``int8`` status, as of the previous message), ``uint32`` number of
  transitions, then 12 bytes per transition (``uint32`` seconds and ``uint32`` microseconds since the epoch,
  ``uint16`` uid, ``int8`` previous status, ``int8`` status), all little endian;
* the first transition after a message opens a window of ``1 / max_msg_per_second``; the transitions of that
  window go out in one message at its end (the original's scheduler passes 100 per second: 10 ms). The manager also
  sends a tick's changes when the tick ends (:meth:`GrootPublisher.end_of_tick`) if the last message is older than
  that window: never more messages per second, and no thread to wake on a loaded machine.

UIDs are BT.CPP's: numbered 1, 2, ... in the order the factory creates the nodes, depth first (a fresh process
building one tree, as the original's one-tree-per-process scheduler does). Our SubTrees are inlined, so no
SUBTREE node appears.
"""

from __future__ import annotations

import errno
import struct
import threading
import time
from collections.abc import Iterable, Sequence
from typing import Any

import flatbuffers
import zmq

from tms_ts.bt.core import FAILURE, IDLE, RUNNING, SUCCESS, BtNode, Status
from tms_ts.errors import TsError

__all__ = [
    "GrootError",
    "NODE_STATUS",
    "NODE_TYPE",
    "PORT_INPUT",
    "GrootTree",
    "serialize_tree",
    "status_header",
    "transition_bytes",
    "status_message",
    "GrootPublisher",
]


class GrootError(TsError):
    """The Groot publisher cannot run (a port in use, bad ports); the message names the port."""


#: Serialization.NodeStatus (BT_logger.fbs)
NODE_STATUS: dict[Status, int] = {IDLE: 0, RUNNING: 1, SUCCESS: 2, FAILURE: 3}
#: our node kinds (BtNode.KIND) -> Serialization.NodeType (UNDEFINED 0)
NODE_TYPE: dict[str, int] = {"Action": 1, "Condition": 2, "Control": 3, "Decorator": 4, "SubTree": 5}
#: Serialization.PortDirection.INPUT: every port of ours is read (the original declares them InputPort)
PORT_INPUT = 0


class GrootTree:
    """One tree as Groot sees it: the nodes depth first with their uids, and its serialized buffer."""

    def __init__(self, root: BtNode) -> None:
        self.nodes: list[BtNode] = list(root.iter_nodes())  # depth first, the factory's creation order
        self.uids: dict[int, int] = {id(node): uid for uid, node in enumerate(self.nodes, start=1)}
        # the header's layout, compiled once: it is packed again after every status message
        self.header_struct = struct.Struct("<" + "Hb" * len(self.nodes))
        self._buffer: bytes | None = None
        self._lock = threading.Lock()

    @property
    def buffer(self) -> bytes:
        """The serialized tree, built when first asked for (on the publisher's server thread, not in the tick: a
        tree of 4,990 nodes takes about 0.5 s); a tree no client asks for is never serialized."""
        with self._lock:
            if self._buffer is None:
                self._buffer = serialize_tree(self.nodes, self.uids)
            return self._buffer

    def uid(self, node: BtNode) -> int:
        return self.uids[id(node)]


def _remap_text(is_key: bool, value: Any) -> str:
    """The port's text as the XML gave it: ``{key}`` or the literal (bools as BT.CPP writes them)."""
    if is_key:
        return f"{{{value}}}"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _vector_of_offsets(builder: flatbuffers.Builder, offsets: Sequence[int]) -> int:
    builder.StartVector(4, len(offsets), 4)
    for off in reversed(offsets):
        builder.PrependUOffsetTRelative(off)
    return builder.EndVector()


def serialize_tree(nodes: Sequence[BtNode], uids: dict[int, int]) -> bytes:
    """``CreateFlatbuffersBehaviorTree``: the BehaviorTree table of these nodes (``nodes[0]`` is the root)."""
    b = flatbuffers.Builder(1024)
    fb_nodes = []
    models: dict[str, BtNode] = {}
    for node in nodes:
        children = [uids[id(c)] for c in node.children]
        b.StartVector(2, len(children), 2)
        for uid in reversed(children):
            b.PrependUint16(uid)
        children_vec = b.EndVector()
        remaps = []
        for name, (is_key, value) in node._ports.items():
            name_off, remap_off = b.CreateString(name), b.CreateString(_remap_text(is_key, value))
            b.StartObject(2)  # PortConfig
            b.PrependUOffsetTRelativeSlot(0, name_off, 0)
            b.PrependUOffsetTRelativeSlot(1, remap_off, 0)
            remaps.append(b.EndObject())
        remaps_vec = _vector_of_offsets(b, remaps)
        instance, registration = b.CreateString(node.name), b.CreateString(node.node_id)
        b.StartObject(6)  # TreeNode
        b.PrependUint16Slot(0, uids[id(node)], 0)
        b.PrependUOffsetTRelativeSlot(1, children_vec, 0)
        b.PrependInt8Slot(2, NODE_STATUS[node.status], 0)
        b.PrependUOffsetTRelativeSlot(3, instance, 0)
        b.PrependUOffsetTRelativeSlot(4, registration, 0)
        b.PrependUOffsetTRelativeSlot(5, remaps_vec, 0)
        fb_nodes.append(b.EndObject())
        models.setdefault(node.node_id, node)
    nodes_vec = _vector_of_offsets(b, fb_nodes)
    fb_models = []
    for registration_id, node in models.items():
        ports = []
        for name, port in type(node).PORTS.items():
            name_off = b.CreateString(name)
            type_off = b.CreateString(port.cpp_type or "AnyTypeAllowed")
            desc_off = b.CreateString(port.description)
            b.StartObject(4)  # PortModel
            b.PrependUOffsetTRelativeSlot(0, name_off, 0)
            b.PrependInt8Slot(1, PORT_INPUT, 0)
            b.PrependUOffsetTRelativeSlot(2, type_off, 0)
            b.PrependUOffsetTRelativeSlot(3, desc_off, 0)
            ports.append(b.EndObject())
        ports_vec = _vector_of_offsets(b, ports)
        reg_off = b.CreateString(registration_id)
        b.StartObject(3)  # NodeModel
        b.PrependUOffsetTRelativeSlot(0, reg_off, 0)
        b.PrependInt8Slot(1, NODE_TYPE.get(node.KIND, 0), 0)
        b.PrependUOffsetTRelativeSlot(2, ports_vec, 0)
        fb_models.append(b.EndObject())
    models_vec = _vector_of_offsets(b, fb_models)
    b.StartObject(3)  # BehaviorTree
    b.PrependUint16Slot(0, uids[id(nodes[0])], 0)
    b.PrependUOffsetTRelativeSlot(1, nodes_vec, 0)
    b.PrependUOffsetTRelativeSlot(2, models_vec, 0)
    b.Finish(b.EndObject())
    return bytes(b.Output())


def status_header(tree: GrootTree) -> bytes:
    """``createStatusBuffer``: (uid, status) of every node, depth first."""
    values = []
    for uid, node in enumerate(tree.nodes, start=1):  # uids are the depth-first positions
        values += (uid, NODE_STATUS[node.status])
    return tree.header_struct.pack(*values)


def transition_bytes(stamp_s: float, uid: int, prev: Status, status: Status) -> bytes:
    """``SerializeTransition``: 12 bytes; seconds and microseconds of ``stamp_s`` (epoch seconds)."""
    usec = int(round(stamp_s * 1e6))
    return struct.pack("<IIHbb", (usec // 1_000_000) & 0xFFFFFFFF, usec % 1_000_000, uid,
                       NODE_STATUS[prev], NODE_STATUS[status])


def status_message(header: bytes, transitions: Iterable[bytes]) -> bytes:
    """``flush``: size of the header, header, number of transitions, transitions."""
    items = list(transitions)
    return b"".join([struct.pack("<I", len(header)), header, struct.pack("<I", len(items)), *items])


class GrootPublisher:
    """PublisherZMQ: a PUB socket for status changes and a REP socket that answers with the tree.

    Both sockets are bound here; a port that cannot be bound is a :class:`GrootError` naming it. :meth:`attach`
    chooses the tree (one at a time, as BT.CPP's one instance per process); ``listener`` is what
    :attr:`tms_ts.bt.core.TreeContext.status_listeners` takes. ``clock`` stamps transitions (epoch seconds).
    """

    def __init__(self, publisher_port: int = 1666, server_port: int = 1667, *, address: str = "*",
                 max_msg_per_second: float = 100.0, clock=time.time) -> None:
        if publisher_port == server_port:
            raise GrootError(f"Groot: the publisher and server ports must differ (both {publisher_port})")
        for what, port in (("publisher", publisher_port), ("server", server_port)):
            if not 0 < port < 65536:
                raise GrootError(f"Groot {what} port {port} is not a TCP port (1..65535)")
        if max_msg_per_second <= 0:
            raise GrootError(f"Groot: max_msg_per_second must be > 0, got {max_msg_per_second}")
        self.publisher_port, self.server_port = publisher_port, server_port
        self.min_interval_s = 1.0 / max_msg_per_second
        self.clock = clock
        self._context = zmq.Context()  # our own, so close() releases both ports at once (term)
        # XPUB is PUB on the wire (Groot's SUB socket cannot tell) and also hands us the subscriptions: with no
        # client subscribed no change is stamped or queued (a tick of a 1,000-node tree: ~7 ms with, ~0.5 without)
        self._pub = self._context.socket(zmq.XPUB)
        self._rep = self._context.socket(zmq.REP)
        for sock in (self._pub, self._rep):
            sock.setsockopt(zmq.LINGER, 0)
        try:
            self._bind(self._pub, address, publisher_port, "publisher")
            self._bind(self._rep, address, server_port, "server")
        except GrootError:
            self._context.destroy(linger=0)
            raise
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._tree: GrootTree | None = None
        self._header = b""
        self._transitions: list[tuple[float, int, Status, Status]] = []
        self._flush_at: float | None = None  # monotonic end of the open window
        self._last_sent = float("-inf")
        self.subscribed = False  # a client is subscribed (XPUB forwards the first subscribe and the last unsubscribe)
        self._active = True
        self.messages_sent = 0
        self._server = threading.Thread(target=self._serve, name="groot-server", daemon=True)
        self._sender = threading.Thread(target=self._send_loop, name="groot-publisher", daemon=True)
        self._server.start()
        self._sender.start()

    @staticmethod
    def _bind(sock: zmq.Socket, address: str, port: int, what: str) -> None:
        try:
            sock.bind(f"tcp://{address}:{port}")
        except zmq.ZMQError as exc:
            why = "is in use" if exc.errno == errno.EADDRINUSE else f"cannot be bound ({exc})"
            raise GrootError(f"Groot {what} port {port} on {address} {why}") from None

    # -- the tree ----------------------------------------------------------------------------------
    @property
    def tree(self) -> GrootTree | None:
        return self._tree

    def attach(self, root: BtNode) -> GrootTree:
        """Publish this tree from now on (the previous one's pending transitions are sent first); its buffer is
        serialized on the server thread when a client asks for it."""
        tree = GrootTree(root)
        self.flush()
        with self._lock:
            self._tree = tree
            self._header = status_header(tree)
        return tree

    def listener(self, node: BtNode, prev: Status, status: Status) -> None:
        """A status change of a node (called on the tick's thread); ignored unless it is the attached tree's."""
        stamp = self.clock()
        with self._lock:
            tree = self._tree
            uid = tree.uids.get(id(node)) if tree is not None and self.subscribed else None
            if uid is None:
                return
            # packed when sent (on the sender thread): a tick of a 1,000-node tree makes 2,000 changes
            self._transitions.append((stamp, uid, prev, status))
            if self._flush_at is None:  # the first of a window: BT.CPP's send_pending_ / wait_for
                self._flush_at = time.monotonic() + self.min_interval_s
                self._wake.notify()

    def end_of_tick(self) -> None:
        """The tick that made the pending changes ended: send them now unless a message went out less than
        ``1 / max_msg_per_second`` ago (then the window's timer sends them). The tick's thread is awake anyway, so
        a loaded machine need not schedule the sender thread first (it took up to 160 ms at load average 10)."""
        with self._lock:
            self._read_subscriptions()
            due = self._transitions and time.monotonic() - self._last_sent >= self.min_interval_s
        if due:
            self.flush()

    def _read_subscriptions(self) -> None:
        """Take the XPUB's subscription messages (under the lock: the socket is shared with the senders). On the
        first subscription the header is brought up to now, so the client's first message starts from the
        statuses the nodes have, not from those of the last message sent before it came."""
        while True:
            try:
                msg = self._pub.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if msg[:1] == b"\x01" and not self.subscribed:
                self.subscribed = True
                if self._tree is not None:
                    self._header = status_header(self._tree)
            elif msg[:1] == b"\x00":
                self.subscribed = False
                self._transitions = []

    def flush(self) -> None:
        """Send the pending transitions now (as ``PublisherZMQ::flush``); nothing pending: nothing sent."""
        with self._lock:
            if not self._transitions or self._tree is None:
                self._flush_at = None
                return
            message = status_message(self._header, (transition_bytes(*t) for t in self._transitions))
            self._transitions = []
            self._header = status_header(self._tree)
            self._flush_at = None
            self.messages_sent += 1  # before the send: a reader of the message sees the count
            self._last_sent = time.monotonic()
            # sent under the lock: the sender thread and the tick's thread share the PUB socket
            self._pub.send(message)

    def _send_loop(self) -> None:
        while True:
            with self._lock:
                while self._active and self._flush_at is None:
                    self._wake.wait()
                if not self._active:
                    return
                delay = self._flush_at - time.monotonic()
                if delay > 0:
                    self._wake.wait(delay)
                    continue
            self.flush()

    def _serve(self) -> None:
        poller = zmq.Poller()
        poller.register(self._rep, zmq.POLLIN)
        while self._active:
            with self._lock:  # a subscription is seen within one poll period even when no tree ticks
                try:
                    self._read_subscriptions()
                except zmq.ZMQError:
                    return  # closed
            if self._tree is None:  # no tree yet: requests wait (Groot times out, as with no PublisherZMQ)
                time.sleep(0.05)
                continue
            try:
                if not poller.poll(100):
                    continue
                self._rep.recv()
                tree = self._tree  # the tree attached when the request came, not when the poll began
                self._rep.send(tree.buffer)  # serialized here on the first request, off the tick's thread
            except zmq.ZMQError:
                return  # closed

    def close(self) -> None:
        """Send what is pending, stop both threads and release both ports."""
        if not self._active:
            return
        try:
            self.flush()
        except zmq.ZMQError:
            pass
        with self._lock:
            self._active = False
            self._wake.notify_all()
        self._sender.join(timeout=1.0)
        self._server.join(timeout=1.0)
        self._context.destroy(linger=0)
