"""Piston-level control through COM3 pilot pressures (HEAP 2.4) against the plant core in-process.

``python -m tests.bench piston``: on ``config/sim/paper_plant.yaml`` (the ZX200 with its bucket raised) it identifies
the look-up table (13 pairs pilot -> steady piston speed per function and direction, :mod:`tms_rc.piston_lut`) of
the boom, arm and bucket cylinders, tracks piston-velocity steps of the arm cylinder with the table alone and with
the table + PI (:class:`tms_rc.excavator.piston.PistonVelocityController`), then lowers the boom until the bucket
is buried in the mound (the plant has no contact force for the bucket on the ground: a buried bucket is held by
the soil's cutting resistance, friction on the front's joints, so the arm cylinder stalls) and steps the arm
cylinder's commanded force (:class:`tms_rc.excavator.piston.PistonForceController`): rise time 10-90 % and
steady-state error per step.

:class:`PlantRig` is the driver: the machine as the controllers see it (pilot pairs in, quantised to the DBC's
0.02 MPa; angles -> cylinder lengths through the description's geometry; chamber pressures -> cylinder forces), at
the plant's 10 ms step = the 100 Hz control rate. ``PISTON_FUNCTIONS=arm_joint`` limits the identification.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from sim_bridge.config import load_plant
from sim_bridge.plant import Plant
from tms_common.config import config_path, repo_root
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    PiGains,
    PilotPair,
    PistonControlSettings,
    PistonForceController,
    PistonLut,
    PistonVelocityController,
    cylinder_force,
    cylinder_of,
    extend_sign,
    load_piston_luts,
    load_piston_settings,
    pilot_range,
    piston_length,
    piston_lut_path,
    piston_stroke,
)
from tms_rc.piston_lut import LutRecord, identify_lut

#: [rad] the arm crowded in while the boom is identified: the bucket then clears the mound over the boom's whole
#: stroke (at the start pose's 1.8 rad only 0.56 of its 1.18 m are clear)
BOOM_ID_ARM_ANGLE = 2.3


class PlantRig:
    """The plant core's ZX200 driven by pilot pairs at 100 Hz; the controllers' view of it (:class:`PilotRig`)."""

    def __init__(self, plant_file: str = "paper_plant.yaml") -> None:
        self.plant = Plant(load_plant(config_path("sim", plant_file)))
        self.zx = self.plant.excavator
        self.front = self.zx.front
        self.names = self.front.names
        # the controller's own description of the machine (geometry only), not the plant's copy
        self.machine = load_kinematics().machine
        #: the DBC's pilot command range and resolution: what the controllers may send, what CAN carries of it
        self.p_max, self.p_step = pilot_range(self.machine.dbc)
        self.extend = {fn: extend_sign(self.machine, fn) for fn in CYLINDER_FUNCTIONS}
        self.stroke = {fn: piston_stroke(self.machine, fn) for fn in CYLINDER_FUNCTIONS}
        self.pairs: dict[str, PilotPair] = {n: PilotPair(0.0, 0.0) for n in self.names}
        self.dt = self.plant.dt
        self._last = {fn: self.length(fn) for fn in CYLINDER_FUNCTIONS}
        self.start_length = dict(self._last)  # [m] the plant's start pose (bucket raised)
        self.speed = dict.fromkeys(CYLINDER_FUNCTIONS, 0.0)  # [m/s] cylinder length rate of the last period

    def _quantise(self, p: float) -> float:
        return min(self.p_max, max(0.0, round(p / self.p_step) * self.p_step))

    def set_pair(self, fn: str, pair: PilotPair) -> None:
        self.pairs[fn] = PilotPair(self._quantise(pair.plus), self._quantise(pair.minus))

    def command(self, fn: str, piston_pilot: float) -> None:
        """Only ``fn`` gets a pilot (the identification's :class:`PilotRig`)."""
        for n in self.names:
            self.pairs[n] = PilotPair(0.0, 0.0)
        self.set_pair(fn, PilotPair.from_piston(piston_pilot, self.extend[fn]))

    def advance(self) -> None:
        self.zx.set_front_pilot({n: p.difference for n, p in self.pairs.items()})
        self.plant.step()
        for fn in CYLINDER_FUNCTIONS:
            now = self.length(fn)
            self.speed[fn] = (now - self._last[fn]) / self.dt
            self._last[fn] = now

    def length(self, fn: str) -> float:
        return piston_length(self.machine, fn, self.front.q[self.names.index(fn)])

    def force(self, fn: str) -> float:
        """Cylinder force [N] from the chamber pressures the machine reports (Pressure_1) and the areas."""
        i = self.names.index(fn)
        return cylinder_force(cylinder_of(self.machine, fn), self.front.p_ext[i] / 1e6, self.front.p_ret[i] / 1e6)

    def tip_depth(self) -> float:
        """[m] the bucket tip below the ground under it (the scenario's set-up, not a controller input)."""
        x, y, z = self.plant.bucket_tip()
        return self.plant.ground.height(x, y) - z

    def rest(self, seconds: float) -> None:
        for n in self.names:
            self.pairs[n] = PilotPair(0.0, 0.0)
        for _ in range(round(seconds / self.dt)):
            self.advance()


def clear_stroke(rig: PlantRig, fn: str, clearance: float = 0.3) -> tuple[float, float]:
    """The part of ``fn``'s stroke around where it stands over which the bucket tip stays ``clearance`` [m] above the
    ground, the other joints where they stand (a scratch copy of the plant, teleported): the identification's steps
    keep the bucket out of the mound (its cutting resistance would stall the front)."""
    scratch = Plant(rig.plant.spec)
    name = rig.plant.spec.excavator
    base = rig.plant.truth(name)
    here = dict(zip(rig.names, rig.front.q, strict=True))
    j = rig.machine.joint(fn)
    assert j.lower is not None and j.upper is not None
    qs = np.linspace(j.lower, j.upper, 61)
    clear = []
    for q in qs:
        scratch.set_truth(name, base.x, base.y, base.yaw, {**here, fn: float(q)})
        x, y, z = scratch.bucket_tip()
        clear.append(z - scratch.ground.height(x, y) >= clearance)
    k = int(np.argmin(np.abs(qs - here[fn])))
    lo = hi = k
    while lo > 0 and clear[lo - 1]:
        lo -= 1
    while hi < len(qs) - 1 and clear[hi + 1]:
        hi += 1
    a, b = (piston_length(rig.machine, fn, float(qs[i])) for i in (lo, hi))
    return min(a, b), max(a, b)


def identify(rig: PlantRig, fn: str, settings: PistonControlSettings) -> tuple[PistonLut, LutRecord]:
    """``fn``'s table over the stroke where the bucket stays clear of the ground (the boom's with the arm crowded in);
    ``fn`` back to its start length."""
    t0 = rig.plant.time
    if fn == "boom_joint":
        move_to(rig, "arm_joint", piston_length(rig.machine, "arm_joint", BOOM_ID_ARM_ANGLE))
    stroke = clear_stroke(rig, fn)
    lut, rec = identify_lut(rig, fn, stroke, settings.identification, rig.p_max)
    rec.stroke = stroke
    move_to(rig, fn, rig.start_length[fn])
    if fn == "boom_joint":
        move_to(rig, "arm_joint", rig.start_length["arm_joint"])
    rec.sim_s = rig.plant.time - t0
    return lut, rec


def controller_luts(rig: PlantRig, functions, settings: PistonControlSettings) -> tuple[dict[str, PistonLut], str]:
    """The tables the force benches' controllers use, and where they came from: the ZX200's file identified over CAN
    (``config/tms_rc/identified/zx200_piston_lut.yaml``, ``tms_rc_identify_pistons``), as a controller on the machine
    would read it; ``PISTON_LUTS=in_process``: identified here on ``rig`` (:func:`identify`, the rig left where it
    started)."""
    if os.environ.get("PISTON_LUTS", "identified") == "in_process":
        t0 = time.monotonic()
        luts = {fn: identify(rig, fn, settings)[0] for fn in functions}
        return luts, f"identified in-process on this plant ({time.monotonic() - t0:.0f} s wall)"
    path = piston_lut_path(rig.zx.name)  # the name the plant gives the machine: its file, as its controller reads it
    every = load_piston_luts(path=path)
    return {fn: every[fn] for fn in functions}, f"read from {path.relative_to(repo_root())} (identified over CAN)"


def move_to(rig: PlantRig, fn: str, goal: float, pilot: float = 1.5, tol: float = 0.03) -> None:
    """Bang-bang the cylinder to ``goal`` length [m], then rest (set-up between experiments)."""
    sign = 1.0 if goal > rig.length(fn) else -1.0
    rig.command(fn, sign * pilot)
    for _ in range(2000):
        rig.advance()
        if sign * (goal - rig.length(fn)) <= tol:
            break
    rig.rest(1.0)


@dataclass(frozen=True)
class TrackResult:
    v_ref: float
    feedback: bool
    steady_error: float  # [m/s] mean of v_ref - v over the last window
    steady_speed: float
    pilot: float  # [MPa] mean signed piston pilot over the window


def track_velocity(rig: PlantRig, fn: str, lut: PistonLut, settings: PistonControlSettings, v_ref: float, *,
                   feedback: bool, hold_s: float = 6.0, window_s: float = 1.5,
                   others: dict[str, float] | None = None) -> TrackResult:
    """A piston-velocity step ``v_ref`` [m/s] from the stroke's far end, held ``hold_s``; ``others``: a fixed piston
    pilot on other functions at the same time (their demand on the shared pumps)."""
    lo, hi = rig.stroke[fn]
    move_to(rig, fn, lo + 0.08 * (hi - lo) if v_ref > 0 else hi - 0.08 * (hi - lo))
    ctl = PistonVelocityController(lut, settings.velocity[fn], 1.0 / settings.rate_hz, extend=rig.extend[fn],
                                   zero_band=settings.zero_band_mpa, p_max=rig.p_max, feedback=feedback)
    n, w = round(hold_s / rig.dt), round(window_s / rig.dt)
    errors, speeds, pilots = [], [], []
    for _ in range(n):
        for o, p in (others or {}).items():
            rig.set_pair(o, PilotPair.from_piston(p, rig.extend[o]))
        v = rig.speed[fn]
        rig.set_pair(fn, ctl.step(v_ref, v))
        rig.advance()
        errors.append(v_ref - rig.speed[fn])
        speeds.append(rig.speed[fn])
        pilots.append(ctl.piston_pilot)
    rig.rest(1.0)
    return TrackResult(v_ref, feedback, float(np.mean(errors[-w:])), float(np.mean(speeds[-w:])),
                       float(np.mean(pilots[-w:])))


def bury_bucket(rig: PlantRig, depth: float = 1.0, limit_s: float = 20.0) -> float:
    """Arm and bucket cylinders back to their start lengths, then lower the boom (boom_down pilot) until the bucket
    tip is ``depth`` [m] into the ground, then rest; the depth."""
    for fn in ("arm_joint", "bucket_joint"):
        move_to(rig, fn, rig.start_length[fn])
    for _ in range(round(limit_s / rig.dt)):
        if rig.tip_depth() >= depth:
            break
        for n in rig.names:
            rig.pairs[n] = PilotPair(0.0, 0.0)
        rig.set_pair("boom_joint", PilotPair(1.5, 0.0))
        rig.advance()
    rig.rest(2.0)
    return rig.tip_depth()


@dataclass(frozen=True)
class ForceStep:
    f_from: float  # [N]
    f_to: float
    delay_s: float  # to 10 % of the step
    rise_s: float  # 10 % -> 90 % (nan: never reached 90 %)
    steady_error: float  # [N] mean of f_ref - f over the step's last second


def force_steps(rig: PlantRig, fn: str, lut: PistonLut, settings: PistonControlSettings, targets: list[float],
                hold_s: float = 5.0, window_s: float = 1.0, gains: PiGains | None = None) -> list[ForceStep]:
    """Steps of the commanded cylinder force [N] of ``fn``, ``hold_s`` each, from the force it holds now; ``gains``
    default the stall's (``settings.force``)."""
    ctl = PistonForceController(lut, gains or settings.force[fn], 1.0 / settings.rate_hz, extend=rig.extend[fn],
                                zero_band=settings.zero_band_mpa, p_max=rig.p_max)
    out = []
    f_from = rig.force(fn)
    n, w = round(hold_s / rig.dt), round(window_s / rig.dt)
    for f_to in targets:
        t10 = t90 = None
        forces = []
        for k in range(n):
            rig.set_pair(fn, ctl.step(f_to, rig.force(fn)))
            rig.advance()
            f = rig.force(fn)
            forces.append(f)
            frac = (f - f_from) / (f_to - f_from)
            if t10 is None and frac >= 0.1:
                t10 = (k + 1) * rig.dt
            if t90 is None and frac >= 0.9:
                t90 = (k + 1) * rig.dt
        err = float(np.mean([f_to - f for f in forces[-w:]]))
        out.append(ForceStep(f_from, f_to, t10 if t10 is not None else float("nan"),
                             (t90 - t10) if t90 is not None and t10 is not None else float("nan"), err))
        f_from = f_to
    return out


def print_lut(fn: str, lut: PistonLut, rec: LutRecord) -> None:
    for d, name in ((1, "extend"), (-1, "retract")):
        side = lut.side(d)
        print(f"  {fn} {name}: crack {rec.crack[d]:.3f} MPa, full {rec.full[d]:.3f} MPa; "
              "pairs (pilot MPa -> speed m/s): "
              + ", ".join(f"{p:.2f}->{s:.3f}" for p, s in zip(side.pilots, side.speeds, strict=True)))
    n = len(rec.steps)
    unsettled = sum(1 for st in rec.steps if not st.settled and abs(st.speed) > 0.003)
    print(f"  {fn}: stroke {rec.stroke[0]:.3f}-{rec.stroke[1]:.3f} m, {n} pilot steps, {rec.sim_s:.0f} s simulated "
          f"({unsettled} moving steps ended by the stroke before two windows agreed)")


def main() -> None:
    settings = load_piston_settings()
    functions = [f for f in os.environ.get("PISTON_FUNCTIONS", ",".join(CYLINDER_FUNCTIONS)).split(",") if f]
    wall0 = time.monotonic()
    rig = PlantRig()
    print(f"piston control in-process (MuJoCo plant core, config/sim/paper_plant.yaml, {settings.rate_hz:.0f} Hz, "
          f"pilots 0..{rig.p_max:g} MPa quantised to {rig.p_step:g} MPa as the DBC has them)")
    luts = {}
    for fn in functions:
        luts[fn], rec = identify(rig, fn, settings)
        print_lut(fn, luts[fn], rec)
    fn = "arm_joint" if "arm_joint" in luts else functions[0]
    print(f"velocity tracking, {fn} cylinder (steady-state error = mean of v_ref - v over the last 1.5 s of 6 s):")
    cases = [(0.15, None), (-0.2, None), (0.15, {"boom_joint": -5.0, "bucket_joint": 5.0})]
    for v_ref, others in cases:
        line = []
        for fb in (False, True):
            r = track_velocity(rig, fn, luts[fn], settings, v_ref, feedback=fb, others=others)
            line.append(f"{'LUT+PI' if fb else 'LUT only'} {r.steady_speed:+.4f} m/s (error {r.steady_error:+.4f}, "
                        f"pilot {r.pilot:+.2f} MPa)")
        load = "" if not others else " with boom and bucket at full pilot (pumps shared)"
        print(f"  v_ref {v_ref:+.3f} m/s{load}: " + "; ".join(line))
    rig = PlantRig()  # a fresh plant: the bucket enters the mound where the test's does
    depth = bury_bucket(rig)
    f0 = rig.force(fn)
    print(f"force steps, {fn} cylinder stalled with the bucket {depth:.2f} m in the mound (holding {f0 / 1e3:.1f} kN; "
          "8 s each, steady-state error = mean of f_ref - f over the last 2 s):")
    for st in force_steps(rig, fn, luts[fn], settings, [100e3, 250e3, 150e3, 0.0, -100e3], hold_s=8.0, window_s=2.0):
        print(f"  {st.f_from / 1e3:+7.1f} -> {st.f_to / 1e3:+7.1f} kN: 10 % after {st.delay_s:.2f} s, rise 10-90 % "
              f"{st.rise_s:.2f} s, steady-state error {st.steady_error / 1e3:+.2f} kN")
    print(f"  {time.monotonic() - wall0:.1f} s wall")


if __name__ == "__main__":
    main()
