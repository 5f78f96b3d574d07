"""Command ``tms_rc_identify_pistons``: identify an excavator's piston-velocity look-up tables (HEAP 2.4) over its
COM3 CAN bus.

The procedure is :mod:`tms_rc.piston_lut`'s (per cylinder function and direction: the crack pilot, the full pilot,
then pilot steps spread between them; the piston speed is the cylinder length rate); here it runs through
:class:`CanPilotRig`, the machine as a COM3 peer in pilot-pressure mode. It writes
``config/tms_rc/identified/<machine>_piston_lut.yaml``, which :func:`tms_rc.excavator.piston.load_piston_luts`
reads, with the command line and the plant's configuration in its header::

    tms_rc_identify_pistons --plant-config config/sim/paper_plant.yaml --machine zx200    # starts sim_plant itself
    tms_rc_identify_pistons --machine zx200 --can-interface udp_multicast --can-channel 239.74.163.20 --can-port 43120

The link, the bus, the plant start and the header are :mod:`tms_rc.identify`'s. Time base: the plant's own, one
control period per Front_Angular_Velocity frame (10 ms), the pilot frame sent on each. Only the description's
geometry and limits are read (cylinder pins, joint ranges, the DBC's pilot range), never its hydraulics.

Safety: every step stays within the cylinder's stroke over the description's joint range less the identification's
``stroke_margin_m`` (config/tms_rc/piston_control.yaml); the machine must stand where the bucket clears the ground
over each cylinder's whole stroke from its start pose (the paper plant's start pose does; plant.yaml's home pose has
the bucket in the mound). The boom is identified with the arm crowded in (``--boom-arm-angle``): the bucket then
stays high over the boom's whole stroke.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import can
import numpy as np

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import JOINTS
from tms_model.machines import EXCAVATOR, Machine
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    LutIdentificationSettings,
    PilotPair,
    PistonLut,
    extend_sign,
    load_piston_settings,
    pilot_range,
    piston_length,
    piston_lut_path,
    piston_stroke,
)
from tms_rc.identify import (
    Codec,
    Link,
    _command_line,
    _common_args,
    _description,
    _num,
    _plant_lines,
    _rel,
    _terminate,
    bus_config,
    start_plant,
)
from tms_rc.piston_lut import LutRecord, fit_direction, identify_direction, identify_lut

__all__ = ["CanPilotRig", "PILOT_LINES", "main"]

#: the COM3 frames of the pilot commands: the front's, and the travel / attachment levers' (held at 0)
FRONT_PILOT, TRAVEL_PILOT = "Pilot_Pressure_Cmd_1", "Pilot_Pressure_Cmd_2"
#: the ``Pilot_Pressure_Cmd_1`` lines of each cylinder function: (turns the joint +, turns it -) in COM3's joint
#: signs (boom + = down, arm + = crowd, bucket + = crowd); com3_can.signal_map holds the same (not imported: it is on
#: tms_rc's architecture level, docs/architecture.md)
PILOT_LINES: Mapping[str, tuple[str, str]] = {
    "boom_joint": ("boom_down", "boom_up"),
    "arm_joint": ("arm_crowd", "arm_dump"),
    "bucket_joint": ("bucket_crowd", "bucket_dump"),
}
#: [rad] the arm's angle while the boom is identified (as tests/bench/bench_piston.py: the bucket clears the mound
#: over the boom's whole stroke on the paper plant)
BOOM_ARM_ANGLE = 2.3
DIRECTIONS = {"extend": (1,), "retract": (-1,), "both": (1, -1)}


class CanPilotRig:
    """The machine over COM3 CAN as :class:`tms_rc.piston_lut.PilotRig` sees it: ``Machine_Setting_Cmd`` front and
    travel in pilot-pressure mode, one ``Pilot_Pressure_Cmd_1`` (the commanded function's line, quantised to the
    DBC's resolution, every other line 0) and one ``Pilot_Pressure_Cmd_2`` (all 0: tracks and attachments still) per
    plant step; the cylinder length from ``Front_Angle`` through the description's geometry.

    ``Front_Angle`` has 0.0004 rad steps (0.43 mm of the boom cylinder, 0.043 m/s over one 10 ms period): a piston
    creeping at a few mm/s keeps the same reading for ~10 periods, and the procedure's rest test (the period's length
    rate below ``rest_mps`` for ``rest_s``) passed on it, so the next step began on a boom still moving and a pilot
    below the crack counted as moving it. The angle used is therefore the previous one advanced by the period's
    ``Front_Angular_Velocity`` (0.0002 rad/s steps), held within the quantisation cell of the angle read."""

    def __init__(self, link: Link, machine: Machine, tick_timeout_s: float = 5.0) -> None:
        self.link = link
        self.machine = machine
        self.dt = link.dt
        self.tick_timeout_s = tick_timeout_s
        self.p_max, self.p_step = pilot_range(machine.dbc)
        self.extend = {fn: extend_sign(machine, fn) for fn in CYLINDER_FUNCTIONS}
        self._travel = link.codec.neutral(TRAVEL_PILOT)
        self._front = self.frame(None, 0.0)
        #: [rad] half the Front_Angle resolution: the true angle lies within this of the one read
        self._half_step = 0.5 * max(sg.scale for sg in link.codec.db.get_message_by_name("Front_Angle").signals)
        self._q: np.ndarray | None = None

    def frame(self, function: str | None, piston_pilot: float) -> dict[str, float]:
        """The ``Pilot_Pressure_Cmd_1`` values for a signed pilot [MPa] along ``function``'s piston (+ extends)."""
        values = self.link.codec.neutral(FRONT_PILOT)
        if function is not None:
            pair = PilotPair.from_piston(piston_pilot, self.extend[function])
            plus, minus = PILOT_LINES[function]
            values[plus], values[minus] = self._quantise(pair.plus), self._quantise(pair.minus)
        return values

    def _quantise(self, p: float) -> float:
        return min(self.p_max, max(0.0, round(p / self.p_step) * self.p_step))

    def start(self, timeout_s: float = 30.0) -> None:
        """Wait for the first state (the plant may still be starting), then switch the machine to pilot mode at once
        (the plant ignores pilot frames until a setting frame has selected them)."""
        self.link.wait_tick(timeout_s)
        self._observe()
        self.link.send_setting(now=True)

    def command(self, function: str, piston_pilot: float) -> None:
        self._front = self.frame(function, piston_pilot)

    def advance(self) -> None:
        self.link.transmit(FRONT_PILOT, self._front)
        self.link.transmit(TRAVEL_PILOT, self._travel)
        self.link.send_setting()
        self.link.wait_tick(self.tick_timeout_s)
        self._observe()

    def _observe(self) -> None:
        q = self.link.q
        assert q is not None
        if self._q is None:
            self._q = q.copy()
        else:
            self._q = np.clip(self._q + self.link.v * self.dt, q - self._half_step, q + self._half_step)

    def length(self, function: str) -> float:
        assert self._q is not None, "no Front_Angle yet (call start)"
        return piston_length(self.machine, function, float(self._q[JOINTS.index(function)]))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._front = self.frame(None, 0.0)
            self.link.transmit(FRONT_PILOT, self._front)
        self.link.close()


