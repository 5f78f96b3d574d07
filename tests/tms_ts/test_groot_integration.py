"""Groot 1 attaches to a real ``tms_ts_manager`` process: a client written from the protocol (pyzmq REQ for the tree,
SUB for the status changes, the BT_logger reader of test_groot) reads the tree of a running task and receives its
status changes; the delay from the scheduler's stamp of each change (taken in its tick) to reception on this
machine's clock is < 100 ms. A second manager on the same Groot port stops at start-up naming the port."""

from __future__ import annotations

import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zmq

from tests.rosproc import ROOT, executable
from tests.tms_ts.test_groot import RUNNING_, SUCCESS_, read_status_message, read_tree
from tests.tms_ts.test_integration import _handoff_tree, _seed, _state

pytestmark = pytest.mark.integration


def _free_port_pair() -> int:
    """A port P with P and P + 1 free (the publisher and the server port)."""
    for _ in range(100):
        with socket.socket() as a:
            a.bind(("127.0.0.1", 0))
            port = a.getsockname()[1]
            with socket.socket() as b:
                try:
                    b.bind(("127.0.0.1", port + 1))
                except OSError:
                    continue
        return port
    raise AssertionError("no two consecutive free ports")


def _subscribe(port: int, out: Path) -> None:
    """The client's SUB side as a process of its own (``python -m tests.tms_ts.test_groot_integration PORT FILE``):
    each message is stamped on reception and written at once, one ``<epoch s> <hex>`` line, with no other thread of
    the test (rclpy's spinning) holding its interpreter."""
    ctx = zmq.Context()
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(f"tcp://127.0.0.1:{port}")
    with out.open("w") as f:
        print("subscribed", flush=True)
        while True:
            data = sub.recv()
            at = time.time()
            f.write(f"{at!r} {data.hex()}\n")
            f.flush()


