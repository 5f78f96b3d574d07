"""tms_ur_recorder as a process over DDS: a publisher process publishes known counts on /tf_static (latched, before the
recorder starts), /tf, a tms_msg custom type and a topic that appears only after the recorder started; the recorder
is stopped with SIGINT; an independent reader (mcap + mcap_ros2, not rosbags) counts the messages per topic, and
metadata.yaml agrees. Run ``python -m tests.tms_ur.test_recorder_node publish`` for the publisher side alone."""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path

import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import DurabilityPolicy, QoSProfile
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from tests.rosproc import executable
from tf2_msgs.msg import TFMessage
from tms_msg.msg import TaskState
from tms_ur.recording import read_bag

COUNTS = {"/tf_static": 1, "/tf": 30, "/tms_ts/status": 7, "/late/topic": 9}
TYPES = {"/tf_static": "tf2_msgs/msg/TFMessage", "/tf": "tf2_msgs/msg/TFMessage",
         "/tms_ts/status": "tms_msg/msg/TaskState", "/late/topic": "std_msgs/msg/String"}


def publish() -> None:
    """The publisher process: latched /tf_static at once; the rest once the recorder subscribes to each topic."""
    rclpy.init()
    node = rclpy.create_node("recorder_test_publisher")
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static = node.create_publisher(TFMessage, "/tf_static", latched)
    static.publish(TFMessage(transforms=[TransformStamped(child_frame_id="static_link")]))
    print("static published", flush=True)

    def when_subscribed(pub, topic: str) -> None:
        deadline = time.monotonic() + 60
        while pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise SystemExit(f"no subscriber on {topic}")
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(0.3)  # the reliable reader is matched on both sides

    tf = node.create_publisher(TFMessage, "/tf", 100)
    status = node.create_publisher(TaskState, "/tms_ts/status", 100)
    when_subscribed(tf, "/tf")
    when_subscribed(status, "/tms_ts/status")
    for i in range(COUNTS["/tf"]):
        tf.publish(TFMessage(transforms=[TransformStamped(child_frame_id=f"l{i}")]))
        if i < COUNTS["/tms_ts/status"]:
            status.publish(TaskState(task_id=i, running_leaves=[f"leaf{i}"]))
        time.sleep(0.01)
    print("first topics published", flush=True)
    late = node.create_publisher(String, "/late/topic", 100)  # appears after the recorder started
    when_subscribed(late, "/late/topic")
    for i in range(COUNTS["/late/topic"]):
        late.publish(String(data=f"late{i}"))
        time.sleep(0.01)
    print("all published", flush=True)
    while rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)


