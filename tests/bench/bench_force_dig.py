"""Force-controlled pressing and digging through the ID hierarchy + piston force control
(:class:`tms_rc.excavator.force_control.ForceLoop`) against the plant core in-process, ``soil.penetration: true``.

``python -m tests.bench force_dig``: reads the boom's, arm's and bucket's look-up tables identified over CAN
(``config/tms_rc/identified/zx200_piston_lut.yaml``; ``PISTON_LUTS=in_process``: identified on
``config/sim/paper_plant.yaml`` as ``python -m tests.bench piston`` does; their cracks feed the dead-zone
compensation), starts the ZX200 over flat ground (:data:`tests.bench.bench_force_steps.FLAT_FRONT`), presses the
edge down with the arm (as ``force_steps`` does) and hands the front to the loop at 100 Hz (the swing's pilot 0):

(a) arm and bucket under force control, the boom held: steps of the commanded normal force (the force the bucket
    exerts on the ground, straight down), fractions of the largest press the controller's own model allows at the
    start pose (every cylinder's static force within ``PRESS_MARGIN`` of its relief force, the machine description's
    bores and relief): per step the time to 10 %, rise 10-90 % and steady-state error (mean of F_ref - F over the
    last 2 s of 8 s) of the *plant's* bearing force on the edge (``Plant.press_force``, the truth), and the steady
    error of the loop's own estimate from the pressures;
(b') a drag towards the machine along the ground (the tip reference moving ``DRAG_M`` at ``DRAG_SPEED``, theta_w
    held) with a constant normal force reference and (a)'s roles (arm and bucket under force control, the boom
    held): RMS of F_ref - F (truth: the bearing + the cut's vertical force; and the estimate), the tip's depth along
    the cut (mean, min, max), the distance dragged and the soil cut;
(c) both designs side by side over the same drags on fresh plants (:func:`compare_drags`): ``ForceLoop`` with the
    drag's roles (:data:`tms_rc.excavator.force_control.DRAG_ROLES`: bucket under force control, boom and arm under
    velocity control) and :class:`tms_rc.excavator.admittance.AdmittanceDrag` (admittance over piston velocity
    control of all three, ``config/tms_rc/force_control.yaml``), on flat ground at ``DRAG_FRACTION`` and over the
    mound's flat top (:func:`mound_front`, pressed by the boom) at ``MOUND_FRACTIONS`` of the largest press, with
    the ratios admittance / ForceLoop and the admittance's tip height against its own reference;
(d) the third design, :class:`tms_rc.excavator.cut_force.CutForceDrag` (the force along the cut regulated through the
    depth of cut, ``cut_force:`` of ``config/tms_rc/force_control.yaml``), on flat ground and the mound with the
    bearing and on flat ground without it (:data:`CUT_CASES`): per case the plant's cutting resistance against the
    depth (:func:`cut_curve`, its slope in kN per cm), tangential references at :data:`CUT_DEPTHS` of that curve, and
    per drag the RMS tangential error (truth), the depth reached against the depth the reference implies, the volume
    cut, the normal force and a trace every 2 s (``FORCE_DIG_TRACE=0``: none); then one table of all three designs.

``FORCE_DIG_DRAG_FT`` [N]: a feed-forward pull along the cut (default 0: the tip PD alone drags).
``FORCE_DIG_ADMITTANCE="path_gain=0.5,admittance=0.0002"``: overrides of ``config/tms_rc/force_control.yaml``'s
``admittance`` keys for a sweep.
``FORCE_DIG_CUT="normal_gain=0.5"``: the same for ``cut_force``; ``FORCE_DIG_ONLY=cut``: (d) alone.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from tests.bench.bench_force_steps import FlatRig, press
from tests.bench.bench_piston import PlantRig, controller_luts
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.admittance import AdmittanceDrag, load_force_control_settings
from tms_rc.excavator.cut_force import CutForceDrag, CutForceSettings, load_cut_force_settings
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.force_control import DRAG_ROLES, ForceLoop, ForceLoopSettings
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import CYLINDER_FUNCTIONS, PilotPair, load_piston_settings

PRESS_MARGIN = 0.9  # every cylinder's static force within this fraction of its relief force
STEP_FRACTIONS = [0.3, 0.6, 0.45, 0.8, 0.3]  # of the largest press
DRAG_FRACTION = 0.45
HOLD_S, WINDOW_S = 8.0, 2.0
DRAG_M, DRAG_SPEED = 2.0, 0.15  # [m], [m/s]
MOUND_FRACTIONS = [0.3, 0.6]  # of the largest press at the pose on the mound's slope
#: over the mound ahead of the machine (the paper plant's start heading): the edge ~7 m out over its flat top
#: (1.5 m high, ~5.9-7.3 m out; beyond ~5.9 m towards the machine its slope falls, so the 2 m drag ends downhill)
MOUND_FRONT = {"arm_joint": 1.2, "bucket_joint": 1.2}


def largest_press(dyn: FrontDynamics, q: np.ndarray, margin: float) -> float:
    """[N] the largest straight-down force on the ground for which the statics of the controller's model keep every
    cylinder's force within ``margin`` of its relief force (bisection; monotonic in the force)."""
    grav = dyn.gravity(q)
    gains = dyn.actuator_gains(q)
    jac = dyn.tip_jacobian(q)
    fmax = np.array([a.force_max for a in dyn.actuators])
    fmin = np.array([a.force_min for a in dyn.actuators])

    def ok(f: float) -> bool:
        force = (grav + jac.T @ np.array([0.0, 0.0, -f]))[1:] / gains[1:]
        return bool(np.all(force <= margin * fmax[1:]) and np.all(force >= margin * fmin[1:]))

    lo, hi = 0.0, 2e6
    if not ok(lo):
        raise RuntimeError("the front cannot even hold itself within the relief margin at the start pose")
    while hi - lo > 500.0:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


