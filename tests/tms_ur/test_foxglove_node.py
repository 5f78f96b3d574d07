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
import time

import pytest
import rclpy
import websockets
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from std_msgs.msg import String
from tms_ur.msgdefs import message_definition

from tests.rosproc import executable
from tests.tms_ur.conftest import free_port
from tf2_msgs.msg import TFMessage
from tms_msg.msg import TaskState, TaskStatus
from tms_ur.foxglove_bridge import message_class

pytestmark = pytest.mark.integration

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
CHATTER = "/fg_test/chatter"  # not a site topic: reaches Foxglove by discovery
STATUS = "/tms_ts/status"  # a site topic of a project type (tms_msg/TaskStatus)


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


def publish() -> None:
    """The publisher process: /tf_static once (latched), then /tf, the chatter and the task status at 20 Hz."""
    rclpy.init()
    node = rclpy.create_node("fg_test_publisher")
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_publisher(TFMessage, "/tf_static", latched).publish(_tf(7, "static_frame"))
    pubs = [(node.create_publisher(TFMessage, "/tf", 10), lambda i: _tf(i, "moving_frame")),
            (node.create_publisher(String, CHATTER, 10), _chatter),
            (node.create_publisher(TaskStatus, STATUS, 10), _task_status)]
    count = [0]

    def tick() -> None:
        count[0] += 1
        for pub, make in pubs:
            pub.publish(make(count[0]))

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
    expected_types = {"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage",
                      CHATTER: "std_msgs/msg/String", STATUS: "tms_msg/msg/TaskStatus"}

    async def session() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                                      max_size=None) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"  # foxglove-sdk's only subprotocol (README: Lichtblick)
            client = FoxgloveClient(ws)
            await client.pump(lambda: client.server_info is not None and set(expected_types) <= set(client.channels),
                              30, "serverInfo and the advertisements")
            assert client.server_info["name"] == "tms_ur_foxglove"
            # read-only: no client publishing, services or parameters
            assert not {"clientPublish", "services", "parameters"} & set(client.server_info["capabilities"])
            assert "/rosout" not in client.channels  # excluded though every node publishes it
            for topic, msgtype in expected_types.items():
                ch = client.channels[topic]
                assert (ch["encoding"], ch["schemaEncoding"], ch["schemaName"]) == ("cdr", "ros2msg", msgtype), ch
                assert ch["schema"] == message_definition(msgtype), topic

            subs = {1: "/tf", 2: "/tf_static", 3: CHATTER, 4: STATUS}
            await client.subscribe(subs)
            await client.pump(lambda: all(len(client.frames.get(s, [])) >= (1 if s == 2 else 5) for s in subs),
                              30, "message data on every subscription")

            static = _messages(client, 2, "tf2_msgs/msg/TFMessage")
            assert static[0] == _tf(7, "static_frame")  # latched before the client came: transient local reader
            for sub_id, topic, make in ((1, "/tf", lambda i: _tf(i, "moving_frame")), (3, CHATTER, _chatter),
                                        (4, STATUS, _task_status)):
                got = _messages(client, sub_id, expected_types[topic])
                if topic == CHATTER:
                    seqs = [int(m.data.split()[1]) for m in got]
                elif topic == STATUS:
                    seqs = [m.tasks[0].task_id for m in got]
                else:
                    seqs = [m.transforms[0].header.stamp.sec - 100 for m in got]
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
