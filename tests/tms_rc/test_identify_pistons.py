"""``tms_rc_identify_pistons``: the piston look-up table's identification (tms_rc.piston_lut) over COM3 CAN.

(a) :class:`CanPilotRig`'s frames, decoded with cantools from the DBC: the right ``Pilot_Pressure_Cmd_1`` line
carries the pilot (the sign along the piston -> the joint direction -> the line, as the plant reads it through
com3_can.signal_map), the machine is switched to pilot-pressure mode, the cylinder length comes from Front_Angle;
(b) bad input stops the command with one line naming the culprit; the written file is what
``load_piston_luts`` reads, and a missing one names itself; (c, integration) one function and direction identified
over CAN against a running sim_plant agrees with the in-process identification of the same plant.
"""

from __future__ import annotations

import dataclasses
import math
import random
import re
from importlib import resources
from pathlib import Path
from types import SimpleNamespace

import can
import cantools
import pytest
import yaml

from com3_can.signal_map import EXCAVATOR_FRONT
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import JOINTS, load_kinematics
from tms_rc import identify_pistons
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    extend_sign,
    load_piston_luts,
    load_piston_settings,
    piston_length,
    piston_stroke,
)
from tms_rc.identify import Codec, Link
from tms_rc.identify_pistons import CanPilotRig
from tms_rc.piston_lut import LutRecord, PilotStep

DBC = cantools.database.load_file(str(resources.files("com3_can").joinpath("dbc", "excavator_com3.dbc")))
MACHINE = load_kinematics("zx200").machine


def _rig() -> CanPilotRig:
    """A rig whose link only encodes (no bus): ``frame`` needs the codec alone."""
    return CanPilotRig(SimpleNamespace(codec=Codec(MACHINE.dbc), dt=0.01), MACHINE)  # type: ignore[arg-type]


def _decode(values: dict[str, float]) -> dict[str, float]:
    msg = DBC.get_message_by_name("Pilot_Pressure_Cmd_1")
    return {k: float(v) for k, v in msg.decode(msg.encode(values, scaling=True, strict=True)).items()}


# ---------------------------------------------------------------------------------------------- (a) frames
@pytest.mark.parametrize("fn", CYLINDER_FUNCTIONS)
@pytest.mark.parametrize("pilot", [1.234, -2.5, 4.0])
def test_a_piston_pilot_goes_out_on_the_line_that_turns_the_joint_the_pistons_way(fn: str, pilot: float) -> None:
    sent = _decode(_rig().frame(fn, pilot))
    lines = next(j for j in EXCAVATOR_FRONT if j.joint == fn)
    # the plant turns the joint + by pilot_plus - pilot_minus; a cylinder extends as its joint turns extend_sign
    joint_way = math.copysign(1.0, pilot) * extend_sign(MACHINE, fn)
    on, off = (lines.pilot_plus, lines.pilot_minus) if joint_way > 0 else (lines.pilot_minus, lines.pilot_plus)
    assert sent[on] == pytest.approx(round(abs(pilot) / 0.02) * 0.02)  # the DBC's 0.02 MPa resolution
    assert all(v == 0.0 for k, v in sent.items() if k != on), sent
    assert off in sent
    # named by joint direction: the boom's cylinder extends as the boom goes up (joint -), the arm's as it crowds (+)
    if fn == "boom_joint":
        assert on == ("boom_up" if pilot > 0 else "boom_down")
    if fn == "arm_joint":
        assert on == ("arm_crowd" if pilot > 0 else "arm_dump")


def test_pilots_are_clipped_into_the_dbcs_range_and_zero_is_no_command() -> None:
    rig = _rig()
    assert max(_decode(rig.frame("bucket_joint", 7.0)).values()) == pytest.approx(5.0)
    assert set(_decode(rig.frame("bucket_joint", 0.0)).values()) == {0.0}


class _Plant:
    """The plant's end of a virtual bus: state frames on demand, the commands received."""

    def __init__(self) -> None:
        self.channel = f"pilot_rig_{random.randrange(1 << 30)}"
        self.codec = Codec(MACHINE.dbc)
        self.bus = can.Bus(interface="virtual", channel=self.channel)

    def state(self, q: dict[str, float], v: dict[str, float] | None = None) -> None:
        short = {j: j.removesuffix("_joint") for j in JOINTS}
        for frame, values in (("Front_Angle", {f"{short[j]}_relative_angle": q[j] for j in JOINTS}),
                              ("Front_Angular_Velocity", {f"{short[j]}_relative_angular_velocity": (v or {}).get(j, 0.0)
                                                          for j in JOINTS})):
            self.bus.send(can.Message(arbitration_id=self.codec.frame_id(frame),
                                      data=self.codec.encode(frame, values), is_extended_id=True))

    def received(self) -> dict[str, dict[str, float]]:
        got = {}
        while (msg := self.bus.recv(0.2)) is not None:
            name, values = self.codec.decode(msg.arbitration_id, bytes(msg.data))
            got[name] = values
        return got


Q = {"swing_joint": 0.0, "boom_joint": -0.9, "arm_joint": 1.8, "bucket_joint": 1.2}