class Driver:
    """The loop on the rig: the measured state in, the pilot pairs out, one plant step."""

    def __init__(self, rig: PlantRig, loop: ForceLoop | None) -> None:
        self.rig, self.loop = rig, loop

    def state(self) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[float, float]]]:
        fr = self.rig.front
        pressures = {fn: (fr.p_ext[fr.names.index(fn)] / 1e6, fr.p_ret[fr.names.index(fn)] / 1e6)
                     for fn in CYLINDER_FUNCTIONS}
        return np.array(fr.q, dtype=float), np.array(fr.v, dtype=float), pressures

    def step(self, ref: IdReference, force_d: np.ndarray):
        assert self.loop is not None
        q, qd, p = self.state()
        out = self.loop.step(q, qd, p, ref, force_d)
        for n in self.rig.names:
            self.rig.pairs[n] = PilotPair(0.0, 0.0)  # the swing: spool centred
        for fn, pair in out.pairs.items():
            self.rig.set_pair(fn, pair)
        self.rig.advance()
        return out


def truth_normal(rig: PlantRig) -> float:
    """[N] the soil's upward force on the edge: the bearing plus the cut's vertical part (the plant's truth)."""
    p = rig.plant
    cut = p.cut_force[0][2] if p.cut_force is not None else 0.0
    return float(p.press_force + cut)


def truth_tangential(rig: PlantRig) -> float:
    """[N] the soil's cutting resistance along the cut on the edge (the plant's wedge, horizontal; 0 out of the cut)."""
    p = rig.plant
    return float(np.hypot(*p.cut_force[0][:2])) if p.cut_force is not None else 0.0


def hold_reference(loop: ForceLoop | AdmittanceDrag, q: np.ndarray) -> IdReference:
    tip = loop.dyn.tip_position(q)
    return IdReference(position=tip, theta_w=float(q[1] + q[2] + q[3]) + loop.kin.c_bucket)


def run_steps(drv: Driver, fmax: float) -> None:
    rig, loop = drv.rig, drv.loop
    q, _, _ = drv.state()
    ref = hold_reference(loop, q)
    n, w = round(HOLD_S / rig.dt), round(WINDOW_S / rig.dt)
    f_from = rig.plant.press_force
    for frac in STEP_FRACTIONS:
        f_to = frac * fmax
        t10 = t90 = None
        truth, est = [], []
        for k in range(n):
            out = drv.step(ref, np.array([0.0, 0.0, -f_to]))
            f = truth_normal(rig)
            truth.append(f)
            est.append(-float(out.pressed[2]))
            frac_done = (f - f_from) / (f_to - f_from) if f_to != f_from else 1.0
            if t10 is None and frac_done >= 0.1:
                t10 = (k + 1) * rig.dt
            if t90 is None and frac_done >= 0.9:
                t90 = (k + 1) * rig.dt
        err = float(np.mean([f_to - f for f in truth[-w:]]))
        err_est = float(np.mean([f_to - f for f in est[-w:]]))
        rise = f"{t90 - t10:.2f} s" if t90 is not None and t10 is not None else "never (90 % not reached)"
        ten = f"{t10:.2f} s" if t10 is not None else "never"
        print(f"    {f_from / 1e3:6.1f} -> {f_to / 1e3:6.1f} kN: 10 % after {ten}, rise 10-90 % {rise}, steady-state "
              f"error {err / 1e3:+.2f} kN (estimate's {err_est / 1e3:+.2f} kN); edge {100 * rig.tip_depth():.1f} cm "
              f"deep, cylinders {', '.join(f'{f / 1e3:.0f}' for f in out.measured)} kN, correction "
              f"{loop.correction / 1e3:+.1f} kN")
        f_from = f_to