def move_to(rig: CanPilotRig, fn: str, goal: float, pilot: float = 1.5, tol: float = 0.03,
            limit_s: float = 20.0) -> None:
    """Bang-bang the cylinder to ``goal`` length [m], then rest 1 s: the set-up between functions (as the bench's
    ``move_to``, so both experiments start alike)."""
    sign = 1.0 if goal > rig.length(fn) else -1.0
    rig.command(fn, sign * pilot)
    for _ in range(round(limit_s / rig.dt)):
        rig.advance()
        if sign * (goal - rig.length(fn)) <= tol:
            break
    rig.command(fn, 0.0)
    for _ in range(round(1.0 / rig.dt)):
        rig.advance()


def identify_function(rig: CanPilotRig, fn: str, s: LutIdentificationSettings, directions: Sequence[int],
                      boom_arm_angle: float | None) -> tuple[PistonLut | None, LutRecord]:
    """``fn``'s table (both directions) or the record of one direction (table None); ``fn`` (and the arm, for the
    boom) back to where it started."""
    tick0 = rig.link.tick
    start = {f: rig.length(f) for f in CYLINDER_FUNCTIONS}
    if fn == "boom_joint" and boom_arm_angle is not None:
        move_to(rig, "arm_joint", piston_length(rig.machine, "arm_joint", boom_arm_angle))
    stroke = piston_stroke(rig.machine, fn)
    if len(directions) == 2:
        lut, rec = identify_lut(rig, fn, stroke, s, rig.p_max)
    else:
        d = directions[0]
        rec = LutRecord(fn, [], {}, {}, stroke=stroke)
        rec.crack[d], rec.full[d] = identify_direction(rig, fn, d, stroke, s, rec.steps, rig.p_max)
        lut = None
    move_to(rig, fn, start[fn])
    if fn == "boom_joint" and boom_arm_angle is not None:
        move_to(rig, "arm_joint", start["arm_joint"])
    rec.sim_s = (rig.link.tick - tick0) * rig.dt
    return lut, rec


