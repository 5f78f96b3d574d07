"""``tms_rc_identify`` finds a machine's real bus as the converter does (by name: its kind's config/can/<kind>.yaml
with the site's ``can`` changes, read through tms_common.schema), and a missing or bad file stops it with one line
naming the file and line, exit code 2 (no bus is opened, no plant started)."""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest

import tms_model.fleet
from tms_common.config import config_path, load_yaml
from tms_model.fleet import machine_kind
from tms_model.site import load_site
from tms_rc import identify


def test_a_real_bus_is_the_kinds_file_with_the_sites_changes_for_the_name() -> None:
    site = load_site()
    # a second machine of a kind: the kind's bus, on the port the site gives that name
    name = next(n for n, m in site.machines.items() if m.can.get("port") and n != m.kind)
    kind = machine_kind(name)
    data, _ = load_yaml(config_path("can", f"{kind}.yaml"))
    bus = identify.bus_config(name)
    assert bus["interface"] == data["interface"] and bus["channel"] == data["channel"]
    assert bus["port"] == site.machines[name].can["port"] != data["port"]
    assert "bridge" not in bus and "in_process" not in bus  # the converter's sections are not a bus option
    # the --can-* options win where given
    assert identify.bus_config(name, {"port": 40001, "channel": None})["port"] == 40001


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize(("text", "problem"), [
    ("interface: udp_multicast\nchannel: 239.1.2.3\nport: 43120\nbitrate: 500000\n",
     r"bad\.yaml:4: bitrate: unknown key"),
    ("interface: udp_multicast\nchannel: 239.1.2.3\nport: many\n", r"bad\.yaml:3: port: expected a port number"),
    ("interface: udp_multicast\nport: 43120\n", r"bad\.yaml:1: channel: missing required key"),
])
def test_a_bad_bus_file_stops_it_with_file_line_and_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str], text: str,
                                                           problem: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(text)
    monkeypatch.setattr(tms_model.fleet, "config_path", lambda *parts: bad)
    assert identify.main(["--machine", "zx200"]) == 2
    line = _one_error_line(capsys)
    assert line.startswith("tms_rc_identify: ") and re.search(problem, line), line


def test_a_missing_bus_file_or_an_unknown_machine_stops_it_with_one_line(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert identify.main(["--machine", "no_such_excavator"]) == 2
    assert "no_such_excavator" in _one_error_line(capsys)
    monkeypatch.setattr(tms_model.fleet, "config_path", lambda *parts: tmp_path / "missing.yaml")
    assert identify.main(["--machine", "zx200"]) == 2
    assert re.search(r"missing\.yaml: cannot read", _one_error_line(capsys))


def test_a_plant_file_without_the_machine_names_its_line(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    plant = tmp_path / "plant.yaml"
    plant.write_text("step_s: 0.01\nmachines: {ic120: machines/ic120.yaml}\n")
    assert identify.main(["--machine", "zx200", "--plant-config", str(plant)]) == 2
    assert re.search(r"plant\.yaml:2: machines: no machine 'zx200'", _one_error_line(capsys))


def test_a_plant_that_sends_nothing_stops_it_with_one_line_naming_the_bus(capsys: pytest.CaptureFixture[str],
                                                                         tmp_path: Path) -> None:
    """No plant on the bus (a python-can virtual channel nobody else uses): one line naming the frame it waited for
    and the bus, exit code 1, nothing written."""
    channel = f"silent_{random.randrange(1 << 30)}"
    out = tmp_path / "zx200.yaml"
    assert identify.main(["--machine", "zx200", "--can-interface", "virtual", "--can-channel", channel,
                          "--wait-s", "0.3", "--output", str(out)]) == 1
    line = _one_error_line(capsys)
    assert line.startswith("tms_rc_identify: no Front_Angular_Velocity frame within 0.3 s"), line
    assert channel in line and not out.exists()