@dataclass
class DragResult:
    """One drag's figures (the plant's truth scores; the estimate is the controller's own)."""

    rms: float  # [N] RMS of F_ref - F (truth: bearing + the cut's vertical)
    mean: float  # [N]
    rms_est: float  # [N] RMS of F_ref - the controller's (unfiltered) estimate from the pressures
    depth: np.ndarray  # [m] the edge below the ground under it, per step after the first second
    along: float  # [m] the tip's horizontal travel
    cut: float  # [m^3] the plant's soil volume change (soil.dug)
    bucket: float  # [m^3] the bucket's load at the end
    tangential: float = 0.0  # [N] mean of the plant's cutting resistance along the cut (truth), scored steps
    normal_max: float = 0.0  # [N] largest normal force (truth), scored steps

    def line(self) -> str:
        d = 100 * self.depth
        return (f"RMS force error {self.rms / 1e3:5.2f} kN (estimate's {self.rms_est / 1e3:5.2f}), mean "
                f"{self.mean / 1e3:+6.2f} kN; depth mean {d.mean():5.1f} cm (min {d.min():5.1f}, max {d.max():5.1f}); "
                f"dragged {self.along:.2f} m; cut {self.cut:.3f} m^3, bucket {self.bucket:.3f} m^3")


class LoopDesign:
    """Design 1: the colleague's :class:`ForceLoop` (ID + piston force control; roles) on the rig."""

    name = "ForceLoop"

    def __init__(self, rig: PlantRig, loop: ForceLoop, f_t: float = 0.0) -> None:
        self.drv, self.loop, self.f_t = Driver(rig, loop), loop, f_t

    def press(self, f_n: float, seconds: float) -> None:
        rig = self.drv.rig
        for _ in range(round(seconds / rig.dt)):
            self.drv.step(hold_reference(self.loop, self.drv.state()[0]), np.array([0.0, 0.0, -f_n]))

    def start(self) -> np.ndarray:
        return self.loop.dyn.tip_position(self.drv.state()[0])

    def step(self, ref: IdReference, f_n: float, back: np.ndarray) -> float:
        out = self.drv.step(ref, np.array([0.0, 0.0, -f_n]) + self.f_t * back)
        return -float(out.pressed[2])


class AdmittanceDesign:
    """Design 2: :class:`AdmittanceDrag` (admittance over piston velocity control of boom, arm and bucket)."""

    name = "AdmittanceDrag"

    def __init__(self, rig: PlantRig, ctl: AdmittanceDrag) -> None:
        self.rig, self.ctl = rig, ctl
        self.drv = Driver(rig, None)  # type: ignore[arg-type]  # only its state()
        self.anchor: np.ndarray | None = None  # the path's start: its height is the depth offset's zero
        self.track: list[float] = []  # [m] the tip's height above its reference (path - depth offset), per step

    def _step(self, ref: IdReference, f_n: float):
        q, qd, p = self.drv.state()
        out = self.ctl.step(q, qd, p, ref, f_n)
        for n in self.rig.names:
            self.rig.pairs[n] = PilotPair(0.0, 0.0)
        for fn, pair in out.pairs.items():
            self.rig.set_pair(fn, pair)
        self.rig.advance()
        return out

    def press(self, f_n: float, seconds: float) -> None:
        q = self.drv.state()[0]
        ref = hold_reference(self.ctl, q)
        self.anchor = ref.position
        for _ in range(round(seconds / self.rig.dt)):
            self._step(ref, f_n)

    def start(self) -> np.ndarray:
        tip = self.ctl.dyn.tip_position(self.drv.state()[0])
        assert self.anchor is not None
        return np.array([tip[0], tip[1], self.anchor[2]])  # along where the tip is, at the depth offset's zero

    def step(self, ref: IdReference, f_n: float, back: np.ndarray) -> float:
        out = self._step(ref, f_n)
        tip = self.ctl.dyn.tip_position(np.array(self.rig.front.q, dtype=float))
        self.track.append(float(tip[2] - (ref.position[2] - out.depth)))
        return -float(out.pressed[2])


