"""tms_ur.recording and tms_ur.msgdefs without ROS nodes: write a rosbag2 MCAP directory of several types (a Jazzy
type with nested types, our own tms_msg type, a peer package's type), read it back with our reader and with an
independent one (mcap + mcap_ros2's decoder, not rosbags), and the errors naming the bag and the topic."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import serialize_message
from std_msgs.msg import Bool

from tf2_msgs.msg import TFMessage
from tms_msg.msg import TaskState
from tms_ur.msgdefs import MsgDefError, message_definition
from tms_ur.recording import (
    BagRecorder,
    RecordingError,
    bag_sizes,
    bag_summary,
    bag_times,
    main,
    plan_topics,
    read_bag,
)

TOPICS = {
    "/tf": ("tf2_msgs/msg/TFMessage", 7),
    "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
    "/tms_ts/status": ("tms_msg/msg/TaskState", 4),
    "/sim/truth/zx200/pose": ("geometry_msgs/msg/PoseStamped", 5),
    "/emergency_signal": ("std_msgs/msg/Bool", 2),
}


def _message(topic: str, i: int):
    if topic.startswith("/tf"):
        t = TransformStamped(child_frame_id=f"link{i}")
        t.header.stamp = Time(sec=100 + i, nanosec=7)
        t.transform.translation.x = float(i)
        return TFMessage(transforms=[t, TransformStamped(child_frame_id="other")])
    if topic == "/tms_ts/status":
        return TaskState(task_id=i, state=TaskState.RUNNING, running_leaves=[f"leaf{i}", "b"], message="m")
    if topic == "/emergency_signal":
        return Bool(data=bool(i % 2))
    msg = PoseStamped()
    msg.header.frame_id = "map"
    msg.pose.position.y = 0.5 * i
    return msg


@pytest.fixture
def bag(tmp_path: Path) -> Path:
    path = tmp_path / "bag"
    rec = BagRecorder(path)
    for topic, (msgtype, _) in TOPICS.items():
        rec.add_topic(topic, msgtype, transient_local=topic == "/tf_static")
    # interleaved and deliberately written out of log-time order across topics
    t = 1_000_000_000
    for k, (topic, (_, count)) in enumerate(TOPICS.items()):
        for i in range(count):
            rec.write(topic, t + i * 10_000_000 + k, serialize_message(_message(topic, i)))
    rec.close()
    rec.close()  # idempotent
    return path


def test_round_trip_our_reader(bag: Path) -> None:
    got = list(read_bag(bag))
    assert len(got) == sum(c for _, c in TOPICS.values())
    assert [m.log_time_ns for m in got] == sorted(m.log_time_ns for m in got)
    by_topic: dict[str, list] = {}
    for m in got:
        assert m.msgtype == TOPICS[m.topic][0]
        by_topic.setdefault(m.topic, []).append(m.msg)
    tf = by_topic["/tf"]
    assert [m.transforms[0].child_frame_id for m in tf] == [f"link{i}" for i in range(7)]
    assert tf[3].transforms[0].header.stamp.sec == 103 and tf[3].transforms[0].transform.translation.x == 3.0
    assert [m.running_leaves[0] for m in by_topic["/tms_ts/status"]] == ["leaf0", "leaf1", "leaf2", "leaf3"]
    assert [m.data for m in by_topic["/emergency_signal"]] == [False, True]
    only = list(read_bag(bag, topics=["/sim/truth/zx200/pose"]))
    assert [m.msg.pose.position.y for m in only] == [0.0, 0.5, 1.0, 1.5, 2.0]


def test_summary_times_and_metadata(bag: Path) -> None:
    assert bag_summary(bag) == {t: (ty, c) for t, (ty, c) in TOPICS.items()}
    start, end = bag_times(bag)
    assert start == 1_000_000_000 and end == 1_000_000_000 + 6 * 10_000_000
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 8 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == sum(c for _, c in TOPICS.values())
    counts = {e["topic_metadata"]["name"]: e["message_count"] for e in meta["topics_with_message_count"]}
    assert counts == {t: c for t, (_, c) in TOPICS.items()}
    qos = {e["topic_metadata"]["name"]: yaml.safe_load(e["topic_metadata"]["offered_qos_profiles"])[0]
           for e in meta["topics_with_message_count"]}
    assert qos["/tf_static"]["durability"] == 1 and qos["/tf"]["durability"] == 2  # transient local / volatile
    assert [p.name for p in bag.iterdir() if p.suffix == ".mcap"] == ["bag.mcap"]


def test_independent_mcap_reader(bag: Path) -> None:
    """mcap + mcap_ros2 decode every message from the schema text alone (nested and custom types included)."""
    with open(bag / "bag.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {s.name: s for s in summary.schemas.values()}
        for msgtype, _ in TOPICS.values():
            assert schemas[msgtype].encoding == "ros2msg"
            assert schemas[msgtype].data.decode() == message_definition(msgtype)
        counts: dict[str, int] = {}
        leaves = []
        for _schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert channel.message_encoding == "cdr"
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/tms_ts/status":
                leaves.append(decoded.running_leaves[0])
            if channel.topic == "/tf":
                assert decoded.transforms[1].child_frame_id == "other"
    assert counts == {t: c for t, (_, c) in TOPICS.items()}
    assert leaves == ["leaf0", "leaf1", "leaf2", "leaf3"]


def test_message_definition_nested() -> None:
    text = message_definition("tf2_msgs/msg/TFMessage")
    assert text.startswith("geometry_msgs/TransformStamped[] transforms\n")
    for nested in ("geometry_msgs/TransformStamped", "std_msgs/Header", "builtin_interfaces/Time",
                   "geometry_msgs/Vector3", "geometry_msgs/Quaternion"):
        assert f"{'=' * 80}\nMSG: {nested}\n" in text
    own = message_definition("tms_msg/msg/TaskState")
    assert "string[] running_leaves" in own and "uint8 RUNNING=1" in own
    with pytest.raises(MsgDefError, match="no_such_pkg/msg/Nope"):
        message_definition("no_such_pkg/msg/Nope")
    with pytest.raises(MsgDefError, match="expected 'pkg/msg/Type'"):
        message_definition("justaname")


def test_writer_errors(tmp_path: Path) -> None:
    existing = tmp_path / "there"
    existing.mkdir()
    with pytest.raises(RecordingError, match=f"{existing}: exists already"):
        BagRecorder(existing)
    with pytest.raises(RecordingError, match="does not exist"):
        BagRecorder(tmp_path / "no" / "bag")
    rec = BagRecorder(tmp_path / "b")
    with pytest.raises(RecordingError, match="topic /x: .*no_pkg/msg/T"):
        rec.add_topic("/x", "no_pkg/msg/T")
    rec.add_topic("/y", "std_msgs/msg/Bool")
    with pytest.raises(RecordingError, match="topic /y added twice"):
        rec.add_topic("/y", "std_msgs/msg/Bool")
    with pytest.raises(RecordingError, match="topic /z was not added"):
        rec.write("/z", 1, b"")
    rec.close()
    assert bag_summary(tmp_path / "b") == {"/y": ("std_msgs/msg/Bool", 0)}


def test_reader_errors(bag: Path, tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match=f"{tmp_path / 'none'}: not a directory"):
        bag_summary(tmp_path / "none")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RecordingError, match=f"{empty}: no metadata.yaml"):
        list(read_bag(empty))
    with pytest.raises(RecordingError, match="no topic /nope"):
        list(read_bag(bag, topics=["/nope"]))
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "metadata.yaml").write_text("not: [a bag")
    with pytest.raises(RecordingError, match=f"{broken}: cannot read"):
        bag_summary(broken)
    # a type not installed on the reading side: the metadata names a package that does not exist
    meta = (bag / "metadata.yaml").read_text().replace("std_msgs/msg/Bool", "gone_msgs/msg/Bool")
    (bag / "metadata.yaml").write_text(meta)
    with pytest.raises(RecordingError, match="topic /emergency_signal: type gone_msgs/msg/Bool is not installed"):
        list(read_bag(bag, topics=["/emergency_signal"]))


def test_plan_topics() -> None:
    graph = {"/a": ["std_msgs/msg/Bool"], "/b": ["x/msg/A", "x/msg/B"], "/c": ["std_msgs/msg/Bool"]}
    new, problems = plan_topics(graph, ["/a", "/b", "/c", "/later"], started=["/c"])
    assert new == {"/a": "std_msgs/msg/Bool"}
    assert "/b" in problems and "2 types" in problems["/b"]


def test_sizes_and_cli(bag: Path, capsys) -> None:
    sizes = bag_sizes(bag)
    assert {t: n for t, (n, _) in sizes.items()} == {t: c for t, (_, c) in TOPICS.items()}
    one = len(serialize_message(_message("/emergency_signal", 0)))
    assert sizes["/emergency_signal"][1] == 2 * one
    assert main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert "0.1 s of log time" in out and "/tms_ts/status" in out and "tms_msg/msg/TaskState" in out
    assert main([str(bag / "nope")]) == 2 and "not a directory" in capsys.readouterr().err
