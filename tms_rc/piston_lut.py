"""Identification of the piston-velocity look-up table (HEAP 2.4): per front function and direction, pairs pilot
pressure -> steady piston speed, from pilot steps held on the machine.

Pure core (no ROS, no CAN, no plant): the experiment talks to the machine through :class:`PilotRig` (command one
function's pilot along its piston, advance one control period, read the cylinder length), so the same procedure runs
in-process against the plant core (``tests/bench/bench_piston.py``'s ``PlantRig``) or, with a rig over COM3 CAN, on a
machine. The piston speed is measured from the cylinder length rate (the joint angle through the description's
geometry). Per direction (extend, retract), :func:`identify_direction`:

1. crack: bisection between 0 and the DBC's maximum pilot ``p_max`` on "the piston moves" (steady speed above
   ``moving_mps``) down to ``crack_tolerance_mpa``; the crack is the highest pilot that does not move it;
2. full: the speed at the maximum pilot, then bisection for the lowest pilot whose speed reaches ``full_fraction``
   of it (the spool fully open, or the pump's limit);
3. ``levels`` (13) pilots spread evenly from the crack to the full pilot, a step each: the pairs.

A step with less than ``min_room_fraction`` of the stroke ahead starts ``start_fraction`` of the stroke from the end
it moves away from (a move at ``reposition_pilot_mpa`` takes it there); it holds the pilot up to ``hold_s`` (ended
early once two consecutive windows of ``window_s`` agree, or when the piston comes within ``stroke_margin_m`` +
speed x ``lookahead_s`` of the end) and takes the mean speed of its last window. :func:`fit_lut` turns the record of
steps into the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from tms_rc.excavator.piston import DirectionLut, LutIdentificationSettings, PistonLut

__all__ = ["PilotRig", "PilotStep", "LutRecord", "identify_direction", "identify_lut", "fit_direction", "fit_lut"]


class PilotRig(Protocol):
    """The machine as the identification sees it."""

    dt: float  # [s] control period

    def command(self, function: str, piston_pilot: float) -> None:
        """Hold the signed pilot [MPa] along the piston (+ extends) on ``function``, nothing on the others."""

    def advance(self) -> None:
        """One control period."""

    def length(self, function: str) -> float:
        """The cylinder length [m] of ``function`` now."""


@dataclass(frozen=True)
class PilotStep:
    """One held pilot: ``pilot`` [MPa, signed along the piston], the steady ``speed`` [m/s, signed] of its last window,
    ``settled`` (two windows agreed), ``held_s`` and why it was held: ``crack``, ``top``, ``full`` or ``level``."""

    function: str
    pilot: float
    speed: float
    settled: bool
    held_s: float
    purpose: str


@dataclass
class LutRecord:
    """The steps of one function's identification and what was found on the way (per direction +1 / -1)."""

    function: str
    steps: list[PilotStep]
    crack: dict[int, float]
    full: dict[int, float]
    sim_s: float = 0.0
    stroke: tuple[float, float] = (0.0, 0.0)


def _wait_rest(rig: PilotRig, fn: str, s: LutIdentificationSettings) -> None:
    rig.command(fn, 0.0)
    need, still, last = max(1, round(s.rest_s / rig.dt)), 0, rig.length(fn)
    for _ in range(max(1, round(s.rest_timeout_s / rig.dt))):
        rig.advance()
        now = rig.length(fn)
        still = still + 1 if abs(now - last) / rig.dt < s.rest_mps else 0
        last = now
        if still >= need:
            return


def _move_to(rig: PilotRig, fn: str, goal: float, s: LutIdentificationSettings, limit_s: float = 20.0) -> None:
    """Bang-bang at ``reposition_pilot_mpa`` until within ``reposition_tolerance_m`` + speed x ``lookahead_s`` of
    ``goal``, then rest."""
    length = rig.length(fn)
    if abs(goal - length) <= s.reposition_tolerance_m:
        return
    sign = 1.0 if goal > length else -1.0
    rig.command(fn, sign * s.reposition_pilot_mpa)
    for _ in range(round(limit_s / rig.dt)):
        rig.advance()
        now = rig.length(fn)
        speed, length = abs(now - length) / rig.dt, now
        if sign * (goal - now) <= s.reposition_tolerance_m + speed * s.lookahead_s:
            break
    _wait_rest(rig, fn, s)


def _hold(rig: PilotRig, fn: str, pilot: float, stroke: tuple[float, float], s: LutIdentificationSettings,
          purpose: str) -> PilotStep:
    lo, hi = stroke
    span = hi - lo
    here = rig.length(fn)
    if (hi - here if pilot > 0 else here - lo) < s.min_room_fraction * span:
        _move_to(rig, fn, lo + s.start_fraction * span if pilot > 0 else hi - s.start_fraction * span, s)
    dt = rig.dt
    win = max(2, round(s.window_s / dt))
    lengths = [rig.length(fn)]
    rig.command(fn, pilot)
    settled = False
    for _ in range(max(1, round(s.hold_s / dt))):
        rig.advance()
        length = rig.length(fn)
        lengths.append(length)
        v = (length - lengths[-2]) / dt
        room = hi - length if pilot > 0 else length - lo
        if room < s.stroke_margin_m + abs(v) * s.lookahead_s:
            break
        if len(lengths) > 2 * win:
            a = (lengths[-1] - lengths[-1 - win]) / (win * dt)
            b = (lengths[-1 - win] - lengths[-1 - 2 * win]) / (win * dt)
            if abs(a) > s.moving_mps and abs(a - b) <= 0.02 * abs(a):
                settled = True
                break
    held = (len(lengths) - 1) * dt
    w = lengths[-min(win, len(lengths) - 1) - 1:]
    speed = (w[-1] - w[0]) / ((len(w) - 1) * dt)
    _wait_rest(rig, fn, s)
    return PilotStep(fn, pilot, speed, settled, held, purpose)