def run_drag(rig: PlantRig, design, f_n: float) -> DragResult:
    """The tip reference moving ``DRAG_M`` towards the machine at ``DRAG_SPEED`` (theta_w held), then 2 s still,
    with the normal force reference ``f_n`` [N] down; scored after the first second."""
    q = np.array(rig.front.q, dtype=float)
    start = design.start()
    kin = load_kinematics()
    theta = float(q[1] + q[2] + q[3]) + kin.c_bucket
    back = -np.array([math.cos(q[0]), math.sin(q[0]), 0.0])  # towards the machine, horizontal
    dug0 = rig.plant.soil.dug
    tip0 = np.array(rig.plant.bucket_tip())
    duration = DRAG_M / DRAG_SPEED
    errs, errs_est, depths, tangs, normals = [], [], [], [], []
    for k in range(round((duration + 2.0) / rig.dt)):
        t = min((k + 1) * rig.dt, duration)
        moving = (k + 1) * rig.dt < duration
        ref = IdReference(position=start + back * DRAG_SPEED * t, velocity=back * DRAG_SPEED if moving else np.zeros(3),
                          theta_w=theta)
        est = design.step(ref, f_n, back)
        if (k + 1) * rig.dt >= 1.0:  # the first second: the valves' dead time after the reference starts
            errs.append(f_n - truth_normal(rig))
            errs_est.append(f_n - est)
            depths.append(rig.tip_depth())
            tangs.append(truth_tangential(rig))
            normals.append(truth_normal(rig))
    tip1 = np.array(rig.plant.bucket_tip())
    return DragResult(math.sqrt(float(np.mean(np.square(errs)))), float(np.mean(errs)),
                      math.sqrt(float(np.mean(np.square(errs_est)))), np.array(depths),
                      float(np.hypot(*(tip1 - tip0)[:2])), rig.plant.soil.dug - dug0, rig.plant.soil.bucket,
                      float(np.mean(tangs)), float(np.max(normals)))


def mound_front(clearance: float = 0.01) -> dict[str, float]:
    """The front over the mound's flat top ahead of the machine (:data:`MOUND_FRONT`'s arm and bucket), the boom
    lowered (bisection on a scratch copy of the plant, teleported) until the edge is ``clearance`` [m] above it."""
    rig = PlantRig()
    name = rig.plant.spec.excavator
    base = rig.plant.truth(name)
    here = dict(zip(rig.names, rig.front.q, strict=True))
    lo, hi = rig.machine.joint("boom_joint").lower, rig.machine.joint("boom_joint").upper  # raised .. lowest

    def gap(boom: float) -> float:
        rig.plant.set_truth(name, base.x, base.y, base.yaw, {**here, **MOUND_FRONT, "boom_joint": boom})
        x, y, z = rig.plant.bucket_tip()
        return z - rig.plant.ground.height(x, y)

    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if gap(mid) > clearance else (lo, mid)
    return {**MOUND_FRONT, "boom_joint": lo}


def new_rig(where: str) -> PlantRig:
    """A fresh plant with the edge pressed on the ground: ``flat`` (bench force_steps' flat ground, pressed by the
    arm as (a)) or ``mound`` (over the mound's flat top, :func:`mound_front`, pressed by the boom)."""
    if where == "flat":
        rig: PlantRig = FlatRig(True)
        press(rig, "arm_joint")
    elif where == "flat-nb":  # the shipped plants' soil: no bearing; the edge lowered until it touches
        rig = FlatRig(False)
        press(rig, "arm_joint", depth=0.0)
    else:  # the arm's press would slide the edge over the mound's top to its slope: the boom presses it down
        rig = FlatRig(True, mound_front())  # the same rig, the front over the mound (soil.penetration on)
        press(rig, "boom_joint")
    return rig


def make_design(which: str, rig: PlantRig, luts, settings, adm_settings, f_t: float):
    dyn = FrontDynamics(rig.machine)
    kin = load_kinematics()
    if which == "ForceLoop":
        return LoopDesign(rig, ForceLoop(dyn, kin, luts, settings, rig.p_max,
                                         settings=ForceLoopSettings(**DRAG_ROLES)), f_t)
    return AdmittanceDesign(rig, AdmittanceDrag(dyn, kin, luts, settings, rig.p_max, adm_settings))


