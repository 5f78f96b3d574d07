"""tms_model.machines: every kind's description parsed once, typed, with file:line errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics, site_excavator_kind
from tms_model.machines import CRAWLER_DUMP, DOZER, EXCAVATOR, PARSERS, TYPES, load_machine, parse_machine


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
    with pytest.raises(
        ConfigError,
        match=r"zx999.yaml: no such machine description.*known kinds: "
        r"\['d37pxi', 'ic120', 'mst110cr', 'mst2200vd', 'zx120', 'zx200'\]",
    ):
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
    with pytest.raises(
        ConfigError, match=r"zx200.yaml:\d+: joints.boom_joint.position: lower limit must be below upper"
    ):
        parse_machine(path)
    path = _copy_with(tmp_path, "axis: [0, 1, 0], position: [0.594", "axis: [1, 0, 0], position: [0.594")
    with pytest.raises(ConfigError, match=r"joints.arm_joint.axis: expected"):
        parse_machine(path)


def test_wrong_model_name_and_type(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"model_name: expected 'zx200'"):
        parse_machine(_copy_with(tmp_path, "model_name: zx200", "model_name: zx120"))
    with pytest.raises(ConfigError, match=r"type: unknown machine type 'backhoe'"):
        parse_machine(_copy_with(tmp_path, "type: excavator", "type: backhoe"))


@pytest.mark.parametrize("kind", ["mst110cr", "mst2200vd"])
def test_rotating_carriers_have_a_swing_in_bus_order(kind: str) -> None:
    m = load_machine(kind)
    assert m.type == CRAWLER_DUMP and m.kind == kind
    assert m.joint_names == ("rotate_joint", "vessel_joint")  # com3_ros's rot_dump_cmd order
    assert m.swing is not None and m.swing.lower is None and m.swing.upper is None  # 360 deg slew
    assert m.joint("rotate_joint").axis == (0.0, 0.0, 1.0) and m.joint("rotate_joint").velocity == m.swing.velocity
    # the vessel hangs on the rotating body: its hinge is relative to the slew centre
    v = m.joint("vessel_joint")
    assert v.parent == "body_link" and v.upper == pytest.approx(math.radians(60))
    assert tuple(a + b for a, b in zip(v.origin_xyz, m.swing.origin_xyz, strict=True)) == pytest.approx(
        m.vessel.hinge_xyz
    )
    assert m.drives["rotate_joint"].dead_time > 0 and m.home_pose == {"rotate_joint": 0.0, "vessel_joint": 0.0}
    assert m.vessel is not None and m.vessel.capacity == pytest.approx(6.0)
    assert m.dbc == "crawler_carrier_com3.dbc" and m.tf_prefix == f"{kind}_tf"


def test_ic120_has_no_swing_and_its_dbc() -> None:
    m = load_machine("ic120")
    assert m.swing is None and m.blade is None and m.dbc == "crawler_carrier_com3.dbc"
    assert load_machine("zx200").dbc == load_machine("zx120").dbc == "excavator_com3.dbc"


def test_d37pxi_is_a_dozer_with_a_blade() -> None:
    m = load_machine("d37pxi")
    assert m.type == DOZER and m.joint_names == ("lift_joint",)
    lift = m.joint("lift_joint")
    assert (lift.lower, lift.upper) == pytest.approx((-0.41015, 0.18675))  # d37pxi_description URDF
    assert lift.parent == "body_link" and lift.child == "blade_arm_link"
    assert m.blade is not None and m.blade.width == pytest.approx(3.17)
    assert m.tracks.max_speed == pytest.approx(1.0) and m.tf_prefix == "d37pxi_tf" and m.dbc == "dozer_com3.dbc"
    assert m.vessel is None and m.swing is None and m.bucket is None
    with pytest.raises(ConfigError, match="is a dozer, expected a crawler_dump"):
        m.require(CRAWLER_DUMP)


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, t in enumerate(path.read_text().splitlines(), 1) if needle in t)


def test_swing_section_errors_name_file_line_and_key(tmp_path: Path) -> None:
    path = _copy_with(tmp_path, "  velocity: 0.35 ", "  velocty: 0.35 ", "mst110cr.yaml")
    with pytest.raises(ConfigError, match=rf"mst110cr.yaml:{_line_of(path, 'velocty')}: swing.velocty: unknown key"):
        parse_machine(path)
    path = _copy_with(tmp_path, "  position: null ", "  position: [1.0, -1.0] ", "mst110cr.yaml")
    with pytest.raises(ConfigError, match=r"mst110cr.yaml:\d+: swing.position: lower limit must be below upper"):
        parse_machine(path)
    path = _copy_with(tmp_path, "  position: null ", "  position: [-4.0, 4.0] ", "mst110cr.yaml")
    with pytest.raises(ConfigError, match=r"swing.position: limits must lie in \[-pi, pi\]"):
        parse_machine(path)
    path = _copy_with(tmp_path, "  swing: {dead_time_s", "  swing: {dead_time: 0.1, dead_time_s", "mst110cr.yaml")
    with pytest.raises(ConfigError, match=r"mst110cr.yaml:\d+: hydraulics.swing.dead_time: unknown key"):
        parse_machine(path)
    # hydraulics of a swing on a carrier without one (the IC120)
    path = _copy_with(tmp_path, "  tracks: {dead_time_s: 0.2, time_constant_s: 0.4",
                      "  swing: {dead_time_s: 0.3, time_constant_s: 0.3, angle_gain: 2.0}\n"
                      "  tracks: {dead_time_s: 0.2, time_constant_s: 0.4", "ic120.yaml")
    with pytest.raises(
        ConfigError, match=r"ic120.yaml:\d+: hydraulics.swing: hydraulics of a swing, but the machine has no swing"
    ):
        parse_machine(path)


def test_blade_and_can_section_errors(tmp_path: Path) -> None:
    path = _copy_with(tmp_path, "  width: 3.17 ", "  widht: 3.17 ", "d37pxi.yaml")
    with pytest.raises(ConfigError, match=rf"d37pxi.yaml:{_line_of(path, 'widht')}: blade.widht: unknown key"):
        parse_machine(path)
    path = _copy_with(tmp_path, "axis: [0, 1, 0], position: [-0.41015", "axis: [0, 0, 1], position: [-0.41015",
                      "d37pxi.yaml")
    with pytest.raises(ConfigError, match=r"d37pxi.yaml:\d+: blade.lift_joint: the blade lifts about y"):
        parse_machine(path)
    path = _copy_with(tmp_path, "can: {dbc: dozer_com3.dbc}", "can: {dbc: ../dozer.txt}", "d37pxi.yaml")
    with pytest.raises(ConfigError, match=r"d37pxi.yaml:\d+: can.dbc: expected a DBC file name"):
        parse_machine(path)
    path = _copy_with(tmp_path, "can: {dbc: dozer_com3.dbc}", "can: {dbc: dozer_com3.dbc, bus: x}", "d37pxi.yaml")
    with pytest.raises(ConfigError, match=r"d37pxi.yaml:\d+: can.bus: unknown key"):
        parse_machine(path)
    path = _copy_with(tmp_path, "can: {dbc: dozer_com3.dbc}", "", "d37pxi.yaml")
    with pytest.raises(ConfigError, match=r"d37pxi.yaml:\d+: can: missing required key"):
        parse_machine(path)


def test_types_are_the_parser_table() -> None:
    assert TYPES == tuple(PARSERS) == (EXCAVATOR, CRAWLER_DUMP, DOZER)
    kinds = [p.stem for p in config_path("machines", "zx200.yaml").parent.glob("*.yaml")]
    assert {load_machine(k).type for k in kinds} == set(TYPES)


def test_default_kinematics_are_the_site_first_excavator() -> None:
    kind = site_excavator_kind()
    assert load_machine(kind).type == EXCAVATOR
    assert load_kinematics().kind == kind