class GrootClient:
    """What Groot 1's monitor does: REQ the tree, SUB the status messages (stamped on reception)."""

    def __init__(self, port: int) -> None:
        self.ctx = zmq.Context()
        self.sub = self.ctx.socket(zmq.SUB)
        self.sub.setsockopt(zmq.SUBSCRIBE, b"")
        self.sub.connect(f"tcp://127.0.0.1:{port}")
        self.server = f"tcp://127.0.0.1:{port + 1}"
        self.messages: list[tuple[float, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    def _receive(self) -> None:
        while not self._stop.is_set():
            if self.sub.poll(50):
                data = self.sub.recv()
                self.messages.append((time.time(), data))

    def tree(self, timeout_s: float = 5.0) -> dict:
        req = self.ctx.socket(zmq.REQ)
        req.setsockopt(zmq.LINGER, 0)
        req.connect(self.server)
        req.send(b"")
        assert req.poll(int(timeout_s * 1000)), f"no tree from {self.server}"
        buf = req.recv()
        req.close()
        return read_tree(buf)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.ctx.destroy(linger=0)


def test_groot1_client_reads_the_running_tree_and_its_status_changes_within_100_ms(ts_system, procs, tmp_path):
    from tms_msg.msg import TaskIds, TaskState

    port = _free_port_pair()
    _seed(ts_system.store)
    ts_system.store.add_task(_handoff_tree("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere", "load_point",
                                           "IC120_TURN", "ZX200_TURN"), task_id=1, description="ic120 side")
    ts_system.store.add_task(_handoff_tree("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose",
                                           "ZX200_TURN", "IC120_TURN"), task_id=2, description="zx200 side")
    # groot_task_id 1: Groot stays on task 1 after it ends (with -1 it would move on to task 2, still running)
    system = ts_system.start(stub_duration_s=0.2, manager_args=("-p", f"groot_port:={port}", "-p", "groot_task_id:=1"))
    client = GrootClient(port)
    out = tmp_path / "groot_messages.txt"
    sub = subprocess.Popen([sys.executable, "-m", "tests.tms_ts.test_groot_integration", str(port), str(out)],
                           cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert sub.stdout.readline().strip() == "subscribed"
        time.sleep(0.5)  # the subscription reaches the PUB socket before the first change (ZMQ's slow joiner)
        system.publish("/tms_ts/start", TaskIds(task_ids=[1, 2]))
        manager = system.procs["manager"]
        assert manager.wait_for(f"Groot: task 1's tree (7 nodes) on ports {port} (publisher) / {port + 1}", 30), \
            manager.output[-3000:]
        tree = client.tree()
        assert tree["root_uid"] == 1
        assert [(n["uid"], n["registration_name"]) for n in tree["nodes"]] == [
            (1, "Repeat"), (2, "Sequence"), (3, "KeepRunningUntilFlgup"), (4, "BlackboardValueReaderMongo"),
            (5, "LeafNodeIc120"), (6, "MongoValueWriter"), (7, "MongoValueWriter")]
        assert tree["nodes"][0]["children"] == [2] and tree["nodes"][1]["children"] == [3, 5, 6, 7]
        assert tree["nodes"][4]["ports"]["subtask_name"] == "st_ic120_navigate_anywhere"

        # a second manager on the same ports: refused at start-up, naming the port (no silent fallback)
        second = procs([executable("tms_ts", "tms_ts_manager"), "--ros-args", "-r", "__node:=second_manager",
                        "-p", f"db_path:={system.db}", "-p", f"groot_port:={port}"], name="second")
        assert second.wait(60) == 2, second.output
        assert f"Groot publisher port {port} on * is in use" in second.output, second.output

        system.wait(lambda: _state(system, 1) == TaskState.SUCCESS and _state(system, 2) == TaskState.SUCCESS, 120,
                    "both handoff tasks to succeed")
        time.sleep(0.3)  # the last window is flushed
        assert "Groot: task 2" not in manager.output  # groot_task_id holds task 1
    finally:
        client.close()
        sub.kill()
        sub.wait(10)

    lines = [line.split() for line in out.read_text().splitlines()]
    received = [(float(at), *read_status_message(bytes.fromhex(data))) for at, data in lines]
    transitions = [(at, *t) for at, _, ts in received for t in ts]
    assert transitions, "no status change received"
    leaf = [(prev, status) for _, _, uid, prev, status in transitions if uid == 5]
    assert leaf.count((0, RUNNING_)) == 5 and leaf.count((RUNNING_, SUCCESS_)) == 5, str(leaf)  # five rounds
    assert (RUNNING_, SUCCESS_) in [(p, s) for _, _, uid, p, s in transitions if uid == 1]  # the Repeat ended
    # each message's header is the state the previous messages built (Groot redraws from it)
    state = {uid: 0 for uid in range(1, 8)}
    for _, header, ts in received:
        assert header == state
        for _, uid, _, status in ts:
            state[uid] = status
    delays = [at - stamp for at, stamp, *_ in transitions]
    median, worst = statistics.median(delays), max(delays)
    print(f"\nGroot 1 client: {len(received)} messages, {len(transitions)} status changes; delay from the scheduler's "
          f"stamp to reception: median {median * 1000:.1f} ms, max {worst * 1000:.1f} ms")
    assert min(delays) >= -0.001, min(delays)  # one clock: no change is received before it happened
    assert worst < 0.100, f"a status change arrived {worst * 1000:.1f} ms after the tick"


SLEEPS = '<root><BehaviorTree ID="{id}"><Sequence name="{name}"><Sleep msec="{ms}"/></Sequence></BehaviorTree></root>'


def test_groot_follows_the_earliest_running_task_and_groot_task_id_picks_one(tmp_path, domain):
    """-1: the earliest started task still running, then the next one; ``groot_task_id`` switches (read every tick).
    The manager runs in this process (its real node, ports and executor); the client is the Groot 1 one above."""
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from tms_common.node import make_executor
    from tms_db import open_store
    from tms_ts.nodes.tms_ts_manager import TaskManager

    db = str(tmp_path / "db")
    with open_store(path=db) as store:
        store.add_task(SLEEPS.format(id="A", name="first", ms=1500), task_id=1)
        store.add_task(SLEEPS.format(id="B", name="second", ms=60000), task_id=2)
        store.add_task(SLEEPS.format(id="C", name="third", ms=60000), task_id=3)
    port = _free_port_pair()
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = TaskManager(context=ctx, parameter_overrides=[
        Parameter("db_path", value=db), Parameter("groot_port", value=port),
        Parameter("groot_address", value="127.0.0.1")])
    ex = make_executor("events", context=ctx)
    ex.add_node(node)
    client = GrootClient(port)

    def spin_until(what, timeout_s=20.0):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.02)
            if what():
                return True
        return False

    def published() -> str:
        return client.tree()["nodes"][0]["instance_name"]

    try:
        node.start_tasks([1, 2, 3])
        assert spin_until(lambda: node._groot_run is not None and node._groot_run.task_id == 1)
        assert published() == "first"
        assert spin_until(lambda: node._groot_run.task_id == 2), "Groot did not move on when task 1 ended"
        assert published() == "second"
        node.set_parameters([Parameter("groot_task_id", value=3)])
        assert spin_until(lambda: node._groot_run.task_id == 3)
        assert published() == "third"
        node.set_parameters([Parameter("groot_task_id", value=1)])  # task 1 has ended: Groot stays on task 3
        spin_until(lambda: False, 0.5)
        assert node._groot_run.task_id == 3 and published() == "third"
    finally:
        client.close()
        ex.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.shutdown(context=ctx)


if __name__ == "__main__":
    _subscribe(int(sys.argv[1]), Path(sys.argv[2]))
