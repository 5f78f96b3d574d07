"""Pure core of the Foxglove WebSocket server ``tms_ur_foxglove``: access, topic selection, channel bookkeeping.

Nothing here imports rclpy or foxglove, so it is tested without ROS; ``tms_ur.nodes.tms_ur_foxglove`` wires it to
the ROS graph (raw CDR subscriptions) and to foxglove-sdk's WebSocket server.

The server is read-only: it advertises no client publishing, services or parameters. The Foxglove WebSocket
protocol has no authentication (a token as the panel's cannot be checked: Foxglove's web app connects from its
own origin), so a bind off loopback is refused unless ``allow_remote`` says so explicitly.
"""

from __future__ import annotations

import importlib
import re
import threading
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from tms_common.errors import ConfigError
from tms_model.machines import Machine
from tms_ur.panel_core import is_loopback
from tms_ur.recording import replay_topics

__all__ = [
    "BridgeConfig",
    "ChannelTable",
    "Plan",
    "QosChoice",
    "choose_qos",
    "message_class",
    "select_topics",
    "site_topics",
]

NODE = "tms_ur_foxglove"
# a ROS 2 topic name, fully qualified (what the graph reports): '/' then tokens of [A-Za-z0-9_] separated by '/'
_TOPIC = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)+$")
_MSGTYPE = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/msg/([A-Z][A-Za-z0-9]*)$")


def message_class(msgtype: str) -> Any:
    """The generated Python class of ``pkg/msg/Type`` (a raw subscription needs it); ConfigError naming the type."""
    m = _MSGTYPE.match(msgtype)
    if not m:
        raise ConfigError(f"{NODE}: {msgtype!r} is not a message type of the form pkg/msg/Type")
    try:
        cls = getattr(importlib.import_module(f"{m.group(1)}.msg"), m.group(2))
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"{NODE}: message type {msgtype} is not installed: {exc}") from None
    return cls


@dataclass(frozen=True)
class BridgeConfig:
    """Settings of ``tms_ur_foxglove`` (its ROS parameters; see tms_ur/README.md, section Foxglove)."""

    host: str = "127.0.0.1"
    port: int = 8765
    allow_remote: bool = False
    topics: tuple[str, ...] = ()
    discover: bool = True
    exclude: tuple[str, ...] = ()
    poll_period_s: float = 0.5

    def __post_init__(self) -> None:
        if not self.host:
            raise ConfigError(f"{NODE}: parameter host is empty")
        if not is_loopback(self.host) and not self.allow_remote:
            raise ConfigError(
                f"{NODE}: bind address {self.host!r} is not loopback; the Foxglove protocol has no authentication, "
                "so every host that reaches the port reads the bridged topics: set allow_remote:=true to serve it")
        if not 0 < self.port < 65536:
            raise ConfigError(f"{NODE}: port {self.port} out of range 1..65535")
        if not self.poll_period_s > 0.0:
            raise ConfigError(f"{NODE}: poll_period_s must be > 0, got {self.poll_period_s}")
        for name, values in (("topics", self.topics), ("exclude", self.exclude)):
            for topic in values:
                if not _TOPIC.match(topic):
                    raise ConfigError(f"{NODE}: {name} entry {topic!r} is not a fully qualified topic name")


def site_topics(machines: Iterable[Machine]) -> list[str]:
    """The site topics bridged by default: the ones a recording of the site takes (``recording.replay_topics``, with
    each machine's ``robot_description``, which Foxglove's 3-D panel draws the machine from)."""
    return replay_topics(machines)


def select_topics(graph: Mapping[str, Sequence[str]], config: BridgeConfig) -> tuple[dict[str, str], dict[str, str]]:
    """Which topics of the graph (topic -> its publishers' types) to bridge, and why others are left out.

    A listed topic (``config.topics``) is bridged once a publisher gives its type; any other topic only when
    ``config.discover``; ``config.exclude`` wins over both. A topic published under two types is left out (a channel
    has one schema). Returns (topic -> type, topic -> reason it is left out) for topics the config asks for.
    """
    chosen: dict[str, str] = {}
    problems: dict[str, str] = {}
    listed = set(config.topics)
    excluded = set(config.exclude)
    for topic, types in graph.items():
        if topic in excluded or not (config.discover or topic in listed):
            continue
        distinct = sorted(set(types))
        if len(distinct) != 1:
            problems[topic] = f"published with {len(distinct)} types {distinct}; a channel has one schema"
            continue
        chosen[topic] = distinct[0]
    return chosen, problems


