"""Groot 1 protocol of tms_ts.groot: the tree buffer read back with a reader written here from BT_logger.fbs
(the flatbuffers runtime's Table API, none of the serialiser's code), uids, statuses, the status messages, and
the two ZMQ sockets of GrootPublisher (a real REQ and SUB client on loopback ports)."""

from __future__ import annotations

import socket
import struct
import time

import flatbuffers
import pytest
import zmq
from flatbuffers.table import Table

from tests.tms_ts.scripted import tree
from tms_ts.bt.core import FAILURE, IDLE, RUNNING, SUCCESS
from tms_ts.groot import GrootError, GrootPublisher, GrootTree

# --- a reader of BT_logger.fbs (BehaviorTree.CPP 3.8.7), written from the schema ------------------------------
IDLE_, RUNNING_, SUCCESS_, FAILURE_ = 0, 1, 2, 3  # Serialization.NodeStatus
UNDEFINED, ACTION, CONDITION, CONTROL, DECORATOR, SUBTREE = range(6)  # Serialization.NodeType


def _table(buf: bytes, pos: int) -> Table:
    return Table(buf, pos)


def _field(t: Table, slot: int) -> int:
    return t.Offset(4 + 2 * slot)  # vtable entry of field `slot`


def _scalar(t: Table, slot: int, flags, default=0):
    o = _field(t, slot)
    return t.Get(flags, o + t.Pos) if o else default


def _string(t: Table, slot: int) -> str | None:
    o = _field(t, slot)
    return t.String(o + t.Pos).decode() if o else None


def _tables(t: Table, slot: int) -> list[Table]:
    o = _field(t, slot)
    if not o:
        return []
    start, n = t.Vector(o), t.VectorLen(o)
    return [_table(t.Bytes, t.Indirect(start + 4 * i)) for i in range(n)]


def _uint16s(t: Table, slot: int) -> list[int]:
    o = _field(t, slot)
    if not o:
        return []
    start, n = t.Vector(o), t.VectorLen(o)
    return [t.Get(flatbuffers.number_types.Uint16Flags, start + 2 * i) for i in range(n)]


def read_tree(buf: bytes) -> dict:
    """BehaviorTree {root_uid, nodes: [TreeNode], node_models: [NodeModel]} as dicts."""
    nt = flatbuffers.number_types
    root = _table(buf, flatbuffers.encode.Get(flatbuffers.packer.uoffset, buf, 0))
    nodes = [{
        "uid": _scalar(n, 0, nt.Uint16Flags),
        "children": _uint16s(n, 1),
        "status": _scalar(n, 2, nt.Int8Flags),
        "instance_name": _string(n, 3),
        "registration_name": _string(n, 4),
        "ports": {_string(p, 0): _string(p, 1) for p in _tables(n, 5)},
    } for n in _tables(root, 1)]
    models = {_string(m, 0): {
        "type": _scalar(m, 1, nt.Int8Flags),
        "ports": {_string(p, 0): (_scalar(p, 1, nt.Int8Flags), _string(p, 2)) for p in _tables(m, 2)},
    } for m in _tables(root, 2)}
    return {"root_uid": _scalar(root, 0, nt.Uint16Flags), "nodes": nodes, "models": models}