def test_recorder_process_sigint_leaves_a_readable_bag(procs, tmp_path: Path) -> None:
    pub = procs([sys.executable, "-m", "tests.tms_ur.test_recorder_node", "publish"], name="publisher")
    assert pub.wait_for("static published", timeout=30), pub.output
    bag = tmp_path / "bag"
    topics = '["' + '","'.join(COUNTS) + '"]'
    rec = procs([executable("tms_ur", "tms_ur_recorder"), "--ros-args", "-p", f"output:={bag}",
                 "-p", f"topics:={topics}", "-p", "poll_period_s:=0.2"], name="recorder")
    assert pub.wait_for("all published", timeout=90), pub.output + rec.output
    time.sleep(1.0)  # the last messages reach the recorder
    assert not (bag / "metadata.yaml").exists()  # written on stop only
    rec.signal(signal.SIGINT)
    assert rec.wait(20) == 0, rec.output
    assert "closed" in rec.output, rec.output

    with open(bag / "bag.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        counts: dict[str, int] = {}
        types: dict[str, str] = {}
        leaves, late, static = [], [], []
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            types[channel.topic] = schema.name
            if channel.topic == "/tms_ts/status":
                leaves.append(decoded.running_leaves[0])
            elif channel.topic == "/late/topic":
                late.append(decoded.data)
            elif channel.topic == "/tf_static":
                static.append(decoded.transforms[0].child_frame_id)
    assert counts == COUNTS, rec.output
    assert types == TYPES
    assert leaves == [f"leaf{i}" for i in range(COUNTS["/tms_ts/status"])]
    assert late == [f"late{i}" for i in range(COUNTS["/late/topic"])]
    assert static == ["static_link"]

    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap" and meta["message_count"] == sum(COUNTS.values())
    listed = {e["topic_metadata"]["name"]: (e["topic_metadata"]["type"], e["message_count"])
              for e in meta["topics_with_message_count"]}
    assert listed == {t: (TYPES[t], c) for t, c in COUNTS.items()}
    durability = {e["topic_metadata"]["name"]: yaml.safe_load(e["topic_metadata"]["offered_qos_profiles"])[0]
                  ["durability"] for e in meta["topics_with_message_count"]}
    assert durability["/tf_static"] == 1 and durability["/tf"] == 2  # transient local matched; volatile


def test_recorder_refuses_an_existing_output(procs, tmp_path: Path) -> None:
    there = tmp_path / "there"
    there.mkdir()
    rec = procs([executable("tms_ur", "tms_ur_recorder"), "--ros-args", "-p", f"output:={there}"], name="recorder")
    assert rec.wait(30) == 2, rec.output
    assert f"output {there} exists already" in rec.output
    assert list(there.iterdir()) == []


if __name__ == "__main__" and sys.argv[1:] == ["publish"]:
    publish()


def _spin(node, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        node.executor_for_test.spin_once(timeout_sec=0.02)


def test_log_time_is_simulated_time(procs, ros_node, tmp_path: Path) -> None:
    """Under use_sim_time the log time is /clock's: a latched message heard before the first /clock is logged at
    the clock's first value, later ones at the clock of their arrival; header stamps stay as published."""
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    static = ros_node.create_publisher(TFMessage, "/tf_static", latched)
    held = TransformStamped(child_frame_id="held")
    held.header.stamp.sec = 7
    static.publish(TFMessage(transforms=[held]))
    clock = ros_node.create_publisher(Clock, "/clock", 10)
    tf = ros_node.create_publisher(TFMessage, "/tf", 100)
    bag = tmp_path / "bag"
    rec = procs([executable("tms_ur", "tms_ur_recorder"), "--ros-args", "-p", f"output:={bag}", "-p",
                 'topics:=["/tf_static", "/tf"]', "-p", "use_sim_time:=true", "-p", "poll_period_s:=0.2"],
                name="recorder")
    deadline = time.monotonic() + 20
    while min(p.get_subscription_count() for p in (tf, static, clock)) == 0:
        assert time.monotonic() < deadline, (rec.output, [p.get_subscription_count() for p in (tf, static, clock)])
        _spin(ros_node, 0.1)
    _spin(ros_node, 1.0)  # the latched message reaches the recorder before any /clock
    sent = []
    for i in range(10):
        now = Time(sec=1000 + i)
        clock.publish(Clock(clock=now))
        _spin(ros_node, 0.3)  # the recorder's clock takes the value before the message arrives
        tf.publish(TFMessage(transforms=[TransformStamped(child_frame_id=f"t{i}")]))
        sent.append(1000 + i)
        _spin(ros_node, 0.2)
    rec.signal(signal.SIGINT)
    assert rec.wait(20) == 0, rec.output
    got = list(read_bag(bag))
    static_msgs = [m for m in got if m.topic == "/tf_static"]
    assert len(static_msgs) == 1 and static_msgs[0].msg.transforms[0].header.stamp.sec == 7
    assert static_msgs[0].log_time_ns == 1000 * 10**9  # held until the first /clock
    tf_times = [m.log_time_ns / 1e9 for m in got if m.topic == "/tf"]
    assert tf_times == pytest.approx(sent), rec.output
