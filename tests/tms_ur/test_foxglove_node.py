"""``tms_ur_foxglove`` across processes: a publisher process, the node, and a Foxglove WebSocket client written from
the protocol (``websockets``): serverInfo, advertisements with the ros2msg definitions, subscriptions, message data
frames whose CDR payload deserialises to what was published; a bad bind fails at start naming it.

``python -m tests.tms_ur.test_foxglove_node publish`` is the publisher process.
"""

from __future__ import annotations

import asyncio
import json
import signal
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import rclpy
import websockets
from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState, PointCloud2, PointField
from std_msgs.msg import String

from tests.rosproc import executable
from tests.tms_ur.conftest import free_port
from tf2_msgs.msg import TFMessage
from tms_model.site import load_site
from tms_msg.msg import TaskState, TaskStatus
from tms_ur.foxglove_bridge import message_class
from tms_ur.msgdefs import message_definition

pytestmark = pytest.mark.integration

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
CHATTER = "/fg_test/chatter"  # not a site topic: reaches Foxglove by discovery
STATUS = "/tms_ts/status"  # a site topic of a project type (tms_msg/TaskStatus)
SHORT = "/fg_test/short_lived"  # its publisher goes on SIGUSR1: the channel is unadvertised
ONLY_SUB = "/fg_test/only_subscribed"  # in the graph with a subscriber only: carries no data, never advertised
URDF = '<robot name="fg_test"><link name="base_link"/></robot>'


def _tf(i: int, frame: str):
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = "map", frame
    t.header.stamp.sec, t.header.stamp.nanosec = 100 + i, 250
    t.transform.translation.x, t.transform.translation.y = 0.5 * i, -1.25
    t.transform.rotation.w = 1.0
    return TFMessage(transforms=[t])


def _chatter(i: int):
    return String(data=f"chatter {i}")


def _task_status(i: int):
    return TaskStatus(tasks=[TaskState(task_id=i, state=1, running_leaves=[f"leaf{i}"], message=f"tick {i}")])


def _stamped(msg, i: int):
    msg.header.frame_id = "map"
    msg.header.stamp.sec, msg.header.stamp.nanosec = 100 + i, 500
    return msg


def _cloud(i: int):
    fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1) for k, n in enumerate("xyz")]
    points = [(0.1 * i, 2.0, -0.5), (1.5, 0.25 * i, 3.0)]
    return _stamped(PointCloud2(height=1, width=len(points), fields=fields, is_bigendian=False, point_step=12,
                                row_step=12 * len(points), is_dense=True,
                                data=b"".join(struct.pack("<3f", *p) for p in points)), i)


def _pose(i: int):
    msg = _stamped(PoseStamped(), i)
    msg.pose.position.x, msg.pose.position.z, msg.pose.orientation.w = 0.1 * i, 1.0, 1.0
    return msg


def _joints(i: int):
    return _stamped(JointState(name=["swing_joint", "boom_joint"], position=[0.01 * i, -0.02 * i]), i)


def _stamp_seq(msg) -> int:
    return msg.header.stamp.sec - 100


def _machine() -> str:
    """A machine of the site's list (its topics are site topics the node bridges by default)."""
    return next(iter(load_site().machines))


def periodic() -> dict[str, tuple[str, Callable[[int], Any], Callable[[Any], int]]]:
    """topic -> (type, the i-th message, i of a message) of every topic the publisher sends at 20 Hz."""
    m = _machine()
    return {
        "/tf": ("tf2_msgs/msg/TFMessage", lambda i: _tf(i, "moving_frame"),
                lambda msg: msg.transforms[0].header.stamp.sec - 100),
        CHATTER: ("std_msgs/msg/String", _chatter, lambda msg: int(msg.data.split()[1])),
        STATUS: ("tms_msg/msg/TaskStatus", _task_status, lambda msg: msg.tasks[0].task_id),
        "/sim/sensors/mound/points": ("sensor_msgs/msg/PointCloud2", _cloud, _stamp_seq),
        f"/sim/truth/{m}/pose": ("geometry_msgs/msg/PoseStamped", _pose, _stamp_seq),
        f"/{m}/joint_states": ("sensor_msgs/msg/JointState", _joints, _stamp_seq),
    }