@dataclass(frozen=True)
class QosChoice:
    reliable: bool
    transient_local: bool


def choose_qos(publishers: Sequence[tuple[bool, bool]]) -> QosChoice:
    """The subscription QoS that matches every publisher, given each one's (reliable, transient_local).

    A reliable reader does not match a best-effort writer and a transient-local reader does not match a volatile
    one, so each is asked only when every publisher offers it (the rule of ros2 bag and foxglove_bridge). With
    transient local the reader gets the latched messages (/tf_static, robot_description) when it joins.
    """
    if not publishers:
        return QosChoice(reliable=True, transient_local=False)
    return QosChoice(reliable=all(r for r, _ in publishers), transient_local=all(t for _, t in publishers))


@dataclass(frozen=True)
class Plan:
    """What to change after a graph poll: channels to close (topic gone or its type changed), then to open."""

    close: tuple[str, ...] = ()
    advertise: tuple[tuple[str, str], ...] = ()


@dataclass
class _Channel:
    topic: str
    msgtype: str
    channel_id: int
    clients: set[int] = field(default_factory=set)


class ChannelTable:
    """Advertised channels and the clients subscribed to each (the server calls in from its own thread: locked).

    The ROS subscription of a topic exists only while a client watches its channel (``wanted``); when another
    client subscribes to a channel already watched, the topic is marked for a fresh ROS subscription
    (``take_rejoined``) so a transient-local topic's latched messages reach that client too.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._by_topic: dict[str, _Channel] = {}
        self._by_id: dict[int, _Channel] = {}
        self._rejoined: set[str] = set()
        self._unavailable: dict[str, str] = {}

    def plan(self, selected: Mapping[str, str]) -> Plan:
        """Changes that bring the channels to ``selected`` (topic -> type); types marked unavailable are skipped."""
        with self._lock:
            close = [t for t, ch in self._by_topic.items() if selected.get(t) != ch.msgtype]
            open_ = [(t, ty) for t, ty in selected.items()
                     if (t not in self._by_topic or t in close) and ty not in self._unavailable]
        return Plan(close=tuple(close), advertise=tuple(open_))

    def mark_unavailable(self, msgtype: str, reason: str) -> bool:
        """Record that ``msgtype`` cannot be bridged (no definition, not importable); True the first time."""
        with self._lock:
            first = msgtype not in self._unavailable
            self._unavailable.setdefault(msgtype, reason)
            return first

    def added(self, topic: str, msgtype: str, channel_id: int) -> None:
        with self._lock:
            if topic in self._by_topic:
                raise ValueError(f"{NODE}: topic {topic} already has channel {self._by_topic[topic].channel_id}")
            ch = _Channel(topic, msgtype, channel_id)
            self._by_topic[topic] = ch
            self._by_id[channel_id] = ch

    def closed(self, topic: str) -> None:
        with self._lock:
            ch = self._by_topic.pop(topic, None)
            if ch is not None:
                self._by_id.pop(ch.channel_id, None)
            self._rejoined.discard(topic)

    def subscribe(self, channel_id: int, client_id: int) -> str | None:
        """A client subscribed to a channel; its topic (None for a channel this table does not know)."""
        with self._lock:
            ch = self._by_id.get(channel_id)
            if ch is None:
                return None
            if ch.clients and client_id not in ch.clients:
                self._rejoined.add(ch.topic)
            ch.clients.add(client_id)
            return ch.topic

    def unsubscribe(self, channel_id: int, client_id: int) -> None:
        with self._lock:
            ch = self._by_id.get(channel_id)
            if ch is not None:
                ch.clients.discard(client_id)

    def wanted(self) -> dict[str, str]:
        """Topics some client watches -> their types: the ROS subscriptions that should exist."""
        with self._lock:
            return {t: ch.msgtype for t, ch in self._by_topic.items() if ch.clients}

    def take_rejoined(self) -> set[str]:
        """Topics another client joined since the last call (cleared by the call)."""
        with self._lock:
            out, self._rejoined = self._rejoined, set()
            return out

    def channel_id(self, topic: str) -> int | None:
        with self._lock:
            ch = self._by_topic.get(topic)
            return None if ch is None else ch.channel_id

    def topics(self) -> dict[str, str]:
        with self._lock:
            return {t: ch.msgtype for t, ch in self._by_topic.items()}