# ------------------------------------------------------------------------------------------------------ output
def render(name: str, command_line: str, plant_lines: Sequence[str], records: Mapping[str, LutRecord],
           levels: int, wall_s: float) -> str:
    """The file :func:`tms_rc.excavator.piston.load_piston_luts` reads, with how it was made in comments."""
    out = [
        f"# Piston-velocity look-up tables of {name} identified over its COM3 CAN bus by",
        "# tms_rc_identify_pistons (tms_rc/identify_pistons.py, procedure tms_rc.piston_lut), read by",
        "# tms_rc.excavator.piston.load_piston_luts. Made with:",
        f"#   {command_line}",
        *plant_lines,
        "# Per function and direction (extend = the cylinder gets longer): pilot_mpa rising from the crack (the",
        "# highest pilot that does not move the piston, speed 0) to the full pilot (the lowest whose speed reaches",
        f"# the identification's full_fraction of the speed at the DBC's maximum pilot), {levels} pairs; speed_mps =",
        "# steady piston speed [m/s] (the mean of a held step's last window), measured in the plant's time",
        "# (Front_Angle frames through the description's cylinder geometry).",
        f"# Over-CAN run: {wall_s:.0f} s wall.",
        f"machine: {name}",
        "functions:",
    ]
    for fn, rec in records.items():
        out.append(f"  {fn}:")
        for d, side in ((1, "extend"), (-1, "retract")):
            if d not in rec.crack:
                continue
            lut = fit_direction(rec.steps, d, rec.crack[d], rec.full[d], levels)
            out.append(f"    {side}:")
            out.append("      pilot_mpa: [" + ", ".join(_num(p, 3) for p in lut.pilots) + "]")
            out.append("      speed_mps: [" + ", ".join(_num(v, 4) for v in lut.speeds) + "]")
    out.append("# The runs: crack and full pilot [MPa], speed at the full pilot [m/s], stroke used [m], pilot steps,")
    out.append("# simulated seconds (the function's, set-up moves included)")
    for fn, rec in records.items():
        for d, side in ((1, "extend"), (-1, "retract")):
            if d not in rec.crack:
                continue
            at_full = fit_direction(rec.steps, d, rec.crack[d], rec.full[d], levels).max_speed
            out.append(f"#   {fn} {side}: crack {rec.crack[d]:.3f}, full {rec.full[d]:.3f}, {at_full:.4f} m/s, "
                       f"stroke {rec.stroke[0]:.3f}-{rec.stroke[1]:.3f}, {len(rec.steps)} steps, {rec.sim_s:.0f} s")
    out.append("# The steps held (tms_rc.piston_lut.PilotStep): purpose, pilot along the piston [MPa] -> steady")
    out.append("# speed [m/s], held [s], settled (two windows agreed)")
    for fn, rec in records.items():
        out += [f"#   {fn} {st.purpose} {st.pilot:+.3f} -> {st.speed:+.4f}, {st.held_s:.2f}"
                + (", settled" if st.settled else "") for st in rec.steps]
    return "\n".join(out) + "\n"