@pytest.fixture
def plant_and_rig():
    plant = _Plant()
    rig = CanPilotRig(Link(plant.codec, {"interface": "virtual", "channel": plant.channel}, front_mode=1,
                           travel_mode=1), MACHINE)
    try:
        yield plant, rig
    finally:
        rig.close()
        plant.bus.shutdown()


def test_a_period_sends_pilot_mode_and_both_pilot_frames_and_reads_the_length_from_front_angle(plant_and_rig) -> None:
    plant, rig = plant_and_rig
    plant.state(Q)
    rig.start(1.0)
    rig.command("arm_joint", 1.5)
    plant.state(Q)
    rig.advance()
    got = plant.received()
    assert set(got) == {"Pilot_Pressure_Cmd_1", "Pilot_Pressure_Cmd_2", "Machine_Setting_Cmd"}
    assert got["Machine_Setting_Cmd"]["front_signal_switch_command"] == 1  # pilot pressure (sim_bridge profile)
    assert got["Machine_Setting_Cmd"]["travel_signal_switch_command"] == 1
    assert got["Pilot_Pressure_Cmd_1"]["arm_crowd"] == pytest.approx(1.5)
    assert set(got["Pilot_Pressure_Cmd_2"].values()) == {0.0}
    for fn in CYLINDER_FUNCTIONS:  # Front_Angle's 0.0004 rad through a moment arm below 1 m
        assert rig.length(fn) == pytest.approx(piston_length(MACHINE, fn, Q[fn]), abs=4e-4)


def test_a_creep_below_the_angle_resolution_shows_in_the_length_within_the_angles_cell(plant_and_rig) -> None:
    plant, rig = plant_and_rig
    plant.state(Q)
    rig.start(1.0)
    q0 = rig.length("boom_joint")
    v = -0.005  # [rad/s] the boom creeping up: 0.05 mrad a period, an eighth of Front_Angle's step
    for k in range(1, 11):
        plant.state(Q, {"boom_joint": v})
        rig.advance()
        # the velocity integrated, but never out of the cell of the angle read (here the same reading throughout)
        expect = Q["boom_joint"] + max(v * 0.01 * k, -0.0002)
        assert rig.length("boom_joint") == pytest.approx(piston_length(MACHINE, "boom_joint", expect), abs=1e-6)
    assert rig.length("boom_joint") != q0


