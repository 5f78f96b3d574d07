"""``tms_ur_recorder``: records the site's topics into a rosbag2 directory (MCAP storage), as ``ros2 bag record``.

Parameters (read-only): ``output`` (the bag directory; it must not exist), ``topics`` (default the site's topics a
replay needs, machine names from the site's list: ``tms_ur.recording.replay_topics``), ``poll_period_s`` (graph
poll, 0.5 s: a topic whose publisher appears later is picked up then). Each topic is subscribed raw (the CDR bytes are
stored as received) with the type its publishers give and a QoS matching them (/tf_static transient local). The log
time is the node's clock: simulated time under ``use_sim_time`` (messages arriving before the first /clock are held
and logged at its time), so a replay runs on the simulation's clock; header stamps are left as they are. On stop
(SIGINT/SIGTERM) the MCAP file and metadata.yaml are written, so the bag is readable.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import StartupParams
from tms_model.fleet import load_named
from tms_model.site import load_site
from tms_ur.foxglove_bridge import choose_qos, message_class
from tms_ur.recording import BagRecorder, RecordingError, plan_topics, replay_topics


class RecorderNode(Node):
    """Thin ROS side of :class:`tms_ur.recording.BagRecorder`: graph polling and raw subscriptions."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_recorder", **kwargs)
        p = StartupParams(self)
        output = p.text("output", "", "the bag directory to create (must not exist)")
        listed = [str(t) for t in p.value("topics", [""], "recorded topics; default the site's") if str(t)]
        period = p.number("poll_period_s", 0.5, "graph poll period [s]", lo=0.0, above=True)
        if not output:
            raise ConfigError("tms_ur_recorder: parameter output (the bag directory) is empty")
        if Path(output).exists():
            raise ConfigError(f"tms_ur_recorder: output {output} exists already; a recording needs a new directory")
        if not listed:
            site = load_site()
            listed = replay_topics(load_named(name, site=site) for name in site.machines)
        self.wanted = tuple(dict.fromkeys(listed))
        self.recorder = BagRecorder(output)
        self._subs: dict[str, Any] = {}
        self._held: list[tuple[str, bytes]] = []  # arrived before the first /clock (sim time 0)
        self._reported: set[str] = set()
        self._sync()
        # the graph poll runs on the steady clock: on simulated time a timer waits for /clock, and topics
        # published before the clock starts (the latched /tf_static) would not be subscribed until then
        self.create_timer(period, self._sync, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"tms_ur_recorder: recording {len(self.wanted)} topics into {output}")

    def _sync(self) -> None:
        new, problems = plan_topics(dict(self.get_topic_names_and_types()), self.wanted, self._subs)
        for topic, reason in problems.items():
            if topic not in self._reported:
                self._reported.add(topic)
                self.get_logger().warning(f"tms_ur_recorder: {topic} not recorded: {reason}")
        for topic, msgtype in new.items():
            info = self.get_publishers_info_by_topic(topic)
            qos = choose_qos([(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE,
                               i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL) for i in info])
            try:
                cls = message_class(msgtype)
                self.recorder.add_topic(topic, msgtype, reliable=qos.reliable, transient_local=qos.transient_local,
                                        depth=100)
            except (ConfigError, RecordingError) as exc:
                self._subs[topic] = None  # reported once, not retried every poll
                self.get_logger().warning(f"tms_ur_recorder: {topic} not recorded: {exc}")
                continue
            profile = QoSProfile(
                depth=100,  # the DDS reader's queue: bursts (a scan, /tf at 100 Hz) wait here while a callback runs
                reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local else DurabilityPolicy.VOLATILE)
            self._subs[topic] = self.create_subscription(cls, topic, lambda raw, t=topic: self._on_message(t, raw),
                                                         profile, raw=True)

    def _on_message(self, topic: str, raw: bytes) -> None:
        now = self.get_clock().now().nanoseconds
        if now == 0:
            self._held.append((topic, raw))  # use_sim_time before the first /clock: log it at the clock's start
            return
        if self._held:
            held, self._held = self._held, []
            for t, data in held:
                self.recorder.write(t, now, data)
        self.recorder.write(topic, now, raw)

    def destroy_node(self) -> None:
        recorder = getattr(self, "recorder", None)
        if recorder is not None:
            for t, data in self._held:  # the clock never started: keep them at time 0 rather than lose them
                recorder.write(t, 0, data)
            self._held = []
            recorder.close()
            # print, not the logger: after SIGINT the context is gone and /rosout cannot take it
            print(f"[tms_ur_recorder] closed {recorder.path} ({sum(recorder.counts.values())} messages)", flush=True)
        super().destroy_node()


def main() -> int:
    return run_node(RecorderNode, executor="events")  # half the CPU per message of the default (1000 msg/s of /tf)
