"""Inverse-dynamics HQP (tms_rc.excavator.id_hqp) along a 10 s dig-like tip trajectory at 100 Hz (1000 steps).

The ZX200's front follows approach -> penetrate -> drag -> curl-and-lift (minimum-jerk segments between
waypoints of tip position and theta_w, 10 s in all); the ID solves every step and its accelerations are
integrated on the rigid-body model itself (semi-implicit Euler), so the loop is closed. During penetrate and drag
a soil force of up to 60 kN resists the tip's motion (``F_ext``), enough for the cylinder force limits to bind.
Prints the solve time per step (wall and thread CPU: median, p99, max), how often each limit level bound, the
RMS tip tracking error and the largest EoM residual. For comparison, the IK controller (``ArmController`` and
its joint-velocity HQP, as in ``bench_zx200``) runs the same waypoints as Cartesian via targets against the
lag + dead-time plant for 1000 steps and its QP solve time is printed the same way; and HEAP's cylinder-space IK
hierarchy (``CylinderIkHQP``) follows a cubic Hermite reference through the same waypoints (tip x, z, theta_w;
Catmull-Rom knot velocities) for 1000 steps, loop closed kinematically on its joint velocities (q += dt qd).

Run: ``.venv/bin/python -m tests.bench id_hqp``.
"""

from __future__ import annotations

import gc
import math
import time

import numpy as np

from tests.bench.stats import summary_ms
from tms_model.excavator.kinematics import load_kinematics
from tms_model.excavator.targets import CartesianTarget
from tms_rc.excavator.controller import ArmController, load_controller_config
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.hermite import HermiteReference
from tms_rc.excavator.id_hqp import IdReference, IdSettings, InverseDynamicsHQP
from tms_rc.excavator.ik_cylinder import CylinderIkHQP, IkReference, IkSettings
from tms_rc.excavator.plant import LagDeadTimePlant

STEPS = 1000
RATE_HZ = 100.0
#: (duration [s], tip x, z [m] in base_link, theta_w [rad], soil force magnitude [N] during the segment)
WAYPOINTS = (
    (0.0, 7.5, 0.8, 1.0, 0.0),  # above the cut
    (2.0, 7.2, -0.4, 1.1, 0.0),  # approach
    (2.0, 6.6, -0.9, 1.3, 60e3),  # penetrate
    (3.0, 4.8, -0.9, 1.7, 60e3),  # drag towards the machine
    (3.0, 4.6, 0.6, 2.4, 0.0),  # curl and lift
)
LEVELS = ("pump_flow", "force_limits", "velocity_limits", "stroke_limits", "collision")


def _min_jerk(s: float) -> tuple[float, float, float]:
    """Position, velocity, acceleration of 10 s^3 - 15 s^4 + 6 s^5 at s in [0, 1] (per unit s)."""
    return (10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3)


def reference(t: float, y: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float, float], float]:
    """Tip position, velocity, acceleration, (theta_w, rate, accel) and soil force magnitude at time ``t``."""
    t0 = 0.0
    for prev, (dur, x, z, th, force) in zip(WAYPOINTS, WAYPOINTS[1:], strict=False):
        if t <= t0 + dur or (dur, x, z, th, force) == WAYPOINTS[-1]:
            s = min(max((t - t0) / dur, 0.0), 1.0)
            p, v, a = _min_jerk(s)
            d = np.array([x - prev[1], 0.0, z - prev[2]])
            dth = th - prev[3]
            pos = np.array([prev[1], y, prev[2]]) + p * d
            return pos, v / dur * d, a / dur**2 * d, (prev[3] + p * dth, v / dur * dth, a / dur**2 * dth), force
        t0 += dur
    raise AssertionError("unreachable")


def id_run() -> None:
    kin = load_kinematics("zx200")
    dyn = FrontDynamics(kin.machine)
    ctl = InverseDynamicsHQP(dyn, kin, IdSettings(rate_hz=RATE_HZ))
    dt = ctl.dt
    y = float(kin.tip_position(kin.home)[1])
    pos, _, _, (th, _, _), _ = reference(0.0, y)
    q = kin.ik_position_with_angle(pos, th)
    qd = np.zeros(4)
    wall, cpu, errs, eom = [], [], [], 0.0
    bound = dict.fromkeys(LEVELS, 0)
    osqp_steps = 0
    gc.collect()
    gc.disable()  # a full collection inside a timed solve is the interpreter's, not the solver's, cost
    try:
        for k in range(STEPS):
            t = k * dt
            pos, vel, acc, (th, om, al), force = reference(t, y)
            ref = IdReference(position=pos, velocity=vel, acceleration=acc, theta_w=th, theta_w_rate=om,
                              theta_w_accel=al)
            # the soil resists the tip's motion (force on the bucket against its velocity)
            v_tip = dyn.tip_jacobian(q) @ qd
            speed = float(np.linalg.norm(v_tip))
            f_ext = -force * v_tip / speed if speed > 1e-3 and force > 0 else np.zeros(3)
            start, cpu_start = time.perf_counter(), time.thread_time()
            res = ctl.solve(q, qd, ref, f_ext)
            wall.append(time.perf_counter() - start)
            cpu.append(time.thread_time() - cpu_start)
            osqp_steps += any(res.hqp.solved.get(n, False) and n not in res.hqp.closed_form for n in res.hqp.solved)
            for name in LEVELS:
                # a limit level binds when it got a QP of its own or its rows hold with no room at x = 0
                if res.hqp.solved.get(name, False):
                    bound[name] += 1
            eom = max(eom, float(np.abs(res.eom_residual).max()))
            errs.append(float(np.linalg.norm(dyn.tip_position(q) - pos)))
            qd = qd + dt * res.qdd
            q = q + dt * qd
    finally:
        gc.enable()
    print(f"id_hqp bench: ZX200 front, {STEPS} steps at {RATE_HZ:.0f} Hz along a 10 s dig (soil force up to "
          f"{max(w[4] for w in WAYPOINTS) / 1e3:.0f} kN), rigid-body loop closed on the ID's accelerations")
    print("  ID HQP solve per step, incl. the model terms (wall): " + summary_ms(wall))
    print("  ID HQP solve per step, incl. the model terms (thread CPU): " + summary_ms(cpu))
    print(f"  steps with an OSQP level {osqp_steps}/{STEPS}; steps where a limit level was violated at the levels "
          "above's solution (so solved): "
          + ", ".join(f"{n} {c}" for n, c in bound.items()))
    print(f"  tip tracking RMS {1000 * math.sqrt(np.mean(np.square(errs))):.2f} mm, max {1000 * max(errs):.2f} mm; "
          f"max |EoM residual| {eom:.2e} N m")