# ---------------------------------------------------------------------------------------------- (b) bad input, file
def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_an_unknown_machine_or_one_that_is_no_excavator_stops_it_with_one_line(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert identify_pistons.main(["--machine", "no_such_excavator"]) == 2
    assert "no_such_excavator" in _one_error_line(capsys)
    assert identify_pistons.main(["--machine", "ic120"]) == 2
    line = _one_error_line(capsys)
    assert re.search(r"ic120\.yaml: machine kind 'ic120' is a \w+, expected a excavator", line), line
    assert identify_pistons.main(["--machine", "zx200", "--functions", "swing_joint"]) == 2
    assert "swing_joint" in _one_error_line(capsys)


def test_a_plant_that_sends_nothing_stops_it_with_one_line_naming_the_bus(capsys: pytest.CaptureFixture[str],
                                                                         tmp_path: Path) -> None:
    out = tmp_path / "lut.yaml"
    assert identify_pistons.main(["--machine", "zx200", "--can-interface", "virtual", "--can-channel",
                                  f"silent_{random.randrange(1 << 30)}", "--wait-s", "0.3", "--output", str(out)]) == 1
    line = _one_error_line(capsys)
    assert line.startswith("tms_rc_identify_pistons: no Front_Angular_Velocity frame within 0.3 s"), line
    assert "silent_" in line and not out.exists()


def test_the_written_file_loads_and_a_missing_one_names_itself(tmp_path: Path) -> None:
    rec = {fn: LutRecord(fn, [], {1: 0.7, -1: 0.74}, {1: 3.0, -1: 2.9}, stroke=(1.7, 3.2))
           for fn in CYLINDER_FUNCTIONS}
    for fn, r in rec.items():  # the level steps of a table of 3 pairs
        for d in (1, -1):
            for p, v in ((0.5 * (r.crack[d] + r.full[d]), 0.2), (r.full[d], 0.45)):
                r.steps.append(PilotStep(fn, d * p, d * v, True, 1.0, "level"))
    path = tmp_path / "zx200_piston_lut.yaml"
    path.write_text(identify_pistons.render("zx200", "tms_rc_identify_pistons --machine zx200", [], rec, 3, 1.0))
    luts = load_piston_luts(path=path)
    assert set(luts) == set(CYLINDER_FUNCTIONS)
    assert luts["arm_joint"].retract.pilots == pytest.approx((0.74, 1.82, 2.9))
    assert luts["arm_joint"].extend.speeds == pytest.approx((0.0, 0.2, 0.45))
    with pytest.raises(ConfigError, match=r"nothing_here_piston_lut\.yaml: no identified piston look-up table"):
        load_piston_luts(path=tmp_path / "nothing_here_piston_lut.yaml")


def test_the_committed_zx200_table_loads() -> None:
    luts = load_piston_luts("zx200")
    assert set(luts) == set(CYLINDER_FUNCTIONS)
    for lut in luts.values():
        assert 0.0 < lut.extend.crack < lut.extend.pilots[-1] <= 5.0 and lut.retract.max_speed > 0.1


# ---------------------------------------------------------------------------------------------- (c) integration
FN = "arm_joint"
LEVELS = 3


@pytest.mark.integration
def test_one_direction_identified_over_can_agrees_with_the_in_process_identification(procs, domain, tmp_path):
    from tests.bench.bench_piston import PlantRig
    from tests.rosproc import executable, start_private_plant
    from tms_common.config import config_path
    from tms_rc.piston_lut import identify_direction

    # the paper plant starts the front in the air (plant.yaml's home pose has the bucket in the mound); at twice real
    # time the over-CAN run of one direction (~60 s simulated) stays near 30 s wall
    buses = start_private_plant(procs, domain, config_path('sim', 'paper_plant.yaml'), speed=2.0, group=78)
    out = tmp_path / "lut.yaml"
    ident = procs([executable("tms_rc", "tms_rc_identify_pistons"), "--machine", "zx200", "--can-interface",
                   "udp_multicast", "--can-channel", buses["zx200"]["channel"], "--can-port",
                   str(buses["zx200"]["port"]), "--functions", FN, "--direction", "extend", "--levels", str(LEVELS),
                   "--output", str(out)], name="tms_rc_identify_pistons")
    assert ident.wait(120) == 0, ident.output
    text = out.read_text()
    assert f"--functions {FN}" in text.splitlines()[3]  # the command that made it
    over_can = yaml.safe_load(text)["functions"][FN]["extend"]

    # the same procedure in-process on the plant core of the same plant file, from the same start pose
    rig = PlantRig("paper_plant.yaml")
    s = dataclasses.replace(load_piston_settings().identification, levels=LEVELS)
    steps: list = []
    crack, full = identify_direction(rig, FN, 1, piston_stroke(rig.machine, FN), s, steps, rig.p_max)
    at_full = next(st.speed for st in reversed(steps) if abs(st.pilot - full) < 1e-9)
    # Over CAN the angle arrives quantised (Front_Angle: 0.0004 rad, ~0.2 mm of the arm cylinder, ~0.001 m/s on a
    # 0.2 s window) and every pilot one frame later: a steady speed moves by a fraction of a percent, and a bisection
    # decision near its threshold may flip. The crack then differs by at most its bracket (0.02 MPa) plus the pilot
    # resolution (0.02 MPa); the speed at the full pilot lies between full_fraction (98 %) of the top speed and the
    # top speed in both runs: 3 % apart at most; the full pilot by one bracket of its bisection (0.1 MPa).
    assert over_can["pilot_mpa"][0] == pytest.approx(crack, abs=0.04), (over_can, crack)
    assert over_can["speed_mps"][-1] == pytest.approx(at_full, rel=0.03), (over_can, at_full)
    assert over_can["pilot_mpa"][-1] == pytest.approx(full, abs=s.full_tolerance_mpa + 0.02), (over_can, full)


# ---------------------------------------------------------------------------------------------- the comparison
def compare(path: Path) -> None:
    """Print, per function and direction, the crack pilot, the full pilot and the speed at the full pilot of the
    table in ``path`` (identified over CAN) beside those of the in-process identification on the plant core
    (``python -m tests.bench piston``'s ``identify``, the same procedure and set-up, on config/sim/paper_plant.yaml)."""
    from tests.bench.bench_piston import PlantRig, identify

    over_can = load_piston_luts(path=path)
    settings = load_piston_settings()
    rig = PlantRig("paper_plant.yaml")
    print(f"{'function':<13}{'direction':<9}{'crack CAN':>10}{'in-proc':>9}{'diff':>8}{'full CAN':>10}{'in-proc':>9}"
          f"{'diff':>8}{'v_full CAN':>12}{'in-proc':>9}{'diff':>9}{'pairs max|dv|':>15}   [MPa, MPa, m/s]")
    for fn in CYLINDER_FUNCTIONS:
        if fn not in over_can:
            continue
        lut, _ = identify(rig, fn, settings)
        for d, name in ((1, "extend"), (-1, "retract")):
            a, b = over_can[fn].side(d), lut.side(d)
            print(f"{fn:<13}{name:<9}{a.crack:>10.3f}{b.crack:>9.3f}{a.crack - b.crack:>+8.3f}"
                  f"{a.pilots[-1]:>10.3f}{b.pilots[-1]:>9.3f}{a.pilots[-1] - b.pilots[-1]:>+8.3f}"
                  f"{a.max_speed:>12.4f}{b.max_speed:>9.4f}{a.max_speed - b.max_speed:>+9.4f}"
                  f"{max(abs(x - y) for x, y in zip(a.speeds, b.speeds, strict=True)):>15.4f}")


if __name__ == "__main__":
    import sys

    compare(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("config/tms_rc/identified/zx200_piston_lut.yaml"))