def _moving(step: PilotStep, direction: int, s: LutIdentificationSettings) -> bool:
    return step.speed * direction > s.moving_mps


def _top(rig: PilotRig, fn: str, direction: int, stroke: tuple[float, float], s: LutIdentificationSettings,
         steps: list[PilotStep], p_max: float) -> PilotStep:
    top = _hold(rig, fn, direction * p_max, stroke, s, "top")
    steps.append(top)
    if not _moving(top, direction, s):
        raise RuntimeError(f"{fn}: the piston does not move {'out' if direction > 0 else 'in'} at {p_max} MPa")
    return top


def _crack(rig: PilotRig, fn: str, direction: int, stroke: tuple[float, float], s: LutIdentificationSettings,
           steps: list[PilotStep], p_max: float) -> float:
    """Bisection on "the piston moves": the highest pilot [MPa] that does not."""
    lo, hi = 0.0, p_max
    while hi - lo > s.crack_tolerance_mpa:
        mid = 0.5 * (lo + hi)
        st = _hold(rig, fn, direction * mid, stroke, s, "crack")
        steps.append(st)
        lo, hi = (lo, mid) if _moving(st, direction, s) else (mid, hi)
    return lo


def _full(rig: PilotRig, fn: str, stroke: tuple[float, float], s: LutIdentificationSettings, steps: list[PilotStep],
          crack: dict[int, float], top: dict[int, PilotStep], p_max: float) -> dict[int, float]:
    """Bisection per direction, the two directions stepped in turn: the lowest pilot [MPa] whose speed reaches
    ``full_fraction`` of the speed at ``p_max``."""
    bracket = {d: [crack[d], p_max] for d in (1, -1)}
    while any(hi - lo > s.full_tolerance_mpa for lo, hi in bracket.values()):
        for d in (1, -1):
            lo, hi = bracket[d]
            if hi - lo <= s.full_tolerance_mpa:
                continue
            mid = 0.5 * (lo + hi)
            st = _hold(rig, fn, d * mid, stroke, s, "full")
            steps.append(st)
            bracket[d] = [lo, mid] if abs(st.speed) >= s.full_fraction * abs(top[d].speed) else [mid, hi]
    return {d: bracket[d][1] for d in (1, -1)}


def identify_direction(rig: PilotRig, fn: str, direction: int, stroke: tuple[float, float],
                       s: LutIdentificationSettings, steps: list[PilotStep],
                       p_max: float) -> tuple[float, float]:
    """One direction alone (the steps appended to ``steps``); (crack, full) [MPa]."""
    top = _top(rig, fn, direction, stroke, s, steps, p_max)
    crack = _crack(rig, fn, direction, stroke, s, steps, p_max)
    lo, hi = crack, p_max
    while hi - lo > s.full_tolerance_mpa:
        mid = 0.5 * (lo + hi)
        st = _hold(rig, fn, direction * mid, stroke, s, "full")
        steps.append(st)
        lo, hi = (lo, mid) if abs(st.speed) >= s.full_fraction * abs(top.speed) else (mid, hi)
    for p in np.linspace(crack, hi, s.levels)[1:]:
        steps.append(_hold(rig, fn, direction * float(p), stroke, s, "level"))
    return crack, hi


def identify_lut(rig: PilotRig, fn: str, stroke: tuple[float, float], s: LutIdentificationSettings,
                 p_max: float) -> tuple[PistonLut, LutRecord]:
    """Both directions of ``fn`` (cylinder ``stroke`` = (shortest, longest) length [m]; ``p_max`` [MPa] the largest
    pilot the DBC takes, :func:`tms_rc.excavator.piston.pilot_range`): the table and its record.

    The full searches and the level steps alternate extend / retract: each step brings the piston back, few moves
    between steps are needed."""
    rec = LutRecord(fn, [], {}, {}, stroke=stroke)
    top = {d: _top(rig, fn, d, stroke, s, rec.steps, p_max) for d in (1, -1)}
    rec.crack = {d: _crack(rig, fn, d, stroke, s, rec.steps, p_max) for d in (1, -1)}
    rec.full = _full(rig, fn, stroke, s, rec.steps, rec.crack, top, p_max)
    levels = {d: np.linspace(rec.crack[d], rec.full[d], s.levels)[1:] for d in (1, -1)}
    for k in range(s.levels - 1):
        for d in (1, -1):
            rec.steps.append(_hold(rig, fn, d * float(levels[d][k]), stroke, s, "level"))
    return fit_lut(rec, s.levels), rec


def fit_direction(steps: Sequence[PilotStep], direction: int, crack: float, full: float, levels: int) -> DirectionLut:
    """The ``levels`` pairs of one direction: the crack at speed 0, then the steps held at the levels spread from the
    crack to ``full`` (the nearest step of the record to each level; speeds as magnitudes)."""
    sign = float(direction)
    mine = [st for st in steps if st.pilot * sign > 0]
    pilots, speeds = [crack], [0.0]
    for p in np.linspace(crack, full, levels)[1:]:
        st = min(mine, key=lambda st: abs(abs(st.pilot) - p))
        if abs(abs(st.pilot) - p) > 1e-6:
            raise ValueError(f"no step of the record held {p:.3f} MPa (direction {direction:+d})")
        pilots.append(float(p))
        speeds.append(max(0.0, st.speed * sign))
    return DirectionLut(tuple(pilots), tuple(speeds))


def fit_lut(record: LutRecord, levels: int) -> PistonLut:
    return PistonLut(*(fit_direction(record.steps, d, record.crack[d], record.full[d], levels) for d in (1, -1)))
