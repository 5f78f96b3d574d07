"""Codec properties: round trip within one LSB for every signal of every DBC, strict checks, neutrals; each kind's
codec found through its machine description."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from com3_can.codec import AliveCounter, dbc_file, dbc_files, load_codec
from com3_can.errors import Com3DecodeError, Com3EncodeError
from tms_common.errors import ConfigError

#: one machine kind per shipped bus DBC (the MSTs share the IC120's crawler-carrier DBC)
MACHINES = ("zx200", "ic120", "d37pxi")
ALL_FRAMES = [(m, f) for m in MACHINES for f in load_codec(m).frame_names]


def _frame_values(machine: str, frame: str) -> st.SearchStrategy[dict[str, float]]:
    codec = load_codec(machine)
    return st.fixed_dictionaries(
        {s.name: st.floats(s.minimum, s.maximum, allow_nan=False, allow_infinity=False) for s in codec.signals(frame)}
    )


@pytest.mark.parametrize(("machine", "frame"), ALL_FRAMES, ids=[f"{m}-{f}" for m, f in ALL_FRAMES])
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_round_trip_within_one_lsb(machine: str, frame: str, data: st.DataObject) -> None:
    codec = load_codec(machine)
    values = data.draw(_frame_values(machine, frame))
    payload = codec.encode(frame, values)
    assert len(payload) == codec.dlc(frame)
    name, decoded = codec.decode(codec.frame_id(frame), payload)
    assert name == frame
    for spec in codec.signals(frame):
        # rounding to the nearest raw step: error <= LSB/2; allow one LSB as the issue states
        assert abs(decoded[spec.name] - values[spec.name]) <= spec.lsb * (1 + 1e-9), spec.name


@pytest.mark.parametrize(("machine", "frame"), ALL_FRAMES, ids=[f"{m}-{f}" for m, f in ALL_FRAMES])
def test_range_ends_encode_and_beyond_is_refused(machine: str, frame: str) -> None:
    codec = load_codec(machine)
    for spec in codec.signals(frame):
        base = {s.name: s.minimum for s in codec.signals(frame)}
        for end in (spec.minimum, spec.maximum):
            base[spec.name] = end
            _, back = codec.decode(codec.frame_id(frame), codec.encode(frame, base))
            assert back[spec.name] == pytest.approx(end, abs=spec.lsb)
        for outside in (spec.maximum + spec.lsb, spec.minimum - spec.lsb, math.nan, math.inf):
            base[spec.name] = outside
            with pytest.raises(Com3EncodeError, match=rf"{frame}\.{spec.name}: value .* outside \["):
                codec.encode(frame, base)


def test_encode_errors_name_the_culprit() -> None:
    codec = load_codec("zx200")
    vals = codec.neutral("Velocity_Cmd_1")
    with pytest.raises(Com3EncodeError, match=r"unknown frame 'Nope'"):
        codec.encode("Nope", vals)
    with pytest.raises(Com3EncodeError, match=r"missing signal\(s\) \['arm_target_anguler_velocity'\]"):
        codec.encode("Velocity_Cmd_1", {k: v for k, v in vals.items() if not k.startswith("arm")})
    with pytest.raises(Com3EncodeError, match=r"unknown signal\(s\) \['bogus'\]"):
        codec.encode("Velocity_Cmd_1", {**vals, "bogus": 1.0})
    with pytest.raises(Com3EncodeError, match=r"expected a number, got 'fast'"):
        codec.encode("Velocity_Cmd_1", {**vals, "boom_target_anguler_velocity": "fast"})
    with pytest.raises(Com3EncodeError, match=r"value 16.5 rad/s outside \[-16, 16\]"):
        codec.encode("Velocity_Cmd_1", {**vals, "boom_target_anguler_velocity": 16.5})
    with pytest.raises(Com3EncodeError, match="state frame"):
        codec.neutral("Front_Angle")


def test_decode_errors_carry_a_reason() -> None:
    codec = load_codec("zx200")
    with pytest.raises(Com3DecodeError, match="unknown COM3 id 0x18FF0000") as exc:
        codec.decode(0x18FF0000, bytes(8))
    assert exc.value.reason == "unknown_id"
    with pytest.raises(Com3DecodeError, match=r"Front_Angle .*DLC 7, expected 8") as exc:
        codec.decode(codec.frame_id("Front_Angle"), bytes(7))
    assert exc.value.reason == "bad_dlc"
    with pytest.raises(Com3DecodeError, match=r"Pilot_Pressure_1\.boom_up_pilot_pressure: received 5.1 MPa") as exc:
        codec.decode(codec.frame_id("Pilot_Pressure_1"), b"\xff" + bytes(7))
    assert exc.value.reason == "out_of_range"
    with pytest.raises(Com3DecodeError, match=r"roll_angle: received 4.1915"):  # 14-bit raw 16383 > 4 rad
        codec.decode(codec.frame_id("Roll_Pitch_Angle"), b"\xff\x3f" + bytes(6))


@pytest.mark.parametrize("machine", list(MACHINES))
def test_neutral_commands_are_not_all_zero_and_decode_to_rest(machine: str) -> None:
    codec = load_codec(machine)
    assert codec.command_frames and codec.state_frames
    for frame in codec.command_frames:
        neutral = codec.neutral(frame)
        payload = codec.encode(frame, neutral)
        _, back = codec.decode(codec.frame_id(frame), payload)
        for name, value in back.items():
            if "velocity" in name or "yaw_rate" in name or frame.startswith("Pilot_Pressure"):
                assert value == pytest.approx(0.0, abs=1e-9), f"{frame}.{name}"
    # the motion frames with offsets are not all-zero bytes when neutral
    motion = "Velocity_Cmd_1" if machine == "zx200" else "Velocity_Cmd"
    if machine == "d37pxi":  # neutral blade = hold (mode 0), target 0 rad: not all-zero bytes either
        assert codec.encode("Blade_Cmd", codec.neutral("Blade_Cmd")) != bytes(8)
    assert codec.encode(motion, codec.neutral(motion)) != bytes(8)


def test_cycle_times_and_ids() -> None:
    zx, ic = load_codec("zx200"), load_codec("ic120")
    assert zx.cycle_ms("Velocity_Cmd_1") == 10 and zx.cycle_ms("Machine_Setting_Cmd") == 50
    assert zx.frame_name(0x18FF670A) == "Velocity_Cmd_1"
    assert all(ic.cycle_ms(f) == 10 for f in ic.command_frames)
    # our extension: J1939-style, priority 6, PF 0xFF, commands from SA 0x0A, states from SA 0xE9
    for f in ic.command_frames:
        fid = ic.frame_id(f)
        assert fid >> 26 == 6 and (fid >> 16) & 0xFF == 0xFF and fid & 0xFF == 0x0A
    for f in ic.state_frames:
        assert ic.frame_id(f) & 0xFF == 0xE9
    # no id collides with the excavator's (both could share one bus)
    assert not {zx.frame_id(f) for f in zx.frame_names} & {ic.frame_id(f) for f in ic.frame_names}


def test_alive_counter_wraps() -> None:
    counter = AliveCounter(start=254)
    assert [counter.next() for _ in range(4)] == [254, 255, 0, 1]
    assert AliveCounter.is_successor(255, 0) and not AliveCounter.is_successor(3, 5)
    with pytest.raises(ValueError, match="outside"):
        AliveCounter(start=256)


def test_each_kind_finds_its_dbc_through_its_machine_description() -> None:
    assert {k: dbc_file(k) for k in ("zx200", "zx120", "ic120", "mst110cr", "mst2200vd", "d37pxi")} == {
        "zx200": "excavator_com3.dbc", "zx120": "excavator_com3.dbc", "ic120": "crawler_carrier_com3.dbc",
        "mst110cr": "crawler_carrier_com3.dbc", "mst2200vd": "crawler_carrier_com3.dbc", "d37pxi": "dozer_com3.dbc",
    }
    assert {"excavator_com3.dbc", "crawler_carrier_com3.dbc", "dozer_com3.dbc"} <= set(dbc_files())
    mst = load_codec("mst110cr")
    assert mst.machine == "mst110cr" and "Swing_Cmd" in mst.command_frames and "Swing_Angle" in mst.state_frames
    assert mst.frame_names == load_codec("ic120").frame_names
    with pytest.raises(ConfigError, match=r"no such machine description \(machine kind 'd61'"):
        load_codec("d61")


def test_a_description_naming_an_unshipped_dbc_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    import com3_can.codec as codec

    real = codec.load_machine("ic120")
    monkeypatch.setattr(codec, "load_machine", lambda kind, path=None: dataclasses.replace(real, dbc="nope.dbc"))
    with pytest.raises(ConfigError, match=r"ic120.yaml: can.dbc: no DBC file 'nope.dbc' in com3_can/dbc"):
        dbc_file("ic120")


def test_new_swing_and_blade_signals_round_trip() -> None:
    ic, dz = load_codec("ic120"), load_codec("d37pxi")
    cmd = {"target_swing_angle": -2.5, "swing_control_enable": 1.0}
    assert ic.decode(ic.frame_id("Swing_Cmd"), ic.encode("Swing_Cmd", cmd))[1] == pytest.approx(cmd, abs=4e-4)
    state = {"swing_angle": 3.1, "swing_angular_velocity": -0.35}
    assert ic.decode(ic.frame_id("Swing_Angle"), ic.encode("Swing_Angle", state))[1] == pytest.approx(state, abs=4e-4)
    assert ic.neutral("Swing_Cmd") == {"target_swing_angle": 0.0, "swing_control_enable": 0.0}  # hold
    assert ic.neutral("Machine_Setting_Cmd")["swing_mode"] == 0.0  # angle control
    blade = {"target_blade_lift_angle": 0.18, "target_blade_lift_velocity": -0.25, "blade_control_mode": 2.0}
    assert dz.decode(dz.frame_id("Blade_Cmd"), dz.encode("Blade_Cmd", blade))[1] == pytest.approx(blade, abs=5e-4)
    with pytest.raises(Com3EncodeError, match=r"Blade_Cmd.blade_control_mode: value 3"):
        dz.encode("Blade_Cmd", {**blade, "blade_control_mode": 3.0})
    got = dz.decode(dz.frame_id("Blade_Angle"), dz.encode("Blade_Angle", {"blade_lift_angle": -0.41,
                                                                          "blade_lift_angular_velocity": 0.2}))
    assert got == (
        "Blade_Angle",
        pytest.approx({"blade_lift_angle": -0.41, "blade_lift_angular_velocity": 0.2}, abs=4e-4),
    )
    # ids: J1939-style from SA 0x0A (commands) and 0xEA (dozer states); no id shared with the other DBCs
    for f in dz.command_frames:
        assert dz.frame_id(f) >> 26 == 6 and dz.frame_id(f) & 0xFF == 0x0A
    assert all(dz.frame_id(f) & 0xFF == 0xEA for f in dz.state_frames)
    zx = load_codec("zx200")
    ids = [{c.frame_id(f) for f in c.frame_names} for c in (zx, ic, dz)]
    assert not (ids[0] & ids[1] or ids[0] & ids[2] or ids[1] & ids[2])
