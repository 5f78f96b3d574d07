"""Golden test: our excavator DBC against every row of tests/com3_can/data/com3_frames.csv (the published COM3 layout),
plus the known vector.

The csv was generated from the published COM3 excavator DBC; each row is one signal. We check what
cantools parses from *our* DBC (id, DLC, direction, cycle time, start bit, length, byte order, sign,
scale, offset, min/max, unit), that no frame or signal is missing or extra, and the value tables.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cantools
import pytest

from com3_can.codec import dbc_text, load_codec

#: the published COM3 layout, one row per signal, kept with the tests
CSV = Path(__file__).parent / "data" / "com3_frames.csv"


def _rows() -> list[dict[str, str]]:
    assert CSV.is_file(), f"the COM3 layout csv is missing: {CSV}"
    with CSV.open() as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return cantools.database.load_string(dbc_text("zx200"), database_format="dbc", strict=True)


def test_every_csv_row_matches_our_dbc(db: cantools.database.can.Database) -> None:
    rows = _rows()
    assert len(rows) == 114
    seen: set[tuple[str, str]] = set()
    for row in rows:
        where = f"{row['frame_name']}.{row['signal']}"
        msg = db.get_message_by_name(row["frame_name"])
        assert msg.frame_id == int(row["can_id_hex"], 16), where
        assert msg.is_extended_frame, where  # the DBC text marks extended ids with bit 31
        assert f"BO_ {int(row['can_id_hex'], 16) | 0x80000000} {row['frame_name']}:" in dbc_text("zx200"), where
        assert msg.length == int(row["dlc"]), where
        assert msg.cycle_time == int(row["cycle_ms"]), where
        sender = "ExternalController" if row["direction"] == "cmd" else "Hitachi_AutomationController"
        assert msg.senders == [sender], where
        sig = msg.get_signal_by_name(row["signal"])
        assert sig.start == int(row["start_bit"]), where
        assert sig.length == int(row["length"]), where
        assert sig.byte_order == ("little_endian" if row["byte_order"] == "little" else "big_endian"), where
        assert sig.is_signed == (row["signed"] == "true"), where
        assert sig.scale == pytest.approx(float(row["scale"]), rel=1e-12), where
        assert sig.offset == pytest.approx(float(row["offset"]), rel=1e-12), where
        if row["min"] == "":
            assert sig.minimum is None and sig.maximum is None, where  # DBC [0|0] = unspecified
        else:
            assert sig.minimum == pytest.approx(float(row["min"])), where
            assert sig.maximum == pytest.approx(float(row["max"])), where
        assert (sig.unit or "") == row["unit"], where
        seen.add((row["frame_name"], row["signal"]))
    ours = {(m.name, s.name) for m in db.messages for s in m.signals}
    assert ours == seen, f"extra in DBC: {sorted(ours - seen)}, missing: {sorted(seen - ours)}"
    assert len(db.messages) == 22


def test_value_tables(db: cantools.database.can.Database) -> None:
    setting = db.get_message_by_name("Machine_Setting_Cmd")
    tables = {s.name: dict(s.choices) for s in setting.signals if s.choices}
    assert {k: {int(r): str(n) for r, n in v.items()} for k, v in tables.items()} == {
        "power_eco_mode": {1: "Power Mode", 0: "Eco Mode"},
        "travel_speed_mode": {1: "Turtle", 0: "Rabbit"},
        "working_mode_notice": {1: "Automation", 0: "Teleoperation"},
        "yellow_led_mode": {2: "Steady light", 1: "Blinking", 0: "Off"},
    }
    assert all(not s.choices for m in db.messages if m.name != "Machine_Setting_Cmd" for s in m.signals)


def test_known_vector_velocity_cmd_1() -> None:
    codec = load_codec("zx200")
    data = codec.encode(
        "Velocity_Cmd_1",
        {
            "boom_target_anguler_velocity": 0.1,
            "arm_target_anguler_velocity": -0.2,
            "bucket_target_anguler_velocity": 0.0,
            "swing_target_anguler_velocity": 0.5,
        },
    )
    assert data.hex() == "c87d707b007de880"


def test_neutral_raws_are_the_documented_ones() -> None:
    """pwri-opera/com3: neutral velocity raw 32000 (00 7D x4); 0 MPa pilot = raw 0; all-zero is not neutral."""
    codec = load_codec("zx200")
    assert codec.encode("Velocity_Cmd_1", codec.neutral("Velocity_Cmd_1")).hex() == "007d" * 4
    assert codec.encode("Velocity_Cmd_2", codec.neutral("Velocity_Cmd_2")).hex() == "007d" * 4
    assert codec.encode("Pilot_Pressure_Cmd_1", codec.neutral("Pilot_Pressure_Cmd_1")) == bytes(8)
    _, zero = codec.decode(codec.frame_id("Velocity_Cmd_1"), bytes(8))
    assert zero["boom_target_anguler_velocity"] == pytest.approx(-16.0)