def latched() -> dict[str, tuple[str, Any]]:
    """topic -> (type, message) of the topics the publisher sends once, transient local, before the node starts."""
    return {"/tf_static": ("tf2_msgs/msg/TFMessage", _tf(7, "static_frame")),
            f"/{_machine()}/robot_description": ("std_msgs/msg/String", String(data=URDF))}


def publish() -> None:
    """The publisher process: the latched topics once, then the periodic ones at 20 Hz."""
    rclpy.init()
    node = rclpy.create_node("fg_test_publisher")
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    keep = []
    for topic, (msgtype, msg) in latched().items():
        keep.append(node.create_publisher(message_class(msgtype), topic, qos))
        keep[-1].publish(msg)
    pubs = [(node.create_publisher(message_class(msgtype), topic, 10), make)
            for topic, (msgtype, make, _) in periodic().items()]
    short = [node.create_publisher(String, SHORT, 10)]
    node.create_subscription(String, ONLY_SUB, lambda _msg: None, 10)
    drop = threading.Event()
    signal.signal(signal.SIGUSR1, lambda *_: drop.set())
    count = [0]

    def tick() -> None:
        count[0] += 1
        for pub, make in pubs:
            pub.publish(make(count[0]))
        if drop.is_set() and short:
            node.destroy_publisher(short.pop())

    node.create_timer(0.05, tick)
    print("publisher ready", flush=True)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass


