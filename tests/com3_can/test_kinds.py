"""The converter of the kinds beyond the paper's: MSTs (crawler carriers with a swing) and the D37PXi dozer.

Pure BridgeCore (no ROS, no bus): commands -> frames, refusals naming the machine, the swing and the blade as
channels of their own (own watchdog), state frames -> joint_states with ``rotate_joint`` / ``lift_joint``.
"""

from __future__ import annotations

import math

import pytest

from com3_can.bridge_core import EFFORT, POSITION, VELOCITY, BridgeConfig, BridgeCore, JointStateOut
from com3_can.errors import Com3CommandError
from com3_can.profiles import PROFILES, converter_profile, profile_for
from com3_can.profiles.dozer import DozerProfile


def _core(kind: str) -> BridgeCore:
    return BridgeCore(BridgeConfig.load(kind), 0.0, converter_profile(kind))


def _frame(core: BridgeCore, txs, name: str) -> dict[str, float]:
    tx = next(t for t in txs if t.name == name)
    return core.codec.decode(tx.arbitration_id, tx.data)[1]


@pytest.mark.parametrize("kind", ["mst110cr", "mst2200vd"])
def test_mst_rot_dump_cmd_commands_swing_and_vessel(kind: str) -> None:
    core = _core(kind)
    assert profile_for(kind) is PROFILES.get("crawler_dump")
    txs = core.rot_dump_cmd(["rotate_joint", "dump_joint"], POSITION, [-2.0, 0.8], 0.1)
    assert _frame(core, txs, "Swing_Cmd") == pytest.approx({"target_swing_angle": -2.0, "swing_control_enable": 1.0},
                                                           abs=4e-4)
    assert _frame(core, txs, "Vessel_Cmd") == pytest.approx({"target_vessel_angle": 0.8, "vessel_control_enable": 1.0},
                                                            abs=4e-4)
    # one joint only: the other channel keeps its command
    txs = core.rot_dump_cmd(["rotate_joint"], POSITION, [math.pi], 0.2)
    assert [t.name for t in txs] == ["Swing_Cmd"]
    assert core.current_values("Vessel_Cmd")["target_vessel_angle"] == pytest.approx(0.8, abs=4e-4)
    for names, ctl, pos, why in (
        (["rotate_joint"], POSITION, [3.2], r"rotate_joint angle 3.2 rad outside \[-3.14159, 3.14159\]"),
        (["dump_joint"], POSITION, [1.2], r"dump_joint angle 1.2 rad outside \[0, 1.0472\]"),  # MST vessel: 60 deg
        (["rotate_joint", "rotate_joint"], POSITION, [0.1, 0.1], "each at most once"),
        (["rotate_joint", "dump_joint"], POSITION, [0.1], "2 joint names but 1 position values"),
        (["rotate_joint"], EFFORT, [0.1], r"POSITION \(0\) dump commands only"),
        (["rotate_joint"], POSITION, [math.nan], "not finite"),
    ):
        with pytest.raises(Com3CommandError, match=why):
            core.rot_dump_cmd(names, ctl, pos, 0.3)
    # the swing has its own watchdog: the vessel was commanded last at 0.1 s, the swing at 0.2 s
    neutral = [t.name for t in core.tick(0.65)]
    assert "Vessel_Cmd" in neutral and core.current_values("Vessel_Cmd")["vessel_control_enable"] == 0.0
    assert core.current_values("Swing_Cmd")["swing_control_enable"] == 1.0
    core.tick(0.75)
    assert core.current_values("Swing_Cmd")["swing_control_enable"] == 0.0  # hold
    assert "no rot_dump_cmd" in core.diagnostics(0.8).message


