"""The site-hosts layout without namespaces: DDS profiles, which node runs on which host, the host launch files."""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts" / "hosts"))
import site_hosts  # noqa: E402

NS = {"d": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def _profiles(name: str) -> ET.Element:
    return ET.parse(ROOT / "config" / "dds" / name).getroot()


def _text(root: ET.Element, path: str) -> list[str]:
    return [e.text.strip() for e in root.findall(path, NS)]


def test_host_profile_keeps_the_platform_lease_and_service_settings() -> None:
    platform, host = _profiles("fastdds_profiles.xml"), _profiles("fastdds_hosts.xml")
    for path in (".//d:participant//d:leaseDuration/d:sec", ".//d:participant//d:leaseAnnouncement/d:sec",
                 ".//d:publisher[@profile_name='service']//d:max_blocking_time/d:sec"):
        assert _text(host, path) == _text(platform, path) != [], path
    default = host.findall(".//d:participant[@is_default_profile='true']", NS)
    assert len(default) == 1


def test_host_profile_uses_only_udp_on_the_site_interface() -> None:
    host = _profiles("fastdds_hosts.xml")
    assert _text(host, ".//d:participant//d:useBuiltinTransports") == ["false"]  # no shared memory past a cut
    descriptors = host.findall(".//d:transport_descriptor", NS)
    assert [d.find("d:type", NS).text for d in descriptors] == ["UDPv4"]
    assert _text(host, ".//d:interfaceWhiteList/d:interface") == [site_hosts.SITE_IF]
    used = _text(host, ".//d:participant//d:userTransports/d:transport_id")
    assert used == _text(host, ".//d:transport_descriptor/d:transport_id")
    assert site_hosts.host_env()["FASTRTPS_DEFAULT_PROFILES_FILE"].endswith("config/dds/fastdds_hosts.xml")
    assert site_hosts.host_env()["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"


def test_every_paper_node_has_one_host_and_converters_sit_on_their_machine_pc() -> None:
    parts = {h: site_hosts.host_launch(h)["nodes"] for h in site_hosts.HOSTS}
    placed = sorted((n.get("namespace", ""), n["name"]) for nodes in parts.values() for n in nodes)
    import yaml

    paper = yaml.safe_load(site_hosts.PAPER_LAUNCH.read_text())["nodes"]
    assert placed == sorted((n.get("namespace", ""), n["name"]) for n in paper)
    for machine, pc in site_hosts.MACHINE_PC.items():
        bridges = [n for n in parts[pc] if n["executable"] == "com3_bridge"]
        assert [n["parameters"]["machine"] for n in bridges] == [machine]
        params = bridges[0]["parameters"]
        assert params["site_heartbeat_topic"] == "/tms_ts/subtask_heartbeat"
        assert params["site_timeout_s"] == site_hosts.SITE_TIMEOUT_S
    assert [n["executable"] for n in parts["plant"]] == ["sim_plant"]
    assert Path(parts["plant"][0]["parameters"]["config"]).is_absolute()
    assert {"tms_ts_manager", "tms_ts_subtasks"} <= {n["executable"] for n in parts["site_server"]}
    assert {n.get("nice") for n in parts["site_server"] if n["executable"] == "tms_ts_subtasks"} == {-10}


def test_host_launch_files_parse_and_overrides_apply(tmp_path: Path) -> None:
    from tms_launch.launch_file import parse_launch_file

    path = site_hosts.write_host_launch("plant", tmp_path, overrides={"sim_plant": {"speed": 1.0}})
    launch = parse_launch_file(path)
    assert [n.name for n in launch.nodes] == ["sim_plant"] and launch.nodes[0].parameters["speed"] == 1.0
    for host in site_hosts.HOSTS:
        parse_launch_file(site_hosts.write_host_launch(host, tmp_path))


def test_unknown_host_or_hostless_node_is_named() -> None:
    with pytest.raises(site_hosts.HostsError, match="unknown host 'zx120_pc'"):
        site_hosts.Site().ns("zx120_pc")
    with pytest.raises(site_hosts.HostsError, match="node 'x': container 'truck' is not a host"):
        site_hosts.host_of({"name": "x", "package": "p", "executable": "e", "container": "truck"})
    with pytest.raises(site_hosts.HostsError, match="machine 'zx120' has no PC host"):
        site_hosts.host_of({"name": "com3_bridge", "package": "com3_can", "executable": "com3_bridge",
                            "parameters": {"machine": "zx120"}})