def compare_drags(luts, settings, adm_settings, f_t: float) -> list[Row]:
    """Both designs over the same drags, side by side (flat ground, the mound at two force references); their rows
    of the three designs' table."""
    rows: list[Row] = []
    cases = [("flat", DRAG_FRACTION)] + [("mound", f) for f in MOUND_FRACTIONS]
    print(f"  drags, both designs ({DRAG_M:.1f} m towards the machine at {DRAG_SPEED:.2f} m/s, 4 s of pressing at the "
          "reference first; scored from 1 s after the start; force = the plant's bearing + the cut's vertical):")
    for where, frac in cases:
        rig = new_rig(where)
        dyn = FrontDynamics(rig.machine)
        fmax = largest_press(dyn, np.array(rig.front.q, dtype=float), PRESS_MARGIN)
        f_n = frac * fmax
        print(f"  {where}: edge {100 * rig.tip_depth():.1f} cm deep, bearing {rig.plant.press_force / 1e3:.1f} kN; "
              f"largest press the model allows {fmax / 1e3:.1f} kN; reference {f_n / 1e3:.1f} kN down")
        res = {}
        for which in ("ForceLoop", "AdmittanceDrag"):
            rig = new_rig(where)
            design = make_design(which, rig, luts, settings, adm_settings, f_t)
            t0 = time.monotonic()
            design.press(f_n, 4.0)
            res[which] = run_drag(rig, design, f_n)
            r = res[which]
            rows.append(Row(where, which, f"{f_n / 1e3:.1f} kN normal", r.rms, r.tangential, float(r.depth.mean()),
                            r.cut, f_n - r.mean, r.normal_max, r.along))
            print(f"    {which:14s}: {res[which].line()} ({time.monotonic() - t0:.1f} s wall)")
            if isinstance(design, AdmittanceDesign):
                tr = 100 * np.array(design.track)
                print(f"    {'':14s}  the tip's height above its reference (path - depth offset): RMS "
                      f"{math.sqrt(float(np.mean(tr ** 2))):.1f} cm (min {tr.min():.1f}, max {tr.max():.1f})")
        a, b = res["AdmittanceDrag"], res["ForceLoop"]

        def ratio(x: float, y: float) -> str:
            return f"{x / y:.2f}" if abs(y) > 1e-9 else "n/a"

        print(f"    ratio AdmittanceDrag / ForceLoop: RMS error {ratio(a.rms, b.rms)}, mean depth "
              f"{ratio(float(a.depth.mean()), float(b.depth.mean()))}, dragged {ratio(a.along, b.along)}, cut "
              f"{ratio(a.cut, b.cut)}")
    return rows


@dataclass
class Row:
    """One line of the three designs' table: each design's regulated force's RMS error (truth), the cutting
    resistance along the cut it met (truth, mean), the edge's mean depth, the volume cut, the normal force."""

    case: str
    design: str
    reference: str
    rms: float  # [N] RMS error of the design's own regulated force (normal for the first two, tangential for the third)
    tangential: float  # [N] mean cutting resistance along the cut (truth)
    depth: float  # [m] mean depth of the edge
    cut: float  # [m^3]
    normal: float  # [N] mean normal force (truth)
    normal_max: float  # [N]
    along: float  # [m] dragged


#: the cut depths whose resistance on the plant (measured, :func:`cut_curve`) are the tangential references
CUT_DEPTHS = (0.05, 0.10, 0.15)
#: flat ground and the mound with the bearing (``soil.penetration``), and flat ground without it (the shipped plants)
CUT_CASES = ("flat", "mound", "flat-nb")
CUT_SETTINGS_ENV = "FORCE_DIG_CUT"  # "key=value,...": overrides of force_control.yaml's cut_force keys


def cut_curve(rig: PlantRig) -> tuple[np.ndarray, np.ndarray]:
    """(depths [m], the plant's cutting resistance along the cut [N]) of the edge where it stands (its rake, the
    bucket empty), the edge put at each depth below the ground under it: the plant's own wedge law
    (``Plant._cutting_force``) evaluated in place, the plant's state restored (a bench measurement of the plant, never
    a controller input)."""
    p = rig.plant
    tip = np.array(p._tip, dtype=float)
    memo, direction = p._wedge_memo, p._cut_direction
    surface = p.ground.height(tip[0], tip[1])
    depths = np.arange(0.0, 0.255, 0.01)
    forces = []
    for d in depths:
        p._tip = np.array([tip[0], tip[1], surface - d])
        cf = p._cutting_force()
        forces.append(float(np.hypot(*cf[0][:2])) if cf is not None else 0.0)
    p._tip, p._wedge_memo, p._cut_direction = tip, memo, direction
    return depths, np.array(forces)


def slope_kn_per_cm(depths: np.ndarray, forces: np.ndarray, lo: float = 0.03, hi: float = 0.2) -> tuple[float, float]:
    """(slope [kN per cm], intercept [kN]) of the least-squares line through the curve between ``lo`` and ``hi``."""
    sel = (depths >= lo - 1e-9) & (depths <= hi + 1e-9)
    k, c = np.polyfit(100 * depths[sel], forces[sel] / 1e3, 1)
    return float(k), float(c)


