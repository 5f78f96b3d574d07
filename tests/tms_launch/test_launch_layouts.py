"""tms-launch layouts: the ``container`` key, ``--layout per-node|composed`` and ``--containers`` (no ROS started).

The launch files are parsed for real (executables resolved in the ament index of the venv); what is checked is
the set of processes each layout starts and what a container process inherits from its nodes' keys.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from com3_can.bus import IN_PROCESS_ENV, link_config, load_bus_config
from tms_common.errors import ConfigError
from tms_launch.launch_file import parse_launch_file, processes, with_parameters
from tms_launch.launcher import main

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "config" / "launch" / "paper_experiment.yaml"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "launch.yaml"
    path.write_text(text)
    return path


TWO_CONTAINERS = """\
name: t
nodes:
  - {name: a, package: tms_launch, executable: demo_talker, container: one, nice: 5, env: {X: "1"}}
  - {name: b, package: tms_launch, executable: demo_listener, container: two}
  - {name: c, package: tms_launch, executable: demo_listener, container: one, nice: 2, required: false,
     stop_grace_s: 10, on_exit: shutdown, ready_timeout: 20}
  - {name: d, package: tms_launch, executable: demo_talker}
"""


def test_composed_groups_a_containers_nodes_in_one_process_in_first_appearance_order(tmp_path):
    launch = parse_launch_file(_write(tmp_path, TWO_CONTAINERS))
    assert launch.containers == ("one", "two")
    procs = processes(launch, "composed")
    assert [(p.name, p.container, [n.name for n in p.nodes]) for p in procs] == [
        ("one", "one", ["a", "c"]), ("two", "two", ["b"]), ("d", None, ["d"])]
    one = procs[0]
    # per process: the lowest nice, the union of env, the sum of the stop graces (stopped one after another),
    # required when one node is, a job when one node is, the longest ready timeout
    assert one.nice == 2 and one.env == {"X": "1"} and one.stop_grace_s == 2.5 + 10
    assert one.required is True and one.on_exit == "shutdown" and one.ready_timeout == 90.0
    assert one.command[1:4] == ("-m", "tms_launch.container", "one")
    nodes = json.loads(one.command[4])
    assert [n["name"] for n in nodes] == ["a", "c"]
    assert nodes[0]["ros_args"][:3] == ["--ros-args", "-r", "__node:=a"] and nodes[1]["on_exit"] == "shutdown"
    # a node without a container key is its own process from its executable
    assert procs[2].command[0].endswith("lib/tms_launch/demo_talker")


def test_per_node_runs_every_node_from_its_executable_with_its_own_keys(tmp_path):
    launch = parse_launch_file(_write(tmp_path, TWO_CONTAINERS))
    procs = processes(launch, "per-node")
    assert [p.name for p in procs] == ["a", "b", "c", "d"]
    assert all(p.container is None for p in procs)
    c = procs[2]
    assert c.nice == 2 and c.required is False and c.stop_grace_s == 10 and c.ready_timeout == 20
    assert procs[0].env == {"X": "1"} and procs[1].env == {}


def test_containers_selects_only_those_containers_nodes_in_either_layout(tmp_path):
    launch = parse_launch_file(_write(tmp_path, TWO_CONTAINERS))
    assert [p.name for p in processes(launch, "composed", ["two"])] == ["two"]
    assert [p.name for p in processes(launch, "per-node", ["one"])] == ["a", "c"]
    with pytest.raises(ConfigError, match=r"no container\(s\) \['three'\]; the file has one, two"):
        processes(launch, "composed", ["two", "three"])
    with pytest.raises(ConfigError, match="unknown layout 'flat'"):
        processes(launch, "flat")


@pytest.mark.parametrize(("extra", "message"), [
    ("  - {name: e, package: tms_launch, executable: demo_talker, container: one, env: {X: '2'}}\n",
     "container 'one': env 'X' is '1' for node 'a' and '2' for node 'e'"),
    ("  - {name: e, package: tms_launch, executable: demo_talker, container: one, arguments: [--x]}\n",
     "node 'e' of container 'one' has 'arguments'"),
])
def test_nodes_that_cannot_share_a_process_are_refused_naming_them(tmp_path, extra, message):
    launch = parse_launch_file(_write(tmp_path, TWO_CONTAINERS + extra))
    with pytest.raises(ConfigError, match=message):
        processes(launch, "composed")
    assert len(processes(launch, "per-node")) == 5  # one process per node: no conflict


def test_a_container_name_must_be_an_identifier(tmp_path):
    text = "nodes:\n  - {name: a, package: tms_launch, executable: demo_talker, container: 'site server'}\n"
    with pytest.raises(
        ConfigError, match=r"launch.yaml:2: node 'a': container name 'site server' must be an identifier"
    ):
        parse_launch_file(_write(tmp_path, text))


def test_paper_experiment_composes_into_the_real_systems_computers():
    launch = parse_launch_file(PAPER)
    composed = {p.name: [n.fqn for n in p.nodes] for p in processes(launch, "composed")}
    assert composed == {
        "plant": ["/sim_plant", "/zx200/com3_bridge", "/ic120/com3_bridge"],
        "zx200_pc": ["/zx200/excavator_arm_controller", "/zx200/zx200_planner"],
        "ic120_pc": ["/ic120/ic120_localization", "/ic120/ic120_navigator", "/ic120/ic120_vessel"],
        "site_server": ["/subtasks_zx200", "/subtasks_ic120", "/tms_ts_manager", "/tms_ur_experiment"],
        "sensing_pc": ["/tms_sp_sensing", "/tms_sp_tf"],
    }
    assert len(processes(launch, "per-node")) == 14
    by_name = {p.name: p for p in processes(launch, "composed")}
    # the plant container holds both converters: both CAN links are in-process; no other process gets that
    assert by_name["plant"].env[IN_PROCESS_ENV] == "ic120,zx200"
    assert by_name["plant"].env["RMW_FASTRTPS_PUBLICATION_MODE"] == "ASYNCHRONOUS"
    assert all(IN_PROCESS_ENV not in p.env for n, p in by_name.items() if n != "plant")
    assert by_name["plant"].nice is None and by_name["zx200_pc"].nice == -10 and by_name["site_server"].nice is None
    assert by_name["site_server"].on_exit == "shutdown" and by_name["site_server"].stop_grace_s == 30 + 3 * 2.5
    for proc in processes(launch, "per-node"):
        assert IN_PROCESS_ENV not in proc.env


def test_the_can_link_is_in_process_only_for_the_named_machines_and_explicit_overrides_win(monkeypatch):
    cfg = load_bus_config("zx200")
    monkeypatch.delenv(IN_PROCESS_ENV, raising=False)
    assert link_config("zx200", cfg)["interface"] == "udp_multicast"
    monkeypatch.setenv(IN_PROCESS_ENV, "ic120,zx200")
    assert link_config("zx200", cfg) == {"interface": "virtual", "channel": "com3_zx200"}
    over = link_config("zx200", cfg, interface="udp_multicast", channel="239.1.2.3", port=4000)
    assert over == {"interface": "udp_multicast", "channel": "239.1.2.3", "port": 4000}
    monkeypatch.setenv(IN_PROCESS_ENV, "ic120")
    assert link_config("zx200", cfg)["interface"] == "udp_multicast"
    monkeypatch.setenv(IN_PROCESS_ENV, "zx200")
    with pytest.raises(ConfigError, match="no 'in_process' mapping"):
        link_config("zx200", {"interface": "udp_multicast", "channel": "239.1.2.3", "port": 1})


def test_cli_list_shows_each_layouts_processes_and_rejects_unknown_containers(capsys):
    assert main(["--list", "--layout", "composed", str(PAPER)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split("\t")[0] for line in lines] == ["plant", "zx200_pc", "ic120_pc", "site_server", "sensing_pc"]
    assert main(["--list", "--layout", "per-node", "--containers", "zx200_pc", str(PAPER)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "excavator_arm_controller\tnode\t/zx200/excavator_arm_controller",
        "zx200_planner\tnode\t/zx200/zx200_planner",
    ]
    assert main(["--list", "--containers", "nowhere", str(PAPER)]) == 2
    assert "no container(s) ['nowhere']" in capsys.readouterr().err


def test_layout_from_the_environment(capsys, monkeypatch):
    monkeypatch.setenv("TMS_LAYOUT", "per-node")
    assert main(["--list", "--containers", "plant", str(PAPER)]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 3


def test_param_overrides_set_a_nodes_parameter_and_name_what_does_not_fit():
    launch = parse_launch_file(PAPER)
    out = with_parameters(launch, ["tms_sp_sensing:blackboard_records=[SAMPLE_BLACKBOARD_SHIMIZU]",
                                   "tms_sp_sensing:approach_record=", "/zx200/excavator_arm_controller:rate_hz=25.0"])
    by = {n.fqn: n for n in out.nodes}
    assert by["/tms_sp_sensing"].parameters["blackboard_records"] == ["SAMPLE_BLACKBOARD_SHIMIZU"]
    assert by["/tms_sp_sensing"].parameters["approach_record"] == ""
    assert by["/zx200/excavator_arm_controller"].parameters["rate_hz"] == 25.0
    assert "-p" in by["/tms_sp_sensing"].ros_args() and launch.nodes != out.nodes  # the input is not changed
    for bad, culprit in (("nobody:x=1", "no node 'nobody'"), ("tms_sp_sensing=1", "NODE:KEY=VALUE"),
                         ("tms_sp_sensing:x=[1,", "not YAML")):
        with pytest.raises(ConfigError, match=culprit):
            with_parameters(launch, [bad])
