"""tms_model.machines: every kind's description parsed once, typed, with file:line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR, load_machine, parse_machine


def test_zx200_description() -> None:
    m = load_machine("zx200")
    assert m is load_machine("zx200")  # parsed once
    assert m.type == EXCAVATOR
    assert m.joint_names == ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
    assert m.joint("swing_joint").lower is None
    assert m.joint("boom_joint").upper == pytest.approx(-0.1)
    assert m.drives["swing_joint"].dead_time == pytest.approx(0.932)
    assert m.bucket is not None and m.bucket.capacity == pytest.approx(0.8)
    assert m.tracks.gauge == pytest.approx(2.19)
    assert m.footprint.length == pytest.approx(3.37)
    assert m.pilot_cutoff is not None and m.pilot_cutoff.solenoid_delay == pytest.approx(0.04)
    assert m.vessel is None
    with pytest.raises(AttributeError):
        m.kind = "other"  # type: ignore[misc]


def test_ic120_description() -> None:
    m = load_machine("ic120")
    assert m.type == CRAWLER_DUMP
    assert m.vessel is not None and m.vessel.max_angle == pytest.approx(1.134464)
    assert m.joint_names == ("vessel_joint",)
    assert m.footprint.width == pytest.approx(3.37)
    assert m.tracks.max_accel == pytest.approx(2.5)
    with pytest.raises(ConfigError, match="is a crawler_dump, expected a excavator"):
        m.require(EXCAVATOR)


def test_unknown_kind_names_the_file_searched() -> None:
    with pytest.raises(ConfigError, match=r"zx999.yaml: no such machine description.*known kinds: \['ic120', 'zx120', 'zx200'\]"):
        load_machine("zx999")


def _copy_with(tmp_path: Path, old: str, new: str, name: str = "zx200.yaml") -> Path:
    text = config_path("machines", name).read_text()
    assert old in text
    out = tmp_path / name
    out.write_text(text.replace(old, new, 1))
    return out


def test_typo_in_a_known_section_names_file_line_and_key(tmp_path: Path) -> None:
    path = _copy_with(tmp_path, "  pump_flow_lpm: 424", "  pump_flow_lpn: 424")
    text = path.read_text().splitlines()
    line = next(i for i, t in enumerate(text, 1) if "pump_flow_lpn" in t)
    with pytest.raises(ConfigError, match=rf"zx200.yaml:{line}: hydraulics.pump_flow_lpn: unknown key"):
        parse_machine(path)


def test_bad_limit_and_axis(tmp_path: Path) -> None:
    path = _copy_with(tmp_path, "position: [-1.137, -0.1]", "position: [-0.1, -1.137]")
    with pytest.raises(ConfigError, match=r"zx200.yaml:\d+: joints.boom_joint.position: lower limit must be below upper"):
        parse_machine(path)
    path = _copy_with(tmp_path, "axis: [0, 1, 0], position: [0.594", "axis: [1, 0, 0], position: [0.594")
    with pytest.raises(ConfigError, match=r"joints.arm_joint.axis: expected"):
        parse_machine(path)


def test_wrong_model_name_and_type(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"model_name: expected 'zx200'"):
        parse_machine(_copy_with(tmp_path, "model_name: zx200", "model_name: zx120"))
    with pytest.raises(ConfigError, match=r"type: unknown machine type 'backhoe'"):
        parse_machine(_copy_with(tmp_path, "type: excavator", "type: backhoe"))