# -------------------------------------------------------------------------------------------------------- main
def _args(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="tms_rc_identify_pistons", description=__doc__.split("\n\n")[0])
    _common_args(ap)
    ap.add_argument("--functions", default=",".join(CYLINDER_FUNCTIONS),
                    help="comma-separated cylinder functions to identify")
    ap.add_argument("--direction", choices=sorted(DIRECTIONS), default="both",
                    help="one direction alone writes a partial file (no loadable table): a check, not a table")
    ap.add_argument("--levels", type=int, help="pairs per direction (default: piston_control.yaml's)")
    ap.add_argument("--boom-arm-angle", type=float, default=BOOM_ARM_ANGLE,
                    help="[rad] the arm's angle while the boom is identified (nan: where it stands)")
    ap.add_argument("--wait-s", type=float, default=30.0,
                    help="[s] longest wait for the plant's first state frame (a plant still starting)")
    ap.add_argument("--output", type=Path, help="default config/tms_rc/identified/<machine>_piston_lut.yaml")
    return ap.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; a bad file or option stops it with one line (``file:line: key: problem``), exit code 2; a
    plant that sends nothing or a piston that does not move, one line, exit code 1."""
    signal.signal(signal.SIGTERM, _terminate)
    args = _args(argv)
    try:
        return _run(args, argv)
    except (ConfigError, ValueError) as exc:
        print(f"tms_rc_identify_pistons: {exc}", file=sys.stderr, flush=True)
        return 2
    except (TimeoutError, RuntimeError, can.CanError, OSError) as exc:
        print(f"tms_rc_identify_pistons: {exc}", file=sys.stderr, flush=True)
        return 1


def _run(args: argparse.Namespace, argv: Sequence[str] | None,
         log: Callable[[str], None] = lambda m: print(m, flush=True)) -> int:
    if args.plant_config is not None:
        args.plant_config = args.plant_config.resolve()
    command_line = _command_line("tms_rc_identify_pistons", argv)
    machine, machine_file = _description(args.machine, args.machine_config, args.plant_config)
    machine.require(EXCAVATOR)
    functions = [f.strip() for f in args.functions.split(",") if f.strip()]
    unknown = [f for f in functions if f not in CYLINDER_FUNCTIONS]
    if unknown or not functions:
        raise ConfigError(f"--functions: {unknown} are not cylinder functions {list(CYLINDER_FUNCTIONS)}")
    settings = load_piston_settings().identification
    if args.levels is not None:
        settings = dataclasses.replace(settings, levels=args.levels)
    boom_arm = None if args.boom_arm_angle != args.boom_arm_angle else args.boom_arm_angle  # nan: no set-up move
    codec = Codec(machine.dbc)
    real_bus = None if args.plant_config is not None else bus_config(
        args.machine, {k: getattr(args, f"can_{k}") for k in ("interface", "channel", "port")})
    output = args.output or piston_lut_path(args.machine)
    records: dict[str, LutRecord] = {}
    wall0 = time.monotonic()
    with contextlib.ExitStack() as stack:
        if args.plant_config is not None:
            bus: Mapping[str, Any] = stack.enter_context(start_plant(args.plant_config, args.speed, log))[args.machine]
        else:
            bus = real_bus
        # pilot-pressure mode for the front and the tracks: every lever but the one under test at 0
        rig = CanPilotRig(Link(codec, bus, front_mode=1, travel_mode=1), machine)
        stack.callback(rig.close)
        rig.start(args.wait_s)
        log(f"{args.machine}: start lengths "
            + ", ".join(f"{fn} {rig.length(fn):.3f} m" for fn in CYLINDER_FUNCTIONS)
            + f"; pilots 0..{rig.p_max:g} MPa in {rig.p_step:g} MPa steps")
        for fn in functions:
            log(f"{fn}:")
            _, rec = identify_function(rig, fn, settings, DIRECTIONS[args.direction], boom_arm)
            records[fn] = rec
            for d in rec.crack:
                at_full = fit_direction(rec.steps, d, rec.crack[d], rec.full[d], settings.levels).max_speed
                log(f"  {'extend' if d > 0 else 'retract'}: crack {rec.crack[d]:.3f} MPa, full {rec.full[d]:.3f} MPa, "
                    f"{at_full:.4f} m/s at full ({len(rec.steps)} steps, {rec.sim_s:.0f} s simulated)")
    wall = time.monotonic() - wall0
    text = render(args.machine, command_line, _plant_lines(args.plant_config, machine_file, bus), records,
                  settings.levels, wall)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text)
    log(f"wrote {_rel(output)} ({wall:.0f} s wall)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
