"""``tms_ur_foxglove``: a Foxglove WebSocket server bridging the site's ROS topics, for Foxglove and Lichtblick.

foxglove-sdk's server on ``host:port`` (127.0.0.1:8765; a bind off loopback only with ``allow_remote:=true``: the
protocol has no authentication). Every topic of ``topics`` (default the site's: /tf, /tf_static, /tms_ts/status,
/sim/truth/soil, /sim/sensors/mound/points and each machine's pose, joint states, robot_description and a carrier's
soil) and, with ``discover`` (default true), every other topic of the graph is advertised as a channel once a
publisher gives its type: encoding ``cdr``, schema encoding ``ros2msg`` with the type's concatenated definition
(``tms_ur.msgdefs.message_definition``). A topic is subscribed (raw CDR, QoS matching its publishers) only while a
client watches its channel, and its bytes are passed on as received, stamped with the node's clock (simulated time
under ``use_sim_time``). Read-only: no client publishing, services or parameters.
"""

from __future__ import annotations

from typing import Any

import foxglove
from foxglove.websocket import ChannelView, Client
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import StartupParams
from tms_model.fleet import load_named
from tms_model.site import load_site
from tms_ur.foxglove_bridge import BridgeConfig, ChannelTable, choose_qos, message_class, select_topics, site_topics
from tms_ur.msgdefs import message_definition


class _Listener:
    """foxglove-sdk's server listener (called on the server's thread): records who watches which channel."""

    def __init__(self, table: ChannelTable) -> None:
        self.table = table

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        self.table.subscribe(channel.id, client.id)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        self.table.unsubscribe(channel.id, client.id)


class FoxgloveNode(Node):
    """ROS side of the Foxglove server: polls the graph, keeps the channels and the raw subscriptions in step."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_foxglove", **kwargs)
        p = StartupParams(self)
        listed = [str(t) for t in p.value("topics", [""], "bridged topics; default the site's") if str(t)]
        if not listed:
            site = load_site()
            listed = site_topics(load_named(name, site=site) for name in site.machines)
        self.config = BridgeConfig(
            host=p.text("host", "127.0.0.1", "bind address; off loopback only with allow_remote"),
            port=p.integer("port", 8765, "TCP port", lo=1),
            allow_remote=bool(p.value("allow_remote", False, "serve a non-loopback host (no authentication)")),
            topics=tuple(listed),
            discover=bool(p.value("discover", True, "bridge every other topic of the graph too")),
            exclude=tuple(str(t) for t in p.value("exclude", [""], "topics never bridged") if str(t)),
            poll_period_s=p.number("poll_period_s", 0.5, "graph poll period [s]", lo=0.0, above=True),
        )
        self.table = ChannelTable()
        self.fg_context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self._subs: dict[str, tuple[Subscription, bool]] = {}  # topic -> (subscription, transient local)
        self._reported: set[str] = set()
        try:
            self.server = foxglove.start_server(name="tms_ur_foxglove", host=self.config.host, port=self.config.port,
                                                context=self.fg_context, server_listener=_Listener(self.table))
        except RuntimeError as exc:  # foxglove-sdk raises RuntimeError("FoxgloveError: Failed to bind port: ...")
            where = f"{self.config.host}:{self.config.port}"
            raise ConfigError(f"tms_ur_foxglove: cannot serve on {where}: {exc}") from None
        self.get_logger().info(f"Foxglove WebSocket server on ws://{self.config.host}:{self.server.port}")
        self._sync()
        self.create_timer(self.config.poll_period_s, self._sync)

    def _sync(self) -> None:
        """Channels after the graph, then ROS subscriptions after the clients' subscriptions."""
        # types as the publishers give them: the graph also lists topics only subscribed to, which carry no data
        graph = {topic: [i.topic_type for i in self.get_publishers_info_by_topic(topic)]
                 for topic, _ in self.get_topic_names_and_types()}
        graph = {topic: types for topic, types in graph.items() if types}
        selected, problems = select_topics(graph, self.config)
        for topic, reason in problems.items():
            self._report(topic, f"tms_ur_foxglove: {topic} not bridged: {reason}")
        plan = self.table.plan(selected)
        for topic in plan.close:
            self._unsubscribe(topic)
            self._channels.pop(topic).close()
            self.table.closed(topic)
        for topic, msgtype in plan.advertise:
            self._advertise(topic, msgtype)
        wanted = self.table.wanted()
        rejoined = self.table.take_rejoined()
        for topic in list(self._subs):
            if topic not in wanted or (topic in rejoined and self._subs[topic][1]):
                self._unsubscribe(topic)  # a fresh transient-local reader gets the latched messages again
        for topic, msgtype in wanted.items():
            if topic not in self._subs:
                self._subscribe(topic, msgtype)

    def _advertise(self, topic: str, msgtype: str) -> None:
        try:
            definition = message_definition(msgtype)
            message_class(msgtype)  # the raw subscription needs the type's Python class
        except Exception as exc:  # noqa: BLE001 - one type we cannot describe must not stop the others
            if self.table.mark_unavailable(msgtype, str(exc)):
                self.get_logger().warning(f"tms_ur_foxglove: type {msgtype} (topic {topic}) not bridged: {exc}")
            return
        channel = foxglove.Channel(topic, context=self.fg_context, message_encoding="cdr",
                                   schema=foxglove.Schema(name=msgtype, encoding="ros2msg",
                                                          data=definition.encode("utf-8")))
        self._channels[topic] = channel
        self.table.added(topic, msgtype, channel.id())

    def _subscribe(self, topic: str, msgtype: str) -> None:
        info = self.get_publishers_info_by_topic(topic)
        qos = choose_qos([(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE,
                           i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL) for i in info])
        profile = QoSProfile(
            depth=10,
            reliability=ReliabilityPolicy.RELIABLE if qos.reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.transient_local else DurabilityPolicy.VOLATILE)
        channel = self._channels[topic]
        clock = self.get_clock()
        sub = self.create_subscription(
            message_class(msgtype), topic, lambda raw: channel.log(raw, log_time=clock.now().nanoseconds),
            profile, raw=True)
        self._subs[topic] = (sub, qos.transient_local)

    def _unsubscribe(self, topic: str) -> None:
        entry = self._subs.pop(topic, None)
        if entry is not None:
            self.destroy_subscription(entry[0])

    def _report(self, key: str, text: str) -> None:
        if key not in self._reported:
            self._reported.add(key)
            self.get_logger().warning(text)

    def destroy_node(self) -> None:
        server = getattr(self, "server", None)
        if server is not None:
            server.stop()
        super().destroy_node()


def main() -> int:
    return run_node(FoxgloveNode)