class PathSurface:
    """The ground along the drag's line as sensed before the drag (the heights under the line at the start): the
    path reference runs on it, the cut depth is scored against it (the edge's own cut lowers the ground after)."""

    def __init__(self, rig: PlantRig, start: np.ndarray, back: np.ndarray) -> None:
        self.start, self.back = start, back
        self.s = np.arange(-0.5, DRAG_M + 1.0, 0.05)
        self.z = np.array([rig.plant.ground.height(*(start + back * si)[:2]) for si in self.s])

    def height(self, s: float) -> float:
        return float(np.interp(s, self.s, self.z))

    def along(self, p: np.ndarray) -> float:
        return float((p - self.start)[:2] @ self.back[:2])

    def depth(self, tip: np.ndarray) -> float:
        """[m] the point below the sensed surface at its place along the line."""
        return self.height(self.along(tip)) - float(tip[2])


@dataclass
class CutResult:
    rms: float  # [N] RMS of F_ref - F_t (truth), moving steps after the first second
    rms_late: float  # [N] the same over the drag's second half
    tangential: float  # [N] mean F_t (truth)
    rms_est: float  # [N] RMS of the filtered estimate - truth
    depth: np.ndarray  # [m] the edge below the sensed surface (scored steps)
    depth_rms: float  # [m] RMS of depth - the depth F_ref implies (the plant's curve, empty bucket)
    cut: float  # [m^3]
    bucket: float  # [m^3]
    normal: float  # [N] mean normal force (truth: bearing + the wedge's vertical)
    normal_max: float
    along: float  # [m]
    trace: list[str]


def run_cut_drag(rig: PlantRig, ctl: CutForceDrag, f_ref: float, d_implied: float) -> CutResult:
    """The cut-force drag: the path on the sensed surface ``DRAG_M`` towards the machine at ``DRAG_SPEED`` (theta_w
    held), then 2 s still, the tangential reference ``f_ref`` [N]; scored while the path moves, after its first
    second."""
    drv = Driver(rig, None)  # type: ignore[arg-type]  # only its state()
    q = np.array(rig.front.q, dtype=float)
    tip0 = ctl.dyn.tip_position(q)
    theta = float(q[1] + q[2] + q[3]) + ctl.kin.c_bucket
    back = -np.array([math.cos(q[0]), math.sin(q[0]), 0.0])
    start = np.array([tip0[0], tip0[1], 0.0])
    # the path in base_link; the ground sensed in the map frame under it (the base at the origin, yaw 0 on this rig)
    base = rig.plant.truth(rig.plant.spec.excavator)
    assert abs(base.x) < 1e-9 and abs(base.y) < 1e-9 and abs(base.yaw) < 1e-9, "the bench's base is at the origin"
    surf = PathSurface(rig, start, back)
    ctl.reset(depth=surf.depth(tip0))
    dug0, ptip0 = rig.plant.soil.dug, np.array(rig.plant.bucket_tip())
    duration = DRAG_M / DRAG_SPEED
    n_steps = round((duration + 2.0) / rig.dt)
    rows = []  # (t, f_t truth, f_t est, depth, depth ref, normal truth, normal est)
    trace = []
    for k in range(n_steps):
        t_next = (k + 1) * rig.dt
        t = min(t_next, duration)
        moving = t_next < duration
        s_here = DRAG_SPEED * t
        slope_z = (surf.height(s_here + 0.05) - surf.height(s_here - 0.05)) / 0.1
        pos = start + back * s_here
        pos[2] = surf.height(s_here)
        vel = (back + np.array([0.0, 0.0, slope_z])) * DRAG_SPEED if moving else np.zeros(3)
        ref = IdReference(position=pos, velocity=vel, theta_w=theta)
        qn, qd, p = drv.state()
        out = ctl.step(qn, qd, p, ref, f_ref)
        for nm in rig.names:
            rig.pairs[nm] = PilotPair(0.0, 0.0)
        for fn, pair in out.pairs.items():
            rig.set_pair(fn, pair)
        rig.advance()
        tip = np.array(rig.plant.bucket_tip())
        depth = surf.depth(tip)
        if moving and t_next >= 1.0:
            rows.append((t_next, truth_tangential(rig), out.f_t, depth, out.depth, truth_normal(rig), out.f_n))
        if k % round(2.0 / rig.dt) == round(2.0 / rig.dt) - 1:
            trace.append(f"t {t_next:4.1f} s: depth ref {100 * out.depth:5.1f} cm, edge {100 * depth:5.1f} cm; F_t "
                         f"{truth_tangential(rig) / 1e3:5.1f} kN (estimate {out.f_t / 1e3:5.1f}); F_n "
                         f"{truth_normal(rig) / 1e3:5.1f} kN (estimate {out.f_n / 1e3:5.1f}, bearing capacity "
                         f"{rig.plant.press_capacity / 1e3:5.1f}); bucket "
                         f"{rig.plant.soil.bucket:.3f} m^3")
    a = np.array(rows)
    late = a[:, 0] >= 0.5 * duration
    ptip1 = np.array(rig.plant.bucket_tip())
    return CutResult(
        rms=math.sqrt(float(np.mean((f_ref - a[:, 1]) ** 2))),
        rms_late=math.sqrt(float(np.mean((f_ref - a[late, 1]) ** 2))),
        tangential=float(a[:, 1].mean()),
        rms_est=math.sqrt(float(np.mean((a[:, 2] - a[:, 1]) ** 2))),
        depth=a[:, 3], depth_rms=math.sqrt(float(np.mean((a[:, 3] - d_implied) ** 2))),
        cut=rig.plant.soil.dug - dug0, bucket=rig.plant.soil.bucket,
        normal=float(a[:, 5].mean()), normal_max=float(a[:, 5].max()),
        along=float(np.hypot(*(ptip1 - ptip0)[:2])), trace=trace)


