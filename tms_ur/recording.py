"""Recording the site's topics as a rosbag2 directory (MCAP storage) and reading it back, without ROS nodes.

No rosbag2 C++ ships with the ROS wheels, so the recorder writes with rosbags' ``Writer`` (metadata version 8,
MCAP storage): ``ros2 bag info``/``play`` and Foxglove open the directory. Each topic's connection carries the type's
message definition (``tms_ur.msgdefs``), so a reader decodes our own interface types too. Messages are stored as the
CDR bytes received (no decode/encode round trip); there is one MCAP file (nothing is split) and ``close`` writes
metadata.yaml, so a recorder stopped by SIGINT leaves a readable bag.

The reader (``read_bag``, ``bag_summary``) gives rclpy message instances in log-time order; the report's replay page
and the panel's replay read recordings through it.
"""

from __future__ import annotations

import importlib
import sys
import threading
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rclpy.serialization import deserialize_message
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.errors import ReaderError, WriterError

from tms_common.errors import TmsError
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR, Machine
from tms_ur.msgdefs import MsgDefError, message_definition, rihs01

__all__ = ["BagRecorder", "RecordedMessage", "RecordingError", "bag_sizes", "bag_summary", "bag_times", "plan_topics",
           "read_bag", "replay_topics"]


class RecordingError(TmsError):
    """A recording cannot be written or read; the message names the bag directory and the topic."""


@dataclass(frozen=True)
class RecordedMessage:
    """One recorded message: its topic, type ('pkg/msg/Type'), log time (ns) and the decoded rclpy message."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any


def replay_topics(machines: Iterable[Machine]) -> list[str]:
    """The site topics a replay needs, in order: /tf, /tf_static, the task states, the emergency signal, the soil
    totals and the mound's point cloud (the terrain source), and per machine its true pose, its joint states, its
    robot_description (latched: a bag opened in Foxglove draws the machines), for a carrier the soil in its vessel and
    for an excavator its bucket tip. /clock is not recorded: the log time is already the simulated time."""
    topics = ["/tf", "/tf_static", "/tms_ts/status", "/emergency_signal", "/sim/truth/soil",
              "/sim/sensors/mound/points"]
    for m in machines:
        name = m.model_name
        topics += [f"/sim/truth/{name}/pose", f"/{name}/joint_states", f"/{name}/robot_description"]
        if m.type == CRAWLER_DUMP:
            topics.append(f"/sim/truth/{name}/soil")
        if m.type == EXCAVATOR:
            topics.append(f"/sim/truth/{name}/bucket_tip")
    return list(dict.fromkeys(topics))


def plan_topics(graph: Mapping[str, Sequence[str]], wanted: Sequence[str],
                started: Iterable[str]) -> tuple[dict[str, str], dict[str, str]]:
    """Which wanted topics to start recording now: (topic -> type) for those the graph now gives one type and that are
    not ``started``, and (topic -> reason) for those published under several types (a connection has one type)."""
    started = set(started)
    new: dict[str, str] = {}
    problems: dict[str, str] = {}
    for topic in wanted:
        if topic in started or topic not in graph:
            continue
        types = sorted(set(graph[topic]))
        if len(types) == 1:
            new[topic] = types[0]
        elif types:
            problems[topic] = f"published with {len(types)} types {types}; a bag connection has one type"
    return new, problems


def _qos(reliable: bool, transient_local: bool, depth: int) -> Qos:
    zero = QosTime(sec=0, nsec=0)
    return Qos(history=QosHistory.KEEP_LAST, depth=depth,
               reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
               deadline=zero, lifespan=zero, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=zero, avoid_ros_namespace_conventions=False)


class BagRecorder:
    """Writes raw CDR messages of several topics into a new rosbag2 MCAP directory. Thread-safe."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RecordingError(f"recording {self.path}: exists already; a recording goes into a new directory")
        if not self.path.parent.is_dir():
            raise RecordingError(f"recording {self.path}: the parent directory {self.path.parent} does not exist")
        self._lock = threading.Lock()
        self._writer: Writer | None = Writer(self.path, version=8, storage_plugin=StoragePlugin.MCAP)
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise RecordingError(f"recording {self.path}: cannot open: {exc}") from exc
        self._connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}

    @property
    def topics(self) -> dict[str, str]:
        """Topic -> type of the topics added so far."""
        return {t: c.msgtype for t, c in self._connections.items()}

    def add_topic(self, topic: str, msgtype: str, *, reliable: bool = True, transient_local: bool = False,
                  depth: int = 10) -> None:
        """Add a topic of type ``msgtype`` ('pkg/msg/Type'); the offered QoS is stored for ``ros2 bag play``."""
        with self._lock:
            if self._writer is None:
                raise RecordingError(f"recording {self.path}: closed; cannot add topic {topic}")
            if topic in self._connections:
                raise RecordingError(f"recording {self.path}: topic {topic} added twice")
            try:
                definition, digest = message_definition(msgtype), rihs01(msgtype)
            except MsgDefError as exc:
                raise RecordingError(f"recording {self.path}: topic {topic}: {exc}") from exc
            self._connections[topic] = self._writer.add_connection(
                topic, msgtype, msgdef=definition, rihs01=digest,
                offered_qos_profiles=[_qos(reliable, transient_local, depth)])
            self.counts[topic] = 0

    def write(self, topic: str, log_time_ns: int, data: bytes | memoryview) -> None:
        """Store one message's CDR bytes as received, at ``log_time_ns``."""
        with self._lock:
            if self._writer is None:
                return  # a message arriving while the recorder stops is dropped, not an error
            conn = self._connections.get(topic)
            if conn is None:
                raise RecordingError(f"recording {self.path}: topic {topic} was not added")
            self._writer.write(conn, int(log_time_ns), bytes(data))
            self.counts[topic] += 1

    def close(self) -> None:
        """Finish the MCAP file and write metadata.yaml; idempotent."""
        with self._lock:
            writer, self._writer = self._writer, None
            if writer is not None:
                writer.close()