def ik_run() -> None:
    kin = load_kinematics("zx200")
    cfg = load_controller_config(kin.machine)
    ctl = ArmController(kin, cfg)
    y = float(kin.tip_position(kin.home)[1])
    pos, _, _, (th, _, _), _ = reference(0.0, y)
    q0 = kin.ik_position_with_angle(pos, th)
    targets = [CartesianTarget(np.array([x, y, z]), th, label=f"wp{i}", via=i < len(WAYPOINTS) - 1)
               for i, (_, x, z, th, _) in enumerate(WAYPOINTS[1:], start=1)]
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    q, v = q0.copy(), np.zeros(4)
    ctl.start(targets)
    wall, cpu = [], []
    gc.collect()
    gc.disable()
    try:
        for _ in range(STEPS):
            u = ctl.step(q, v)
            wall.append(ctl.last_result.solve_time_s)
            cpu.append(ctl.last_result.solve_cpu_s)
            q, v = plant.step(u)
            if ctl.status.result is not None:
                break
    finally:
        gc.enable()
    print(f"  IK HQP (ArmController, joint velocities) on the same waypoints, lag + dead-time plant, {len(wall)} "
          f"steps (wall): " + summary_ms(wall))
    print("  IK HQP (thread CPU): " + summary_ms(cpu))


def cylinder_ik_run() -> None:
    kin = load_kinematics("zx200")
    ctl = CylinderIkHQP(kin, IkSettings(rate_hz=RATE_HZ))
    dt = ctl.dt
    y = float(kin.tip_position(kin.home)[1])
    times = np.cumsum([w[0] for w in WAYPOINTS])
    ref = HermiteReference.through(times, [(x, z, th) for _, x, z, th, _ in WAYPOINTS])
    p0 = ref.sample(0.0)[0]
    q = kin.ik_position_with_angle(np.array([p0[0], y, p0[1]]), float(p0[2]))
    qd = np.zeros(4)
    wall, cpu, errs = [], [], []
    levels = ("pump_flow", "velocity_limits", "stroke_limits", "collision")
    bound = dict.fromkeys(levels, 0)
    gave_way = 0
    gc.collect()
    gc.disable()
    try:
        for k in range(STEPS):
            pos, vel = ref.sample(k * dt)
            target = np.array([pos[0], y, pos[1]])
            ik_ref = IkReference(position=target, velocity=np.array([vel[0], 0.0, vel[1]]), theta_w=float(pos[2]),
                                 theta_w_rate=float(vel[2]))
            start, cpu_start = time.perf_counter(), time.thread_time()
            res = ctl.solve(q, ik_ref, qd=qd)
            wall.append(time.perf_counter() - start)
            cpu.append(time.thread_time() - cpu_start)
            for name in levels:
                if res.hqp.solved.get(name, False):
                    bound[name] += 1
            gave_way += res.gave_way
            errs.append(float(np.linalg.norm(kin.tip_position(q) - target)))
            qd = res.qd
            q = q + dt * qd
    finally:
        gc.enable()
    print(f"  cylinder-space IK HQP (CylinderIkHQP, HEAP's 7 IK tasks), Hermite reference, kinematic loop, {STEPS} "
          "steps, per step incl. the kinematics and J_p (wall): " + summary_ms(wall))
    print("  cylinder-space IK HQP (thread CPU): " + summary_ms(cpu))
    print(f"  cylinder-space IK: tip RMS {1000 * math.sqrt(np.mean(np.square(errs))):.2f} mm, max "
          f"{1000 * max(errs):.2f} mm; position task gave way on {gave_way} steps; limit level solved on: "
          + ", ".join(f"{n} {c}" for n, c in bound.items()))


def main() -> None:
    id_run()
    ik_run()
    cylinder_ik_run()


if __name__ == "__main__":
    main()
