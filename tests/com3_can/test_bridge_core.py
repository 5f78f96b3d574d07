"""BridgeCore without ROS: command mapping, rejection, emg_stop latch, watchdog, scheduler, fuzzing, outputs."""

from __future__ import annotations

import math
import random

import pytest

from com3_can.bridge_core import (
    EFFORT,
    POSITION,
    VELOCITY,
    BridgeConfig,
    BridgeCore,
    FixOut,
    JointStateOut,
    OdomOut,
)
from com3_can.codec import load_codec
from com3_can.errors import Com3CommandError
from com3_can.profiles import PROFILES, converter_profile
from com3_can.scheduler import FrameScheduler
from tms_common.errors import ConfigError

FRONT = ["swing_joint", "boom_joint", "arm_joint", "bucket_joint"]


def zx(now: float = 0.0) -> BridgeCore:
    return BridgeCore(BridgeConfig.load("zx200"), now, converter_profile("zx200"))


def ic(now: float = 0.0) -> BridgeCore:
    return BridgeCore(BridgeConfig.load("ic120"), now, converter_profile("ic120"))


def by_name(txs):
    return {t.name: t for t in txs}


def test_front_velocity_becomes_velocity_cmd_1_bytes() -> None:
    core = zx()
    txs = by_name(core.front_cmd(FRONT, VELOCITY, [0.5, 0.1, -0.2, 0.0], [], now=0.01))
    assert txs["Velocity_Cmd_1"].data.hex() == "c87d707b007de880"
    assert txs["Velocity_Cmd_1"].arbitration_id == 0x18FF670A
    assert txs["Pilot_Pressure_Cmd_1"].data == bytes(8)  # the other front kind goes neutral
    assert core.current_values("Machine_Setting_Cmd")["front_signal_switch_command"] == 2


def test_front_effort_maps_to_pilot_pressure_with_dead_zone() -> None:
    core = zx()
    core.front_cmd(["boom_joint", "swing_joint"], EFFORT, [], [0.5, -0.0005], now=0.0)
    values = core.current_values("Pilot_Pressure_Cmd_1")
    assert values["boom_down"] == pytest.approx((0.5 + 0.161) * 5.0)  # boom + = down
    assert values["boom_up"] == 0.0 and values["swing_left"] == 0.0 and values["swing_right"] == 0.0
    assert core.current_values("Machine_Setting_Cmd")["front_signal_switch_command"] == 1


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (
            (["boom_joint"], VELOCITY, [17.0], []),
            r"Velocity_Cmd_1\.boom_target_anguler_velocity: value 17.0 rad/s outside \[-16, 16\]",
        ),
        ((["boom_joint"], VELOCITY, [math.nan], []), r"boom_joint velocity: value nan is not finite"),
        ((["stick_joint"], VELOCITY, [0.1], []), r"unknown joint\(s\) \['stick_joint'\]"),
        ((["boom_joint", "arm_joint"], VELOCITY, [0.1], []), r"2 joint names but 1 velocity values"),
        ((["boom_joint"], POSITION, [], []), r"control_type POSITION is not carried by COM3"),
        ((["boom_joint"], EFFORT, [], [1.5]), r"boom_joint effort 1.5 outside \[-1, 1\]"),
        ((["boom_joint", "boom_joint"], VELOCITY, [0.1, 0.1], []), r"duplicate joint names"),
        (([], VELOCITY, [], []), r"joint_name is empty"),
    ],
)
def test_bad_front_cmd_is_rejected_and_changes_nothing(args, match) -> None:
    core = zx()
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.0)
    before = core.current_values("Velocity_Cmd_1")
    with pytest.raises(Com3CommandError, match=match):
        core.front_cmd(*args, now=0.1)
    assert core.current_values("Velocity_Cmd_1") == before  # never clipped, never wrapped
    assert core.counters["cmd_rejected"] == 1
    diag = core.diagnostics(0.1)
    assert dict(diag.values)["last_reject"].startswith("front_cmd: ") and diag.level == 1


