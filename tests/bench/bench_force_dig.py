"""Force-controlled pressing and digging through the ID hierarchy + piston force control
(:class:`tms_rc.excavator.force_control.ForceLoop`) against the plant core in-process, ``soil.penetration: true``.

``python -m tests.bench force_dig``: identifies the boom's, arm's and bucket's look-up tables on
``config/sim/paper_plant.yaml`` as ``python -m tests.bench piston`` does (their cracks feed the dead-zone
compensation), starts the ZX200 over flat ground (:data:`tests.bench.bench_force_steps.FLAT_FRONT`), presses the
edge down with the arm (as ``force_steps`` does) and hands the front to the loop at 100 Hz (the swing's pilot 0):

(a) arm and bucket under force control, the boom held: steps of the commanded normal force (the force the bucket
    exerts on the ground, straight down), fractions of the largest press the controller's own model allows at the
    start pose (every cylinder's static force within ``PRESS_MARGIN`` of its relief force, the machine description's
    bores and relief): per step the time to 10 %, rise 10-90 % and steady-state error (mean of F_ref - F over the
    last 2 s of 8 s) of the *plant's* bearing force on the edge (``Plant.press_force``, the truth), and the steady
    error of the loop's own estimate from the pressures;
(b) a drag towards the machine along the ground (the tip reference moving ``DRAG_M`` at ``DRAG_SPEED``, theta_w
    held) with a constant normal force reference, with the drag's roles
    (:data:`tms_rc.excavator.force_control.DRAG_ROLES`: bucket under force control, boom and arm under velocity
    control) and (b') with the pressing roles of (a) (arm and bucket under force control, the boom held): RMS of
    F_ref - F (truth: the bearing + the cut's vertical force; and the estimate), the tip's depth along the cut (mean,
    min, max), the distance dragged and the soil cut.

``FORCE_DIG_DRAG_FT`` [N]: a feed-forward pull along the cut (default 0: the tip PD alone drags).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from tests.bench.bench_force_steps import FlatRig, press
from tests.bench.bench_piston import PlantRig, identify
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.force_control import DRAG_ROLES, ForceLoop, ForceLoopSettings
from tms_rc.excavator.id_hqp import IdReference
from tms_rc.excavator.piston import CYLINDER_FUNCTIONS, PilotPair, load_piston_settings

PRESS_MARGIN = 0.9  # every cylinder's static force within this fraction of its relief force
STEP_FRACTIONS = [0.3, 0.6, 0.45, 0.8, 0.3]  # of the largest press
DRAG_FRACTION = 0.45
HOLD_S, WINDOW_S = 8.0, 2.0
DRAG_M, DRAG_SPEED = 2.0, 0.15  # [m], [m/s]


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

    def __init__(self, rig: PlantRig, loop: ForceLoop) -> None:
        self.rig, self.loop = rig, loop

    def state(self) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[float, float]]]:
        fr = self.rig.front
        pressures = {fn: (fr.p_ext[fr.names.index(fn)] / 1e6, fr.p_ret[fr.names.index(fn)] / 1e6)
                     for fn in CYLINDER_FUNCTIONS}
        return np.array(fr.q, dtype=float), np.array(fr.v, dtype=float), pressures

    def step(self, ref: IdReference, force_d: np.ndarray):
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


def hold_reference(loop: ForceLoop, q: np.ndarray) -> IdReference:
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


def run_drag(drv: Driver, f_n: float, f_t: float) -> None:
    rig, loop = drv.rig, drv.loop
    q, _, _ = drv.state()
    start = loop.dyn.tip_position(q)
    theta = float(q[1] + q[2] + q[3]) + loop.kin.c_bucket
    back = -np.array([math.cos(q[0]), math.sin(q[0]), 0.0])  # towards the machine, horizontal
    dug0 = rig.plant.soil.dug
    tip0 = np.array(rig.plant.bucket_tip())
    duration = DRAG_M / DRAG_SPEED
    force = np.array([0.0, 0.0, -f_n]) + f_t * back
    errs, errs_est, depths = [], [], []
    for k in range(round((duration + 2.0) / rig.dt)):
        t = min((k + 1) * rig.dt, duration)
        moving = (k + 1) * rig.dt < duration
        ref = IdReference(position=start + back * DRAG_SPEED * t, velocity=back * DRAG_SPEED if moving else np.zeros(3),
                          theta_w=theta)
        out = drv.step(ref, force)
        if (k + 1) * rig.dt >= 1.0:  # the first second: the valves' dead time after the reference starts
            errs.append(f_n - truth_normal(rig))
            errs_est.append(f_n + float(out.pressed[2]))
            depths.append(rig.tip_depth())
    tip1 = np.array(rig.plant.bucket_tip())
    along = float(np.hypot(*(tip1 - tip0)[:2]))
    rms = math.sqrt(float(np.mean(np.square(errs))))
    rms_est = math.sqrt(float(np.mean(np.square(errs_est))))
    d = 100 * np.array(depths)
    print(f"    reference {f_n / 1e3:.1f} kN down{f', {f_t / 1e3:.1f} kN pull' if f_t else ''}, tip path "
          f"{DRAG_M:.1f} m at {DRAG_SPEED:.2f} m/s: RMS force error {rms / 1e3:.2f} kN (truth: bearing + cut's "
          f"vertical; the estimate's {rms_est / 1e3:.2f} kN), mean error {np.mean(errs) / 1e3:+.2f} kN")
    print(f"    edge depth along the cut mean {d.mean():.1f} cm (min {d.min():.1f}, max {d.max():.1f}); dragged "
          f"{along:.2f} m of {DRAG_M:.1f}; soil cut {rig.plant.soil.dug - dug0:.3f} m^3 (bucket holds "
          f"{rig.plant.soil.bucket:.3f} m^3)")


def main() -> None:
    settings = load_piston_settings()
    wall0 = time.monotonic()
    rig = PlantRig()
    luts = {fn: identify(rig, fn, settings)[0] for fn in CYLINDER_FUNCTIONS}
    print(f"force-controlled pressing and digging in-process (MuJoCo plant core, config/sim/paper_plant.yaml, "
          f"soil.penetration on, {settings.rate_hz:.0f} Hz; tables of {', '.join(luts)} identified in "
          f"{time.monotonic() - wall0:.0f} s wall)")
    kin = load_kinematics()
    f_t = float(os.environ.get("FORCE_DIG_DRAG_FT", "0"))
    cases = [("a", "steps", ForceLoopSettings()), ("b", "drag", ForceLoopSettings(**DRAG_ROLES)),
             ("b'", "drag", ForceLoopSettings())]
    for tag, part, loop_settings in cases:
        rig = FlatRig(True)
        press(rig, "arm_joint")
        dyn = FrontDynamics(rig.machine)
        loop = ForceLoop(dyn, kin, luts, settings, rig.p_max, settings=loop_settings)
        drv = Driver(rig, loop)
        q, _, _ = drv.state()
        fmax = largest_press(dyn, q, PRESS_MARGIN)
        roles = (f"force control {', '.join(loop_settings.functions)}; velocity control "
                 f"{', '.join(loop_settings.velocity_functions) or 'none'}")
        print(f"  ({tag}) {roles}. Edge {100 * rig.tip_depth():.1f} cm into flat ground after the arm's press, bearing "
              f"{rig.plant.press_force / 1e3:.1f} kN; largest press the model allows here {fmax / 1e3:.1f} kN")
        t0 = time.monotonic()
        if part == "steps":
            run_steps(drv, fmax)
        else:
            for _ in range(round(4.0 / rig.dt)):  # press to the drag's force first
                drv.step(hold_reference(loop, drv.state()[0]), np.array([0.0, 0.0, -DRAG_FRACTION * fmax]))
            run_drag(drv, DRAG_FRACTION * fmax, f_t)
        print(f"    ({time.monotonic() - t0:.1f} s wall)")


if __name__ == "__main__":
    main()
