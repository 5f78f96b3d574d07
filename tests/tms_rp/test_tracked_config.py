"""One navigation stack, configured per kind: nav files over the default, names' frames, RTK relay (no ROS)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.fleet import machine_name, vessel_swing_joint
from tms_model.machines import load_machine
from tms_rp.tracked.config import load_nav_config, nav_path_for
from tms_rp.tracked.rtk import GlobalPoseRelay


def test_each_kind_reads_its_nav_file_over_the_default_and_its_description() -> None:
    ic, ic1, zx = (load_nav_config(machine=n) for n in ("ic120", "ic120_1", "zx200"))
    assert Path(ic.file).name == Path(ic1.file).name == "tracked_nav.yaml"  # the IC120 runs on the default
    assert (ic.footprint.length, ic.footprint.width) == (6.05, 3.37)  # config/machines/ic120.yaml
    assert ic.machine.frame("base_link") == "ic120_tf/base_link"
    assert ic1.machine.frame("base_link") == "ic120_1_tf/base_link" and ic1.machine.model_name == "ic120_1"
    assert ic.reverse and zx.reverse
    # the ZX200's file holds only what differs: the rest comes from the default (tracked_nav.yaml)
    assert Path(zx.file).name == "zx200_nav.yaml" and zx.map_yaml.name == "site_map_mound.yaml"
    assert (zx.footprint.length, zx.footprint.width) == (5.5, 2.8)
    assert (zx.limits.max_speed, zx.limits.max_accel) == (1.5, 0.5)  # speed from its description, accel from its file
    assert zx.controller.desired_speed == 0.8 and zx.controller.reverse_speed == ic.controller.reverse_speed
    assert zx.ekf == load_nav_config(config_path("nav", "tracked_nav.yaml"), machine="zx200").ekf
    zx.build_navigator()  # its map and footprint make a costmap


def test_a_kind_without_a_nav_file_uses_the_documented_default(tmp_path: Path) -> None:
    assert nav_path_for("d37pxi").name == "tracked_nav.yaml"
    assert nav_path_for("zx120").name == "zx120_nav.yaml"
    cfg = load_nav_config(config_path("nav", "tracked_nav.yaml"), machine="zx120")
    assert (cfg.limits.max_accel, cfg.limits.max_yaw_accel) == (0.5, 0.5)  # the default's tracks section


def test_legs_reverse_false_drives_every_leg_forward(tmp_path: Path) -> None:
    nav = tmp_path / "nav.yaml"
    nav.write_text(f"costmap: {{map: {config_path('nav', 'site_map.yaml')}}}\nlegs: {{reverse: false}}\n")
    cfg = load_nav_config(nav, machine="ic120_2")
    assert cfg.reverse is False
    core = cfg.build_navigator()
    core.start([(16.0, 10.0, 0.0)], yaw_at_each=True)  # behind the machine, heading east: the paper rule reverses
    core.step((22.0, 10.0, 0.0), 0.0, 0.05)
    assert core.controller._dir == 1


@pytest.mark.parametrize(("text", "message"), [
    ("legs: {reverse: maybe}\n", r"nav.yaml:1: legs.reverse: expected true or false"),
    ("footprint: {length: 4.0, widht: 2.0}\n", r"nav.yaml:1: footprint.widht: unknown key"),
    ("tracks: {max_accel: -1}\n", r"nav.yaml:1: tracks.max_accel: must be >= "),
    ("blade: {}\n", r"nav.yaml:1: unknown section 'blade'"),
    ("controller: {desired_sped: 1.0}\n", r"nav.yaml:\d+: controller.desired_sped: unknown key"),
    ("goal_checker: {xy_goal_tolerance: 0}\n", r"nav.yaml:1: goal_checker.xy_goal_tolerance: must be >= "),
])
def test_a_bad_kind_file_names_file_line_and_key(tmp_path: Path, text: str, message: str) -> None:
    nav = tmp_path / "nav.yaml"
    nav.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_nav_config(nav, machine="zx200")


def test_machine_name_from_parameter_or_namespace() -> None:
    assert machine_name("", "/ic120_1") == "ic120_1"
    assert machine_name("zx200", "/") == "zx200"
    assert machine_name("", "/", "ic120") == "ic120"
    with pytest.raises(ConfigError, match="machine:=<name>"):
        machine_name("", "/")


def test_only_a_carrier_with_a_vertical_joint_has_a_vessel_swing() -> None:
    assert vessel_swing_joint(load_machine("ic120")) is None
    assert vessel_swing_joint(load_machine("zx200")) is None  # an excavator's swing is its front's, not a vessel's


def test_rtk_relay_estimates_speed_and_yaw_rate_under_noise() -> None:
    rng = np.random.default_rng(3)
    relay = GlobalPoseRelay(1.0)
    v = w = 0.0
    for k in range(300):  # 3 s at 100 Hz: 0.5 m/s along a 30 deg heading, 1 cm noise
        t = k * 0.01
        x, y = 0.5 * t * math.cos(math.radians(30)), 0.5 * t * math.sin(math.radians(30))
        v, w = relay.update(t, x + rng.normal(0, 0.01), y + rng.normal(0, 0.01), math.radians(30))
    assert v == pytest.approx(0.5, abs=0.02) and w == pytest.approx(0.0, abs=0.01)
    turn = GlobalPoseRelay(1.0)
    for k in range(300):  # turning on the spot at 0.1 rad/s
        v, w = turn.update(k * 0.01, 1.0 + rng.normal(0, 0.01), 2.0 + rng.normal(0, 0.01), 0.1 * k * 0.01)
    assert abs(v) < 0.02 and w == pytest.approx(0.1, abs=0.005)
    still = GlobalPoseRelay(1.0)
    for k in range(200):
        v, w = still.update(k * 0.01, 3.0 + rng.normal(0, 0.01), -1.0 + rng.normal(0, 0.01), math.pi)
    assert abs(v) < 0.02 and abs(w) < 0.01  # at rest: below the navigator's rest threshold
    # reversing reads negative, and a yaw across +-pi does not jump
    back = GlobalPoseRelay(1.0)
    for k in range(100):
        v, w = back.update(
            k * 0.01, -0.3 * k * 0.01, 0.0, math.pi - 0.01 + 0.05 * k * 0.01 - (2 * math.pi if k > 20 else 0)
        )
    assert v == pytest.approx(0.3, abs=0.01) and w == pytest.approx(0.05, abs=0.01)