def test_cmd_vel_and_tracks_on_both_machines() -> None:
    core = zx()
    core.cmd_vel(0.4, -0.1, now=0.0)
    v2 = core.current_values("Velocity_Cmd_2")
    assert v2["target_travel_center_velocity"] == 0.4 and v2["target_travel_yaw_rate"] == -0.1
    assert core.current_values("Machine_Setting_Cmd")["travel_signal_switch_command"] == 3
    core.tracks_cmd(["left_track", "right_track"], VELOCITY, [0.2, 0.3], [], now=0.01)
    v2 = core.current_values("Velocity_Cmd_2")
    assert (
        v2["target_travel_left_velocity"],
        v2["target_travel_right_velocity"],
        v2["target_travel_center_velocity"],
    ) == (0.2, 0.3, 0.0)
    with pytest.raises(Com3CommandError, match=r"cmd_vel: .*target_travel_center_velocity: value 40"):
        core.cmd_vel(40.0, 0.0, now=0.02)
    car = ic()
    car.cmd_vel(1.0, 0.2, now=0.0)
    assert car.current_values("Machine_Setting_Cmd")["velocity_mode"] == 0
    car.tracks_cmd(["right_track"], VELOCITY, [0.5], [], now=0.0)
    assert car.current_values("Machine_Setting_Cmd")["velocity_mode"] == 1
    with pytest.raises(Com3CommandError, match="track_cmd: the ic120 takes VELOCITY"):
        car.tracks_cmd(["right_track"], EFFORT, [], [0.5], now=0.0)
    # com3_ros names the topics per type: an excavator's tracks_cmd, a crawler carrier's track_cmd
    assert (zx().profile.tracks_topic, car.profile.tracks_topic) == ("tracks_cmd", "track_cmd")
    assert car.topics == frozenset({"track_cmd", "cmd_vel", "rot_dump_cmd"})


def test_rot_dump_cmd_range_from_machine_config() -> None:
    car = ic()
    car.rot_dump_cmd(["dump_joint"], POSITION, [0.8], now=0.0)
    assert car.current_values("Vessel_Cmd") == {"target_vessel_angle": 0.8, "vessel_control_enable": 1.0}
    for bad in (-0.1, 1.2, math.inf):
        with pytest.raises(Com3CommandError, match="rot_dump_cmd: "):
            car.rot_dump_cmd(["dump_joint"], POSITION, [bad], now=0.0)
    for names, ctl, pos, why in (
        (["rotate_joint"], POSITION, [0.1], "has no rotate_joint"),
        (["vessel_joint"], POSITION, [0.1], r"expected \['dump_joint'\]"),
        (["dump_joint"], VELOCITY, [0.1], "POSITION \\(0\\) dump commands only"),
        (["dump_joint"], POSITION, [], "1 joint name but 0 position values"),
    ):
        with pytest.raises(Com3CommandError, match=why):
            car.rot_dump_cmd(names, ctl, pos, now=0.0)
    assert car.current_values("Vessel_Cmd")["target_vessel_angle"] == 0.8
    with pytest.raises(Com3CommandError, match=r"rot_dump_cmd: the zx200 \(excavator\) does not take rot_dump_cmd"):
        zx().rot_dump_cmd(["dump_joint"], POSITION, [0.1], now=0.0)


def test_emg_stop_latch() -> None:
    codec = load_codec("zx200")
    core = zx()
    core.front_cmd(FRONT, VELOCITY, [0.5, 0.1, -0.2, 0.0], [], now=0.0)
    txs = by_name(core.emg_stop(True, now=0.1))
    assert txs["Velocity_Cmd_1"].data == codec.encode("Velocity_Cmd_1", codec.neutral("Velocity_Cmd_1"))
    assert txs["Velocity_Cmd_2"].data.hex() == "007d" * 4
    with pytest.raises(Com3CommandError, match="emg_stop is latched"):
        core.front_cmd(["boom_joint"], VELOCITY, [0.1], [], now=0.2)
    assert core.diagnostics(0.2).level == 2 and "emg_stop latched" in core.diagnostics(0.2).message
    core.emg_stop(True, now=0.3)  # repeated true keeps it latched
    core.emg_stop(False, now=0.4)
    assert not core.emg_latched
    assert core.current_values("Velocity_Cmd_1") == codec.neutral("Velocity_Cmd_1")  # stays neutral until a new cmd
    core.front_cmd(["boom_joint"], VELOCITY, [0.1], [], now=0.5)
    assert core.current_values("Velocity_Cmd_1")["boom_target_anguler_velocity"] == 0.1