def cut_drags(luts, settings, cut_settings: CutForceSettings, trace: bool) -> list[Row]:
    """The cut-force drag on flat ground and the mound at the tangential references of :data:`CUT_DEPTHS`."""
    rows: list[Row] = []
    print(f"  CutForceDrag drags ({DRAG_M:.1f} m towards the machine at {DRAG_SPEED:.2f} m/s on the surface "
          f"sensed before, no pressing first; scored while the path moves, from 1 s after the start; F_t = the plant's "
          f"cutting resistance along the cut, truth): {cut_settings}")
    for where in CUT_CASES:
        rig = new_rig(where)
        depths, forces = cut_curve(rig)
        k, c = slope_kn_per_cm(depths, forces)
        dyn = FrontDynamics(rig.machine)
        fmax = largest_press(dyn, np.array(rig.front.q, dtype=float), 1.0)
        if rig.plant._press_on:  # the bearing capacity under the edge at 1 cm: what a descending edge must exceed
            cap = rig.plant._press_q0 + rig.plant._press_dq * 0.01
            print(f"  {where}: the largest press the controller's model allows at the start pose (every cylinder at "
                  f"its relief) {fmax / 1e3:.1f} kN; the plant's bearing capacity under the edge 1 cm deep "
                  f"{cap / 1e3:.1f} kN (a descending edge, even while it moves along, meets it)")
        table = ", ".join(f"{100 * d:.0f} cm {f / 1e3:.1f}" for d, f in zip(depths, forces, strict=True)
                          if round(100 * d) % 5 == 0)
        print(f"  {where}: the plant's cutting resistance along the cut at the start pose (tip angle "
              f"{math.degrees(rig.zx.tip_angle()):.0f} deg, the wedge's rake clamped to 30-80 deg; bucket empty): "
              f"{table} kN; slope over 3-20 cm "
              f"{k:.2f} kN per cm (intercept {c:+.1f} kN)")
        for d_cut in CUT_DEPTHS:
            f_ref = float(np.interp(d_cut, depths, forces))
            rig = new_rig(where)
            dyn = FrontDynamics(rig.machine)
            ctl = CutForceDrag(dyn, load_kinematics(), luts, settings, rig.p_max, cut_settings)
            t0 = time.monotonic()
            r = run_cut_drag(rig, ctl, f_ref, d_cut)
            d = 100 * r.depth
            print(f"    F_t ref {f_ref / 1e3:5.1f} kN ({100 * d_cut:.0f} cm): RMS error {r.rms / 1e3:5.2f} kN (second "
                  f"half {r.rms_late / 1e3:5.2f}; estimate vs truth {r.rms_est / 1e3:5.2f}), F_t mean "
                  f"{r.tangential / 1e3:5.1f} kN; depth mean {d.mean():5.1f} cm (min {d.min():5.1f}, max "
                  f"{d.max():5.1f}), RMS vs {100 * d_cut:.0f} cm {100 * r.depth_rms:4.1f} cm; cut {r.cut:.3f} m^3 "
                  f"(bucket {r.bucket:.3f}); normal mean {r.normal / 1e3:5.1f} kN, max {r.normal_max / 1e3:5.1f} kN; "
                  f"dragged {r.along:.2f} m ({time.monotonic() - t0:.1f} s wall)")
            if trace:
                for line in r.trace:
                    print(f"        {line}")
            rows.append(Row(where, "CutForceDrag", f"{f_ref / 1e3:.1f} kN tangential",
                            r.rms, r.tangential, float(r.depth.mean()), r.cut, r.normal, r.normal_max, r.along))
    return rows