def _open(path: str | Path) -> Reader:
    path = Path(path)
    if not path.is_dir():
        raise RecordingError(f"recording {path}: not a directory (a rosbag2 recording is a directory)")
    if not (path / "metadata.yaml").is_file():
        raise RecordingError(f"recording {path}: no metadata.yaml; not a rosbag2 directory or not closed")
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise RecordingError(f"recording {path}: cannot read: {exc}") from exc
    return reader


def bag_summary(path: str | Path) -> dict[str, tuple[str, int]]:
    """Topic -> (type, message count) from the bag's metadata."""
    reader = _open(path)
    try:
        out: dict[str, tuple[str, int]] = {}
        for conn in reader.connections:
            _, count = out.get(conn.topic, (conn.msgtype, 0))
            out[conn.topic] = (conn.msgtype, count + conn.msgcount)
        return out
    finally:
        reader.close()


def bag_times(path: str | Path) -> tuple[int, int]:
    """(first, last) message log time of the bag in ns."""
    reader = _open(path)
    try:
        return reader.start_time, max(reader.start_time, reader.end_time - 1)  # rosbags' end_time is exclusive
    finally:
        reader.close()


def _message_class(path: Path, topic: str, msgtype: str) -> Any:
    pkg, kind, typ = ([*msgtype.split("/"), "", ""])[:3]
    try:
        if kind != "msg" or not typ:
            raise ValueError("expected 'pkg/msg/Type'")
        return getattr(importlib.import_module(f"{pkg}.msg"), typ)
    except (AttributeError, ImportError, ValueError) as exc:
        raise RecordingError(f"recording {path}: topic {topic}: type {msgtype} is not installed ({exc})") from exc


def read_bag(path: str | Path, topics: Sequence[str] | None = None) -> Iterator[RecordedMessage]:
    """The messages of ``topics`` (all when None) in log-time order, decoded into rclpy messages."""
    path = Path(path)
    reader = _open(path)
    try:
        known = {c.topic for c in reader.connections}
        if topics is not None:
            missing = [t for t in topics if t not in known]
            if missing:
                raise RecordingError(f"recording {path}: no topic {', '.join(missing)} (it holds {sorted(known)})")
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        classes = {c.id: _message_class(path, c.topic, c.msgtype) for c in conns}
        # rosbags merges the MCAP chunks by log time (heapq.merge), so the stream is in log-time order
        for conn, stamp, data in reader.messages(connections=conns):
            try:
                msg = deserialize_message(data, classes[conn.id])
            except Exception as exc:  # rclpy raises bare errors on bad CDR; name the culprit
                raise RecordingError(f"recording {path}: topic {conn.topic} at {stamp} ns: cannot decode "
                                     f"{conn.msgtype}: {exc}") from exc
            yield RecordedMessage(conn.topic, conn.msgtype, stamp, msg)
    finally:
        reader.close()



def bag_sizes(path: str | Path) -> dict[str, tuple[int, int]]:
    """Topic -> (message count, bytes of CDR) over the whole recording."""
    reader = _open(path)
    try:
        out: dict[str, tuple[int, int]] = {c.topic: (0, 0) for c in reader.connections}
        for conn, _stamp, data in reader.messages():
            n, b = out[conn.topic]
            out[conn.topic] = (n + 1, b + len(data))
        return out
    finally:
        reader.close()


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tms_ur.recording BAG``: each topic's type, count and size, per second of log time."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m tms_ur.recording BAG_DIR", file=sys.stderr)
        return 2
    try:
        types, sizes, (start, end) = bag_summary(args[0]), bag_sizes(args[0]), bag_times(args[0])
    except RecordingError as exc:
        print(f"recording: {exc}", file=sys.stderr)
        return 2
    span = max((end - start) * 1e-9, 1e-9)
    print(f"{args[0]}: {span:.1f} s of log time")
    for topic, (count, size) in sorted(sizes.items(), key=lambda kv: -kv[1][1]):
        print(f"  {topic:<40} {types[topic][0]:<36} {count:7d} msgs {size / 1e6:8.2f} MB {size / span / 1e3:8.1f} kB/s")
    total = sum(b for _, b in sizes.values())
    print(f"  total {total / 1e6:.2f} MB, {total / span / 1e3:.1f} kB per second of log time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