def test_watchdog_neutral_and_reason() -> None:
    core = zx()
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.0)
    assert all(t.name != "Velocity_Cmd_1" or t.data != bytes.fromhex("007d" * 4) for t in core.tick(0.49))
    txs = by_name(core.tick(0.51))
    assert txs["Velocity_Cmd_1"].data.hex() == "007d" * 4
    diag = core.diagnostics(0.6)
    assert diag.level == 1 and "watchdog: no front_cmd for 0.60 s" in diag.message
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.7)
    assert "watchdog" not in core.diagnostics(0.7).message
    assert core.next_wake() <= 0.7 + 0.5 + 0.001


def test_watchdog_warns_only_when_it_stops_a_moving_machine(caplog: pytest.LogCaptureFixture) -> None:
    core = ic()
    core.cmd_vel(0.5, 0.0, now=0.0)
    core.cmd_vel(0.0, 0.0, now=0.1)  # a navigator at its goal: a neutral command, then silence
    with caplog.at_level("DEBUG", logger="com3_can.bridge_core"):
        core.tick(0.7)
        core.cmd_vel(0.5, 0.0, now=1.0)  # driving, then the sender dies
        core.tick(1.6)
    assert core.counters["watchdog_travel"] == 2
    levels = [(r.levelname, r.getMessage()) for r in caplog.records if "watchdog" in r.getMessage()]
    assert [lv for lv, _ in levels] == ["DEBUG", "WARNING"], levels
    assert "ic120: watchdog: no cmd_vel for 0.60 s" in levels[1][1]


def test_tick_emits_each_frame_at_its_cycle_with_alive_counter() -> None:
    core = zx(now=0.0)
    counts: dict[str, int] = {}
    alive = []
    codec = load_codec("zx200")
    t = 0.0
    while t < 1.0 - 1e-9:
        for tx in core.tick(t):
            counts[tx.name] = counts.get(tx.name, 0) + 1
            if tx.name == "Machine_Setting_Cmd":
                alive.append(int(codec.decode(tx.arbitration_id, tx.data)[1]["alive_counter"]))
        t += 0.001
    assert counts["Velocity_Cmd_1"] == 100 and counts["Pilot_Pressure_Cmd_2"] == 100
    assert counts["Machine_Setting_Cmd"] == 20
    assert alive == list(range(20))


def test_scheduler_event_send_restarts_period_and_late_frames_do_not_burst() -> None:
    s = FrameScheduler({"a": 0.01}, start=0.0)
    assert s.due(0.0) == ["a"] and s.due(0.005) == []
    s.sent("a", 0.007)
    assert s.due(0.012) == [] and s.due(0.017) == ["a"]
    assert s.due(0.5) == ["a"] and s.due(0.5) == [] and s.next_due() == pytest.approx(0.51)
    with pytest.raises(ValueError, match="period must be > 0"):
        FrameScheduler({"b": 0.0}, 0.0)


@pytest.mark.parametrize("machine", ["zx200", "ic120"])
def test_fuzz_10000_garbled_frames_never_crash_and_are_counted(machine: str) -> None:
    core = BridgeCore(BridgeConfig.load(machine), 0.0, converter_profile(machine))
    codec = core.codec
    rng = random.Random(1234)
    ids = [codec.frame_id(f) for f in codec.state_frames]
    n = 12_000
    for i in range(n):
        kind = rng.random()
        if kind < 0.4:  # a real id with random bytes of random length
            fid, data = rng.choice(ids), rng.randbytes(rng.choice([0, 1, 7, 8, 8, 8, 9, 64]))
        elif kind < 0.7:  # a random 29-bit id
            fid, data = rng.getrandbits(29), rng.randbytes(8)
        elif kind < 0.8:  # flags a CAN controller can deliver
            fid, data = rng.choice(ids), rng.randbytes(8)
            core.on_frame(fid, data, is_error_frame=rng.random() < 0.5, is_remote_frame=True, stamp=i * 0.01)
            continue
        else:
            fid, data = rng.getrandbits(11), rng.randbytes(8)
            core.on_frame(fid, data, is_extended_id=False, stamp=i * 0.01)
            continue
        out = core.on_frame(fid, data, stamp=i * 0.01)
        assert isinstance(out, list)
    c = core.counters
    assert c["frames_rx"] == n
    dropped = sum(v for k, v in c.items() if k.startswith("rx_") and k not in ("rx_ok", "rx_command_echo"))
    assert dropped + c["rx_ok"] + c["rx_command_echo"] == n
    assert c["rx_unknown_id"] > 2000 and c["rx_bad_dlc"] > 1000 and c["rx_out_of_range"] > 0
    diag = dict(core.diagnostics(1.0).values)
    assert int(diag["rx_dropped_total"]) == dropped
    # and the converter still works afterwards
    assert core.tick(200.0)


