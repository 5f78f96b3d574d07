"""The Foxglove server's pure core: access rule, default topics, topic selection, QoS choice, channel bookkeeping."""

from __future__ import annotations

import pytest
from std_msgs.msg import String

from tms_common.errors import ConfigError
from tms_model.fleet import load_named
from tms_model.machines import CRAWLER_DUMP
from tms_model.site import load_site
from tms_msg.msg import TaskStatus
from tms_ur.foxglove_bridge import (
    BridgeConfig,
    ChannelTable,
    Plan,
    QosChoice,
    choose_qos,
    message_class,
    select_topics,
    site_topics,
)
from tms_ur.recording import replay_topics


def test_loopback_default_and_remote_needs_explicit_setting() -> None:
    assert BridgeConfig().host == "127.0.0.1" and BridgeConfig().port == 8765
    for host in ("localhost", "127.0.0.2", "::1"):
        assert BridgeConfig(host=host).host == host
    with pytest.raises(ConfigError, match=r"'0\.0\.0\.0' is not loopback.*allow_remote"):
        BridgeConfig(host="0.0.0.0")
    with pytest.raises(ConfigError, match="'192.168.1.5' is not loopback"):
        BridgeConfig(host="192.168.1.5")
    assert BridgeConfig(host="0.0.0.0", allow_remote=True).allow_remote


@pytest.mark.parametrize(("kwargs", "culprit"), [
    ({"port": 0}, "port 0"), ({"port": 70000}, "port 70000"), ({"host": ""}, "host"),
    ({"poll_period_s": 0.0}, "poll_period_s"), ({"topics": ("tf",)}, "topics entry 'tf'"),
    ({"exclude": ("/a//b",)}, "exclude entry '/a//b'"), ({"topics": ("/9x",)}, "'/9x'"),
])
def test_bad_settings_name_the_culprit(kwargs: dict, culprit: str) -> None:
    with pytest.raises(ConfigError, match=culprit):
        BridgeConfig(**kwargs)


def test_site_topics_cover_every_machine_of_the_site() -> None:
    site = load_site()
    machines = [load_named(name, site=site) for name in site.machines]
    topics = site_topics(machines)
    assert len(topics) == len(set(topics))
    assert set(replay_topics(machines)) <= set(topics)  # what a recording takes
    for t in ("/tf", "/tf_static", "/tms_ts/status", "/sim/truth/soil", "/sim/sensors/mound/points"):
        assert t in topics
    assert machines, "the site lists machines"
    for m in machines:
        name = m.model_name
        for t in (f"/sim/truth/{name}/pose", f"/{name}/joint_states", f"/{name}/robot_description"):
            assert t in topics
        assert (f"/sim/truth/{name}/soil" in topics) == (m.type == CRAWLER_DUMP)
    assert all(BridgeConfig(topics=tuple(topics)).topics)  # every default is a valid topic name


def test_select_topics_listed_discovered_excluded_and_ambiguous() -> None:
    graph = {"/tf": ["tf2_msgs/msg/TFMessage"], "/other": ["std_msgs/msg/String"],
             "/rosout": ["rcl_interfaces/msg/Log"], "/two": ["std_msgs/msg/String", "std_msgs/msg/Int32"]}
    chosen, problems = select_topics(graph, BridgeConfig(topics=("/tf", "/absent"), exclude=("/rosout",)))
    assert chosen == {"/tf": "tf2_msgs/msg/TFMessage", "/other": "std_msgs/msg/String"}
    assert set(problems) == {"/two"} and "2 types" in problems["/two"]
    chosen, problems = select_topics(graph, BridgeConfig(topics=("/tf",), discover=False))
    assert chosen == {"/tf": "tf2_msgs/msg/TFMessage"} and problems == {}
    # exclude wins over the list
    chosen, _ = select_topics(graph, BridgeConfig(topics=("/tf",), exclude=("/tf",), discover=False))
    assert chosen == {}


def test_choose_qos_matches_every_publisher() -> None:
    assert choose_qos([(True, True)]) == QosChoice(reliable=True, transient_local=True)
    assert choose_qos([(True, True), (True, False)]) == QosChoice(reliable=True, transient_local=False)
    assert choose_qos([(False, False), (True, False)]) == QosChoice(reliable=False, transient_local=False)
    assert choose_qos([]) == QosChoice(reliable=True, transient_local=False)


def test_channel_table_plans_opens_closes_and_follows_clients() -> None:
    table = ChannelTable()
    plan = table.plan({"/a": "std_msgs/msg/String", "/b": "std_msgs/msg/Int32"})
    assert plan == Plan(close=(), advertise=(("/a", "std_msgs/msg/String"), ("/b", "std_msgs/msg/Int32")))
    table.added("/a", "std_msgs/msg/String", 1)
    table.added("/b", "std_msgs/msg/Int32", 2)
    with pytest.raises(ValueError, match="/a already has channel 1"):
        table.added("/a", "std_msgs/msg/String", 3)
    assert table.plan({"/a": "std_msgs/msg/String", "/b": "std_msgs/msg/Int32"}) == Plan()
    # /b changed type: closed and advertised again; /a gone: closed
    plan = table.plan({"/b": "std_msgs/msg/String"})
    assert plan == Plan(close=("/a", "/b"), advertise=(("/b", "std_msgs/msg/String"),))

    assert table.wanted() == {}
    assert table.subscribe(1, client_id=10) == "/a"
    assert table.subscribe(99, client_id=10) is None
    assert table.wanted() == {"/a": "std_msgs/msg/String"} and table.take_rejoined() == set()
    table.subscribe(1, client_id=11)  # a second client joins a watched channel: a fresh reader for latched data
    assert table.take_rejoined() == {"/a"} and table.take_rejoined() == set()
    table.unsubscribe(1, 10)
    assert table.wanted() == {"/a": "std_msgs/msg/String"}
    table.unsubscribe(1, 11)
    assert table.wanted() == {}
    table.closed("/a")
    assert table.channel_id("/a") is None and table.topics() == {"/b": "std_msgs/msg/Int32"}
    assert table.subscribe(1, 12) is None


def test_unavailable_type_is_reported_once_and_not_advertised_again() -> None:
    table = ChannelTable()
    assert table.mark_unavailable("pkg/msg/Missing", "no definition")
    assert not table.mark_unavailable("pkg/msg/Missing", "no definition")
    assert table.plan({"/m": "pkg/msg/Missing", "/s": "std_msgs/msg/String"}).advertise == (
        ("/s", "std_msgs/msg/String"),)


def test_message_class_resolves_installed_types_and_names_the_bad_one() -> None:
    assert message_class("std_msgs/msg/String") is String
    assert message_class("tms_msg/msg/TaskStatus") is TaskStatus
    for bad, culprit in (("std_msgs/String", "not a message type"), ("std_msgs/srv/String", "not a message type"),
                         ("no_such_pkg/msg/Thing", "no_such_pkg/msg/Thing is not installed"),
                         ("std_msgs/msg/NoSuchType", "std_msgs/msg/NoSuchType is not installed")):
        with pytest.raises(ConfigError, match=culprit):
            message_class(bad)
