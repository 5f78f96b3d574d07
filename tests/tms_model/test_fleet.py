"""Machine names and kinds: the site's ``machines`` list, named descriptions and each machine's own CAN link."""

from __future__ import annotations

from pathlib import Path

import pytest

from com3_can.bus import link_config, load_bus_config
from tms_common.errors import ConfigError
from tms_model.fleet import load_named, machine_kind
from tms_model.machines import load_machine
from tms_model.site import load_site

SITE = Path(load_site().source)


def _site_with(tmp_path: Path, machines: str) -> Path:
    text = SITE.read_text()
    head, tail = text.split("machines:\n", 1)
    rest = tail[tail.index("\n\n"):]  # the next section after the machines block
    path = tmp_path / "site.yaml"
    path.write_text(head + "machines:\n" + machines + rest)
    return path


def test_names_resolve_to_kinds_and_named_descriptions() -> None:
    assert machine_kind("ic120_1") == machine_kind("ic120_2") == "ic120"
    one, kind = load_named("ic120_1"), load_machine("ic120")
    assert (one.kind, one.model_name, kind.model_name) == ("ic120", "ic120_1", "ic120")
    # ic120_ros2 names frames <namespace>_tf/<link>: the name replaces the kind in the prefix
    assert one.frame("base_link") == "ic120_1_tf/base_link"
    assert kind.frame("base_link") == "ic120_tf/base_link"
    assert load_named("zx200").frame("base_link") == "base_link"  # zx200_ros2: no prefix
    assert one.vessel == kind.vessel and one.joints == kind.joints


def test_unknown_name_lists_the_sites_machines() -> None:
    with pytest.raises(ConfigError, match=r"no machine 'ic120_9' in machines \(known: .*'ic120_1'.*\)"):
        load_named("ic120_9")


def test_each_machine_of_a_kind_has_its_own_link() -> None:
    kind, one, two = (load_bus_config(n) for n in ("ic120", "ic120_1", "ic120_2"))
    assert kind["channel"] == one["channel"] == two["channel"]
    assert len({kind["port"], one["port"], two["port"]}) == 3
    assert one["bridge"] == kind["bridge"]
    assert one["in_process"] == {"interface": "virtual", "channel": "com3_ic120_1"}
    assert load_bus_config("zx200")["in_process"]["channel"] == "com3_zx200"
    # every machine of the site: distinct udp_multicast links and in-process channels
    site = load_site()
    links = {n: load_bus_config(n) for n in site.machines}
    assert len({(c["channel"], c["port"]) for c in links.values()}) == len(links)
    assert len({c["in_process"]["channel"] for c in links.values()}) == len(links)


def test_two_machines_of_a_kind_on_one_port_are_refused(tmp_path: Path) -> None:
    path = _site_with(tmp_path, "  ic120: {kind: ic120}\n  ic120_1: {kind: ic120}\n")
    site = load_site(path)
    assert sorted(site.machines) == ["ic120", "ic120_1"]
    with pytest.raises(ConfigError, match=r"'ic120_1' and 'ic120' of the site would share the udp_multicast link"):
        load_bus_config("ic120_1", site=site)


def test_in_process_link_is_per_name(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMS_CAN_IN_PROCESS", "ic120_2")
    assert link_config("ic120_2", load_bus_config("ic120_2")) == {"interface": "virtual", "channel": "com3_ic120_2"}
    assert link_config("ic120_1", load_bus_config("ic120_1"))["interface"] == "udp_multicast"


@pytest.mark.parametrize(("entry", "problem"), [
    ("  ic-120: {kind: ic120}\n", "a machine name is a ROS namespace segment"),
    ("  ic120_1: {kind: ic120, colour: red}\n", "colour"),
    ("  ic120_1: {kind: ic120, can: {port: 0}}\n", "port"),
])
def test_malformed_machine_entries_name_file_and_key(tmp_path: Path, entry: str, problem: str) -> None:
    path = _site_with(tmp_path, entry)
    with pytest.raises(ConfigError, match=rf"site.yaml:\d+: machines.*{problem}"):
        load_site(path)


def test_tree_of_a_named_machine_uses_its_prefix() -> None:
    from tms_model.urdf import load_tree

    one, kind = load_tree("ic120_1"), load_tree("ic120")
    assert one.machine.frame("vessel_link") == "ic120_1_tf/vessel_link"
    assert [j.name for j in one.joints] == [j.name for j in kind.joints]