def test_zx200_state_frames_to_joint_states_imu_odom_fix() -> None:
    core = zx()
    codec = core.codec
    vel = {"boom_relative_angular_velocity": 0.1, "arm_relative_angular_velocity": -0.2,
           "bucket_relative_angular_velocity": 0.3, "swing_relative_angular_velocity": 0.4}
    core.on_frame(codec.frame_id("Front_Angular_Velocity"), codec.encode("Front_Angular_Velocity", vel))
    ang = {
        "boom_relative_angle": -0.5,
        "arm_relative_angle": 1.6,
        "bucket_relative_angle": 0.5,
        "swing_relative_angle": 0.25,
    }
    (js,) = core.on_frame(codec.frame_id("Front_Angle"), codec.encode("Front_Angle", ang))
    assert isinstance(js, JointStateOut)
    assert js.name == ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
    assert js.position == pytest.approx((0.25, -0.5, 1.6, 0.5), abs=4e-4)
    assert js.velocity == pytest.approx((0.4, 0.1, -0.2, 0.3), abs=2e-4)
    core.on_frame(
        codec.frame_id("Swing_Center_Position_1"),
        codec.encode("Swing_Center_Position_1", {"swing_center_position_x": 21405.178}),
    )
    core.on_frame(
        codec.frame_id("Swing_Center_Position_2"),
        codec.encode("Swing_Center_Position_2", {"swing_center_position_y": 14024.450}),
    )
    z3 = codec.encode("Swing_Center_Position_3", {"swing_center_position_z": 28.552})
    # no azimuth yet: the fix alone (a pose in map with a made-up heading of 0 would be a wrong pose), no IMU
    (fix,) = core.on_frame(codec.frame_id("Swing_Center_Position_3"), z3)
    assert isinstance(fix, FixOut)
    rp = codec.encode("Roll_Pitch_Angle", {"roll_angle": 0.01, "pitch_angle": -0.02})
    assert core.on_frame(codec.frame_id("Roll_Pitch_Angle"), rp) == []
    az = codec.encode("Vehicle_Azimuth", {"track_body_azimuth": -0.7, "upper_body_azimuth": -0.95})  # yaw +0.7 rad
    core.on_frame(codec.frame_id("Vehicle_Azimuth"), az)
    (imu,) = core.on_frame(codec.frame_id("Roll_Pitch_Angle"), rp)
    assert imu.yaw == pytest.approx(0.7, abs=1e-3)
    odom, fix = core.on_frame(codec.frame_id("Swing_Center_Position_3"), z3)
    assert isinstance(odom, OdomOut) and (odom.x, odom.y) == pytest.approx((10.0, -10.0), abs=1e-3)
    assert odom.yaw == pytest.approx(0.7, abs=1e-3)
    assert isinstance(fix, FixOut) and (fix.latitude, fix.longitude) == pytest.approx(
        (36.12626 - 9.0e-5, 140.07103 + 1.11e-4), abs=2e-5
    )


def test_carrier_odometry_before_the_first_azimuth_stays_continuous() -> None:
    """Track frames before the first azimuth (the frames' order on the bus at start-up): odometry dead-reckons from
    0, and the first azimuth does not make it jump (REP 105); from then on it turns with the azimuth. No IMU before
    the azimuth."""
    core = ic()
    codec = core.codec
    rp = codec.encode("Roll_Pitch_Angle", {"roll_angle": 0.0, "pitch_angle": 0.0})
    assert core.on_frame(codec.frame_id("Roll_Pitch_Angle"), rp) == []
    tv = codec.encode("Track_Velocity", {"left_track_velocity": 0.0, "right_track_velocity": 0.0})
    odom, _ = core.on_frame(codec.frame_id("Track_Velocity"), tv, stamp=0.0)
    assert odom.yaw == 0.0
    for i, azimuth in enumerate((1.4, 1.5)):  # the machine stands at +1.4 rad, then turns by 0.1 rad
        core.on_frame(codec.frame_id("Vehicle_Azimuth"),
                      codec.encode("Vehicle_Azimuth", {"track_body_azimuth": -azimuth, "yaw_rate": 0.0}))
        odom, _ = core.on_frame(codec.frame_id("Track_Velocity"), tv, stamp=0.01 * (i + 1))
        assert odom.yaw == pytest.approx(azimuth - 1.4, abs=1e-3)
    (imu,) = core.on_frame(codec.frame_id("Roll_Pitch_Angle"), rp)
    assert imu.yaw == pytest.approx(1.5, abs=1e-3)
    # a converter that hears the azimuth first reports it as the odometry's heading
    fresh = ic()
    fresh.on_frame(codec.frame_id("Vehicle_Azimuth"),
                   codec.encode("Vehicle_Azimuth", {"track_body_azimuth": -1.4, "yaw_rate": 0.0}))
    odom, _ = fresh.on_frame(codec.frame_id("Track_Velocity"), tv, stamp=0.0)
    assert odom.yaw == pytest.approx(1.4, abs=1e-3)