def read_status_message(msg: bytes) -> tuple[dict[int, int], list[tuple[float, int, int, int]]]:
    """PublisherZMQ::flush's layout: header (uid -> status) and transitions (stamp, uid, prev, status)."""
    (size,) = struct.unpack_from("<I", msg, 0)
    header = dict(struct.unpack_from("<Hb", msg, 4 + 3 * i) for i in range(size // 3))
    (count,) = struct.unpack_from("<I", msg, 4 + size)
    out = []
    for i in range(count):
        sec, usec, uid, prev, status = struct.unpack_from("<IIHbb", msg, 8 + size + 12 * i)
        out.append((sec + usec * 1e-6, uid, prev, status))
    assert len(msg) == 8 + size + 12 * count
    return header, out


BODY = ('<Sequence name="main"><SetBlackboard output_key="x" value="1"/>'
        '<Inverter><Scripted id="a"/></Inverter><Fallback><Scripted id="b"/><AlwaysSuccess/></Fallback></Sequence>')


def test_tree_buffer_holds_nodes_depth_first_with_btcpp_uids_types_and_ports():
    t = tree(BODY, a="F", b="R")
    g = GrootTree(t.root)
    got = read_tree(g.buffer)
    assert got["root_uid"] == 1
    names = [(n["uid"], n["registration_name"], n["children"]) for n in got["nodes"]]
    assert names == [(1, "Sequence", [2, 3, 5]), (2, "SetBlackboard", []), (3, "Inverter", [4]),
                     (4, "Scripted", []), (5, "Fallback", [6, 7]), (6, "Scripted", []), (7, "AlwaysSuccess", [])]
    assert got["nodes"][0]["instance_name"] == "main"
    assert got["nodes"][1]["ports"] == {"output_key": "x", "value": "1"}
    assert all(n["status"] == IDLE_ for n in got["nodes"])
    models = got["models"]
    assert models["Sequence"]["type"] == CONTROL and models["Inverter"]["type"] == DECORATOR
    assert models["Scripted"]["type"] == ACTION and models["Scripted"]["ports"] == {"id": (0, "std::string")}
    assert set(models) == {"Sequence", "SetBlackboard", "Inverter", "Scripted", "Fallback", "AlwaysSuccess"}


def test_status_changes_reach_the_listener_with_btcpp_statuses_and_halt_to_idle():
    t = tree(BODY, a="F", b="RF")
    g = GrootTree(t.root)
    seen = []
    t.ctx.status_listeners.append(lambda node, prev, status: seen.append((g.uid(node), prev, status)))
    assert t.tick() is RUNNING
    # the Inverter resets its finished child to IDLE (BT.CPP 3.8 resetChild), a transition Groot sees too
    assert seen == [(2, IDLE, SUCCESS), (4, IDLE, FAILURE), (4, FAILURE, IDLE), (3, IDLE, SUCCESS),
                    (6, IDLE, RUNNING), (5, IDLE, RUNNING), (1, IDLE, RUNNING)]
    seen.clear()
    t.halt()  # running nodes go IDLE, the finished ones too (BT.CPP halts every child)
    assert (6, RUNNING, IDLE) in seen and (1, RUNNING, IDLE) in seen and (2, SUCCESS, IDLE) in seen
    seen.clear()
    assert t.tick() is SUCCESS  # b's script goes on: F now, AlwaysSuccess rescues the Fallback, Sequence ends
    assert seen[4:] == [(6, IDLE, FAILURE), (7, IDLE, SUCCESS), (6, FAILURE, IDLE), (7, SUCCESS, IDLE),
                        (5, IDLE, SUCCESS), (2, SUCCESS, IDLE), (3, SUCCESS, IDLE), (5, SUCCESS, IDLE),
                        (1, IDLE, SUCCESS)]


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def test_publisher_serves_the_tree_and_batches_transitions_as_publisherzmq():
    pub_port, srv_port = _free_ports(2)
    t = tree(BODY, a="F", b="R")
    groot = GrootPublisher(pub_port, srv_port, address="127.0.0.1", max_msg_per_second=20)
    ctx = zmq.Context()
    try:
        req = ctx.socket(zmq.REQ)
        req.connect(f"tcp://127.0.0.1:{srv_port}")
        sub = ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.connect(f"tcp://127.0.0.1:{pub_port}")
        groot.attach(t.root)
        t.ctx.status_listeners.append(groot.listener)
        req.send(b"")
        assert req.poll(2000), "no tree from the REP socket"
        assert [n["uid"] for n in read_tree(req.recv())["nodes"]] == [1, 2, 3, 4, 5, 6, 7]
        time.sleep(0.3)  # the SUB's subscription reaches the PUB (slow joiner)
        before = time.time()
        t.tick()
        assert sub.poll(2000), "no status message"
        got_at = time.time()
        header, transitions = read_status_message(sub.recv())
        assert header == {uid: IDLE_ for uid in range(1, 8)}  # statuses as of the previous message
        assert [(u, p, s) for _, u, p, s in transitions] == [
            (2, IDLE_, SUCCESS_), (4, IDLE_, FAILURE_), (4, FAILURE_, IDLE_), (3, IDLE_, SUCCESS_),
            (6, IDLE_, RUNNING_), (5, IDLE_, RUNNING_), (1, IDLE_, RUNNING_)]  # one message: the 1/20 s window
        assert all(before - 0.001 <= stamp <= got_at for stamp, *_ in transitions)
        assert got_at - before >= 0.04  # sent at the end of the window, not per transition
        t.halt()
        assert sub.poll(2000)
        header, transitions = read_status_message(sub.recv())
        assert header[1] == RUNNING_ and header[2] == SUCCESS_  # the header caught up with the last message
        assert (1, RUNNING_, IDLE_) in [(u, p, s) for _, u, p, s in transitions]
        assert groot.messages_sent == 2
    finally:
        ctx.destroy(linger=0)
        groot.close()


def test_with_no_client_subscribed_nothing_is_queued_or_sent_and_a_late_client_starts_from_now():
    pub_port, srv_port = _free_ports(2)
    t = tree(BODY, a="F", b="R")
    groot = GrootPublisher(pub_port, srv_port, address="127.0.0.1", max_msg_per_second=20)
    ctx = zmq.Context()
    try:
        groot.attach(t.root)
        t.ctx.status_listeners.append(groot.listener)
        t.tick()
        groot.end_of_tick()
        time.sleep(0.2)
        assert not groot.subscribed and groot.messages_sent == 0 and not groot._transitions
        sub = ctx.socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.connect(f"tcp://127.0.0.1:{pub_port}")
        deadline = time.monotonic() + 5
        while not groot.subscribed and time.monotonic() < deadline:  # the server thread reads the subscription
            time.sleep(0.02)
        assert groot.subscribed
        t.halt()
        assert sub.poll(2000), "no status message after the client subscribed"
        header, transitions = read_status_message(sub.recv())
        assert header[1] == RUNNING_ and header[2] == SUCCESS_  # the statuses when it subscribed, not at attach
        assert (1, RUNNING_, IDLE_) in [(u, p, s) for _, u, p, s in transitions]
        sub.close(linger=0)
        deadline = time.monotonic() + 5
        while groot.subscribed and time.monotonic() < deadline:  # the last unsubscription (the pipe closed)
            time.sleep(0.02)
        assert not groot.subscribed
    finally:
        ctx.destroy(linger=0)
        groot.close()


def test_a_port_in_use_is_an_error_naming_it_and_close_releases_both():
    pub_port, srv_port = _free_ports(2)
    first = GrootPublisher(pub_port, srv_port, address="127.0.0.1")
    try:
        with pytest.raises(GrootError, match=f"Groot publisher port {pub_port} on 127.0.0.1 is in use"):
            GrootPublisher(pub_port, _free_ports(1)[0], address="127.0.0.1")
        other = _free_ports(1)[0]
        with pytest.raises(GrootError, match=f"Groot server port {srv_port} on 127.0.0.1 is in use"):
            GrootPublisher(other, srv_port, address="127.0.0.1")
        # the publisher port of the failed attempt was released again
        GrootPublisher(other, _free_ports(1)[0], address="127.0.0.1").close()
    finally:
        first.close()
    again = GrootPublisher(pub_port, srv_port, address="127.0.0.1")  # close() released both ports
    again.close()
    with pytest.raises(GrootError, match="must differ"):
        GrootPublisher(1666, 1666)
    with pytest.raises(GrootError, match="port 70000 is not a TCP port"):
        GrootPublisher(70000, 1667)