def print_table(rows: list[Row]) -> None:
    print("  all three designs (the plant's truth; RMS err = of each design's own regulated force: normal (bearing + "
          "the wedge's vertical) for ForceLoop and AdmittanceDrag, along the cut for CutForceDrag; F_t = the cutting "
          "resistance along the cut; depth = the edge below the ground under it (ForceLoop, AdmittanceDrag) or below "
          "the surface sensed before the drag (CutForceDrag); flat-nb = flat ground without the bearing):")
    print(f"    {'case':7s} {'design':14s} {'reference':20s} {'RMS err':>8s} {'F_t mean':>8s} {'depth':>7s} "
          f"{'cut m^3':>8s} {'F_n mean':>8s} {'F_n max':>8s} {'dragged':>7s}")
    for r in rows:
        print(f"    {r.case:7s} {r.design:14s} {r.reference:20s} {r.rms / 1e3:6.2f}kN {r.tangential / 1e3:6.1f}kN "
              f"{100 * r.depth:5.1f}cm {r.cut:8.3f} {r.normal / 1e3:6.1f}kN {r.normal_max / 1e3:6.1f}kN "
              f"{r.along:6.2f}m")


def main() -> None:
    settings = load_piston_settings()
    adm_settings = load_force_control_settings().admittance
    override = {k: float(v) for k, v in (kv.split("=") for kv in os.environ.get("FORCE_DIG_ADMITTANCE", "").split(",")
                                         if kv)}
    if override:
        adm_settings = dataclasses.replace(adm_settings, **override)
        print(f"  AdmittanceDrag settings overridden by FORCE_DIG_ADMITTANCE: {override}")
    wall0 = time.monotonic()
    rig = PlantRig()
    luts, source = controller_luts(rig, CYLINDER_FUNCTIONS, settings)
    print(f"force-controlled pressing and digging in-process (MuJoCo plant core, config/sim/paper_plant.yaml, "
          f"soil.penetration on, {settings.rate_hz:.0f} Hz; tables of {', '.join(luts)} {source})")
    kin = load_kinematics()
    f_t = float(os.environ.get("FORCE_DIG_DRAG_FT", "0"))
    only_cut = os.environ.get("FORCE_DIG_ONLY", "") == "cut"  # the cut-force drags alone (a sweep)
    parts = () if only_cut else (("a", "steps", ForceLoopSettings()), ("b'", "drag", ForceLoopSettings()))
    for tag, part, loop_settings in parts:
        rig = new_rig("flat")
        dyn = FrontDynamics(rig.machine)
        loop = ForceLoop(dyn, kin, luts, settings, rig.p_max, settings=loop_settings)
        q = np.array(rig.front.q, dtype=float)
        fmax = largest_press(dyn, q, PRESS_MARGIN)
        roles = (f"force control {', '.join(loop_settings.functions)}; velocity control "
                 f"{', '.join(loop_settings.velocity_functions) or 'none'}")
        print(f"  ({tag}) ForceLoop, {roles}. Edge {100 * rig.tip_depth():.1f} cm into flat ground after the arm's "
              f"press, bearing {rig.plant.press_force / 1e3:.1f} kN; largest press the model allows here "
              f"{fmax / 1e3:.1f} kN")
        t0 = time.monotonic()
        if part == "steps":
            run_steps(Driver(rig, loop), fmax)
        else:
            design = LoopDesign(rig, loop, f_t)
            design.press(DRAG_FRACTION * fmax, 4.0)
            print(f"    drag at {DRAG_FRACTION * fmax / 1e3:.1f} kN: "
                  f"{run_drag(rig, design, DRAG_FRACTION * fmax).line()}")
        print(f"    ({time.monotonic() - t0:.1f} s wall)")
    rows = [] if only_cut else compare_drags(luts, settings, adm_settings, f_t)
    cut_settings = load_cut_force_settings()
    cut_override = {k: float(v) for k, v in (kv.split("=") for kv in os.environ.get(CUT_SETTINGS_ENV, "").split(",")
                                             if kv)}
    if cut_override:
        cut_settings = dataclasses.replace(cut_settings, **cut_override)
        print(f"  CutForceDrag settings overridden by {CUT_SETTINGS_ENV}: {cut_override}")
    rows += cut_drags(luts, settings, cut_settings, os.environ.get("FORCE_DIG_TRACE", "1") == "1")
    print_table(rows)
    print(f"  {time.monotonic() - wall0:.1f} s wall")


if __name__ == "__main__":
    main()