def test_ic120_odometry_integrates_track_velocities_with_azimuth() -> None:
    core = ic()
    codec = core.codec
    az = codec.encode("Vehicle_Azimuth", {"track_body_azimuth": -math.pi / 2, "yaw_rate": 0.0})  # yaw = +90 deg
    core.on_frame(codec.frame_id("Vehicle_Azimuth"), az)
    tv = codec.encode("Track_Velocity", {"left_track_velocity": 1.0, "right_track_velocity": 1.0})
    out = []
    for i in range(101):
        out = core.on_frame(codec.frame_id("Track_Velocity"), tv, stamp=i * 0.01)
    odom, js = out
    assert (odom.x, odom.y) == pytest.approx((0.0, 1.0), abs=1e-3)
    assert odom.yaw == pytest.approx(math.pi / 2, abs=1e-3) and odom.v == pytest.approx(1.0)
    assert js.name == ("vessel_joint", "left_track", "right_track") and js.position[1] == pytest.approx(1.0)
    for name, vals in (("GNSS_Latitude", {"latitude": 36.12626}), ("GNSS_Longitude", {"longitude": 140.07103})):
        assert core.on_frame(codec.frame_id(name), codec.encode(name, vals)) == []
    (fix,) = core.on_frame(
        codec.frame_id("GNSS_Altitude_Status"),
        codec.encode(
            "GNSS_Altitude_Status",
            {"altitude": 30.0, "fix_status": 3, "num_satellites": 12, "horizontal_accuracy": 0.02},
        ),
    )
    assert (fix.latitude, fix.longitude, fix.status) == (
        pytest.approx(36.12626, abs=1e-9),
        pytest.approx(140.07103, abs=1e-9),
        2,
    )


def test_machine_setting_and_bad_config() -> None:
    core = zx()
    (tx,) = core.machine_setting({"engine_rpm": 1500, "yellow_led_mode": 1}, now=0.0)
    _, back = core.codec.decode(tx.arbitration_id, tx.data)
    assert back["engine_rpm"] == 1500 and back["yellow_led_mode"] == 1
    with pytest.raises(Com3CommandError, match=r"machine_setting: .*engine_rpm: value 3000"):
        core.machine_setting({"engine_rpm": 3000}, now=0.0)
    with pytest.raises(Com3CommandError, match=r"unknown field 'turbo'"):
        core.machine_setting({"turbo": 1}, now=0.0)
    with pytest.raises(ConfigError, match="watchdog_s must be > 0"):
        BridgeConfig.load("zx200", watchdog_s=0.0)
    with pytest.raises(ConfigError, match=r"site.yaml: no machine 'd61' in machines \(known: .*ic120.*zx200"):
        BridgeConfig.load("d61")
    with pytest.raises(ConfigError, match=r"default_setting.turbo"):
        BridgeCore(BridgeConfig.load("zx200", default_setting={"turbo": 1}), 0.0, converter_profile("zx200"))


def test_the_core_runs_the_profile_it_is_given_and_refuses_one_of_another_type() -> None:
    cfg = BridgeConfig.load("zx200")
    profile = converter_profile("zx200")
    assert BridgeCore(cfg, 0.0, profile).profile is profile
    other = next(t for t in PROFILES if t != cfg.machine_type)
    with pytest.raises(ConfigError, match=rf"zx200 is a {cfg.machine_type}, but the profile given serves '{other}'"):
        BridgeCore(cfg, 0.0, PROFILES.get(other)("zx200"))
