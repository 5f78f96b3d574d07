"""The arm controller takes its hydraulics from the identified file, never from the machine description's model."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

from tms_common.errors import ConfigError
from tms_model.machines import load_machine
from tms_rc.excavator.controller import controller_config, identified_file, load_controller_settings

IDENTIFIED = """machine: {name}
pump_flow_lpm: 400.0
pump_saturated: true
joints:
  swing_joint: {{dead_time_s: 0.9, lag_s: 0.4, flow_lpm_per_rad_s: [150, 160]}}
  boom_joint: {{dead_time_s: 0.6, lag_s: 0.3, flow_lpm_per_rad_s: [500, 700]}}
  arm_joint: {{dead_time_s: 0.5, lag_s: 0.2, flow_lpm_per_rad_s: [300, 250]}}
  bucket_joint: {{dead_time_s: 0.35, lag_s: 0.15, flow_lpm_per_rad_s: [200, 200]}}
"""


def _settings(tmp_path: Path):
    return dataclasses.replace(load_controller_settings(), identified=str(tmp_path / "{name}.yaml"))


def test_the_controller_takes_the_identified_figures_and_not_the_descriptions_hydraulics(tmp_path):
    (tmp_path / "zx120.yaml").write_text(IDENTIFIED.format(name="zx120"))
    settings = _settings(tmp_path)
    # the description without its hydraulic model: nothing of it may be needed
    machine = dataclasses.replace(load_machine("zx120"), drives=MappingProxyType({}), pump_flow=None)
    cfg = controller_config(settings, machine)
    assert cfg.dead_time_s.tolist() == pytest.approx(np.array([0.9, 0.6, 0.5, 0.35]) + settings.transport_delay_s)
    assert cfg.lag_s.tolist() == pytest.approx([0.4, 0.3, 0.2, 0.15])
    assert cfg.flow_per_rad_s.tolist() == [160.0, 700.0, 300.0, 200.0]  # the larger direction: the pump row is |dq|
    assert cfg.pump_flow_lpm == 400.0


def test_a_missing_identified_file_is_one_line_naming_it_and_the_command_that_makes_it(tmp_path):
    with pytest.raises(ConfigError) as err:
        controller_config(_settings(tmp_path), load_machine("zx200"))
    msg = str(err.value)
    assert "\n" not in msg
    assert str(tmp_path / "zx200.yaml") in msg and "tms_rc_identify --machine zx200" in msg


@pytest.mark.parametrize(("text", "key"), [
    (IDENTIFIED.format(name="zx200"), "machine"),  # another machine's file
    (IDENTIFIED.format(name="zx120").replace("  bucket_joint:", "  bucket:"), "joints"),
    (IDENTIFIED.format(name="zx120").replace("lag_s: 0.2", "lag_s: -0.2"), r"joints.arm_joint.lag_s"),
    (IDENTIFIED.format(name="zx120").replace("pump_flow_lpm: 400.0\n", ""), "pump_flow_lpm"),
    # read through tms_common.schema: unknown keys are refused, types checked, each error at its line
    (IDENTIFIED.format(name="zx120").replace("pump_saturated: true", "pump_saturated: true\npump_flow: 300"),
     "pump_flow"),
    (IDENTIFIED.format(name="zx120").replace("lag_s: 0.3,", "lag_s: 0.3, lag: 0.3,"), r"joints.boom_joint.lag"),
    (IDENTIFIED.format(name="zx120").replace("[300, 250]", "[300, fast]"), r"joints.arm_joint.flow_lpm_per_rad_s.1"),
    (IDENTIFIED.format(name="zx120").replace("pump_saturated: true", "pump_saturated: 1"), "pump_saturated"),
])
def test_a_bad_identified_file_names_the_key(tmp_path, text, key):
    (tmp_path / "zx120.yaml").write_text(text)
    with pytest.raises(ConfigError, match=rf"zx120.yaml:\d+: {key}: ") as err:
        controller_config(_settings(tmp_path), load_machine("zx120"))
    line = int(str(err.value).split("zx120.yaml:")[1].split(":")[0])
    leaf = key.split(".")[-1] if not key.split(".")[-1].isdigit() else key.split(".")[-2]
    # the line of the key (of its mapping when the key is missing)
    assert leaf in text.splitlines()[line - 1] or key == "joints" or "missing" in str(err.value), (line, str(err.value))
    assert "tms_rc_identify --machine zx120" in str(err.value) and "\n" not in str(err.value)


def test_every_site_excavator_has_its_identified_file_with_every_joint():
    settings = load_controller_settings()
    for name in ("zx200", "zx120"):
        cfg = controller_config(settings, load_machine(name))
        assert identified_file(settings, name).is_file()
        assert np.all(cfg.dead_time_s > settings.transport_delay_s) and np.all(cfg.lag_s > 0), name
        assert cfg.pump_flow_lpm > 0 and np.all(cfg.flow_per_rad_s[1:] > 0), name