class FoxgloveClient:
    """A Foxglove WebSocket protocol client: JSON text ops, binary message data frames (op 0x01)."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.server_info: dict | None = None
        self.channels: dict[str, dict] = {}  # topic -> advertised channel
        self.frames: dict[int, list[tuple[int, bytes]]] = {}  # subscription id -> [(log time, payload)]

    async def pump(self, until, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not until():
            left = deadline - time.monotonic()
            assert left > 0, f"timed out waiting for {what}; channels {sorted(self.channels)}"
            try:
                raw = await asyncio.wait_for(self.ws.recv(), left)
            except TimeoutError:
                continue
            if isinstance(raw, bytes):
                assert raw[0] == 0x01, f"unexpected binary opcode {raw[0]}"
                sub_id, log_time = struct.unpack_from("<IQ", raw, 1)
                self.frames.setdefault(sub_id, []).append((log_time, raw[13:]))
                continue
            msg = json.loads(raw)
            if msg["op"] == "serverInfo":
                self.server_info = msg
            elif msg["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in msg["channels"]})
            elif msg["op"] == "unadvertise":
                gone = set(msg["channelIds"])
                self.channels = {t: c for t, c in self.channels.items() if c["id"] not in gone}

    async def subscribe(self, subs: dict[int, str]) -> None:
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub_id, "channelId": self.channels[topic]["id"]} for sub_id, topic in subs.items()]}))


def _messages(client: FoxgloveClient, sub_id: int, msgtype: str) -> list:
    cls = message_class(msgtype)
    return [deserialize_message(payload, cls) for _, payload in client.frames.get(sub_id, [])]


def test_foxglove_client_sees_the_site_topics_as_published(procs) -> None:
    port = free_port()
    pub = procs([sys.executable, "-m", "tests.tms_ur.test_foxglove_node", "publish"], name="publisher")
    assert pub.wait_for("publisher ready", 60), pub.output
    node = procs([executable("tms_ur", "tms_ur_foxglove"), "--ros-args", "-p", f"port:={port}",
                  "-p", "exclude:=[/rosout]", "-p", "poll_period_s:=0.2"], name="foxglove")
    assert node.wait_for("Foxglove WebSocket server on ws://127.0.0.1:", 60), node.output
    sent, once = periodic(), latched()
    expected_types = {**{t: v[0] for t, v in sent.items()}, **{t: v[0] for t, v in once.items()}}

    async def session() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                                      max_size=None) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"  # foxglove-sdk's only subprotocol (README: Lichtblick)
            client = FoxgloveClient(ws)
            await client.pump(lambda: client.server_info is not None
                              and {*expected_types, SHORT} <= set(client.channels), 30,
                              "serverInfo and the advertisements")
            assert ONLY_SUB not in client.channels
            assert client.server_info["name"] == "tms_ur_foxglove"
            # read-only: no client publishing, services or parameters
            assert not {"clientPublish", "services", "parameters"} & set(client.server_info["capabilities"])
            assert "/rosout" not in client.channels  # excluded though every node publishes it
            for topic, msgtype in expected_types.items():
                ch = client.channels[topic]
                assert (ch["encoding"], ch["schemaEncoding"], ch["schemaName"]) == ("cdr", "ros2msg", msgtype), ch
                assert ch["schema"] == message_definition(msgtype), topic

            subs = dict(enumerate(expected_types, start=1))
            await client.subscribe(subs)
            await client.pump(lambda: all(len(client.frames.get(s, [])) >= (1 if t in once else 5)
                                          for s, t in subs.items()), 30, "message data on every subscription")

            for sub_id, topic in subs.items():
                got = _messages(client, sub_id, expected_types[topic])
                if topic in once:  # latched before the client came: the node's reader is transient local
                    assert got[0] == once[topic][1], topic
                    continue
                _, make, seq = sent[topic]
                seqs = [seq(m) for m in got]
                assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs), (topic, seqs)
                assert got == [make(i) for i in seqs], topic  # every field as published
            assert all(t > 0 for frames in client.frames.values() for t, _ in frames)

            # a second client joining /tf_static gets the latched transform too
            async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS) as ws2:
                second = FoxgloveClient(ws2)
                await second.pump(lambda: "/tf_static" in second.channels, 10, "the second client's advertisements")
                await second.subscribe({9: "/tf_static"})
                await second.pump(lambda: len(second.frames.get(9, [])) >= 1, 10, "/tf_static for the second client")
                assert _messages(second, 9, "tf2_msgs/msg/TFMessage")[0] == _tf(7, "static_frame")

            pub.signal(signal.SIGUSR1)  # the publisher drops SHORT's publisher: the channel goes
            await client.pump(lambda: SHORT not in client.channels, 15, f"the unadvertisement of {SHORT}")
            assert ONLY_SUB not in client.channels and set(expected_types) <= set(client.channels)

    asyncio.run(session())

    async def legacy_only() -> None:  # the pre-SDK name alone is refused at the handshake (old Lichtblick sends it)
        with pytest.raises(websockets.exceptions.InvalidStatus, match="HTTP 400"):
            async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.websocket.v1"]):
                pass

    asyncio.run(legacy_only())
    assert node.popen.poll() is None, node.output
    node.signal(signal.SIGINT)
    assert node.wait(15) == 0, node.output


def test_bad_bind_fails_at_start_naming_it(procs) -> None:
    remote = procs([executable("tms_ur", "tms_ur_foxglove"), "--ros-args", "-p", "host:=0.0.0.0"], name="remote")
    assert remote.wait(60) == 2, remote.output
    assert "bind address '0.0.0.0' is not loopback" in remote.output and "allow_remote" in remote.output
    assert "Foxglove WebSocket server on" not in remote.output

    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        busy = procs([executable("tms_ur", "tms_ur_foxglove"), "--ros-args", "-p", f"port:={port}"], name="busy")
        assert busy.wait(60) == 2, busy.output
        assert f"cannot serve on 127.0.0.1:{port}" in busy.output and "Address already in use" in busy.output

    # off loopback with the explicit setting: it serves (reached here over loopback)
    port = free_port()
    opened = procs([executable("tms_ur", "tms_ur_foxglove"), "--ros-args", "-p", "host:=0.0.0.0",
                    "-p", "allow_remote:=true", "-p", f"port:={port}"], name="opened")
    assert opened.wait_for(f"Foxglove WebSocket server on ws://0.0.0.0:{port}", 60), opened.output
    deadline = time.monotonic() + 10
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            assert time.monotonic() < deadline, opened.output
            time.sleep(0.1)


if __name__ == "__main__" and sys.argv[1:] == ["publish"]:
    publish()