def test_mst_joint_states_carry_rotate_joint_first() -> None:
    core = _core("mst110cr")
    c = core.codec
    core.on_frame(
        c.frame_id("Swing_Angle"), c.encode("Swing_Angle", {"swing_angle": 1.5, "swing_angular_velocity": 0.3})
    )
    core.on_frame(c.frame_id("Vessel_Angle"), c.encode("Vessel_Angle", {"vessel_angle": 0.4,
                                                                        "vessel_angular_velocity": 0.0}))
    outs = core.on_frame(
        c.frame_id("Track_Velocity"),
        c.encode("Track_Velocity", {"left_track_velocity": 0.5, "right_track_velocity": 0.5}),
        stamp=1.0,
    )
    js = next(o for o in outs if isinstance(o, JointStateOut))
    assert js.name == ("rotate_joint", "vessel_joint", "left_track", "right_track")
    assert js.position[:2] == pytest.approx((1.5, 0.4), abs=4e-4) and js.velocity[0] == pytest.approx(0.3, abs=2e-4)
    # the IC120 reports no rotate_joint
    ic = _core("ic120")
    outs = ic.on_frame(c.frame_id("Track_Velocity"),
                       c.encode("Track_Velocity", {"left_track_velocity": 0.0, "right_track_velocity": 0.0}), stamp=1.0)
    assert next(o for o in outs if isinstance(o, JointStateOut)).name == ("vessel_joint", "left_track", "right_track")


def test_ic120_refuses_rotate_joint_naming_the_machine() -> None:
    core = _core("ic120")
    with pytest.raises(Com3CommandError, match="the ic120 has no rotate_joint"):
        core.rot_dump_cmd(["rotate_joint", "dump_joint"], POSITION, [0.0, 0.5], 0.1)
    assert core.counters["cmd_rejected"] == 1


def test_dozer_blade_cmd_and_travel() -> None:
    core = _core("d37pxi")
    assert isinstance(core.profile, DozerProfile) and core.topics == frozenset({"track_cmd", "cmd_vel", "blade_cmd"})
    txs = core.blade_cmd(["lift_joint"], POSITION, [0.15], [], 0.1)
    assert _frame(core, txs, "Blade_Cmd") == pytest.approx(
        {"target_blade_lift_angle": 0.15, "target_blade_lift_velocity": 0.0, "blade_control_mode": 1.0}, abs=5e-4)
    txs = core.blade_cmd(["lift_joint"], VELOCITY, [], [-0.2], 0.2)
    assert _frame(core, txs, "Blade_Cmd")["blade_control_mode"] == 2.0
    for names, ctl, pos, vel, why in (
        (["lift_joint"], POSITION, [0.3], [], r"lift_joint angle 0.3 rad outside \[-0.41015, 0.18675\]"),
        (["lift_joint"], VELOCITY, [], [0.5], r"velocity 0.5 rad/s outside \[-0.25, 0.25\]"),
        (["blade_joint"], POSITION, [0.0], [], r"expected \['lift_joint'\]"),
        (["lift_joint"], EFFORT, [], [], r"POSITION \(0\) or VELOCITY \(1\)"),
    ):
        with pytest.raises(Com3CommandError, match=why):
            core.blade_cmd(names, ctl, pos, vel, 0.3)
    txs = core.cmd_vel(0.8, -0.1, 0.3)
    assert _frame(core, txs, "Velocity_Cmd")["target_travel_center_velocity"] == pytest.approx(0.8, abs=1e-3)
    assert core.current_values("Machine_Setting_Cmd")["velocity_mode"] == 0.0
    with pytest.raises(Com3CommandError, match=r"the d37pxi \(dozer\) does not take rot_dump_cmd"):
        core.rot_dump_cmd(["dump_joint"], POSITION, [0.1], 0.4)
    c = core.codec
    core.on_frame(c.frame_id("Blade_Angle"), c.encode("Blade_Angle", {"blade_lift_angle": -0.2,
                                                                      "blade_lift_angular_velocity": 0.0}))
    outs = core.on_frame(
        c.frame_id("Track_Velocity"),
        c.encode("Track_Velocity", {"left_track_velocity": 1.0, "right_track_velocity": 1.0}),
        stamp=1.0,
    )
    js = next(o for o in outs if isinstance(o, JointStateOut))
    assert js.name == ("lift_joint", "left_track", "right_track") and js.position[0] == pytest.approx(-0.2, abs=4e-4)
    # travel and blade watchdogs are separate channels
    core.tick(0.75)
    assert core.current_values("Blade_Cmd")["blade_control_mode"] == 0.0
    assert core.current_values("Velocity_Cmd")["target_travel_center_velocity"] == pytest.approx(0.8, abs=1e-3)
    core.tick(0.85)
    assert core.current_values("Velocity_Cmd")["target_travel_center_velocity"] == 0.0
