"""HEAP's cylinder-space IK hierarchy on the plant core in-process, through piston velocity control
(:class:`tms_rc.excavator.ik_drive.IkDrive`), against the same IK on a kinematic loop.

``python -m tests.bench ik_plant``: the dig waypoints of ``bench_id_hqp`` (approach, penetrate, drag towards the
machine, curl and lift: tip x, z and theta_w, 10 s; the Hermite reference through them with Catmull-Rom knot
velocities, held at its end for 2 s more, 1200 steps at 100 Hz) run on :class:`~tests.bench.bench_piston.PlantRig`
(``config/sim/paper_plant.yaml``, soil penetration off as shipped) with the front swung to the flat ground beside
the machine (:data:`~tests.bench.bench_force_steps.FLAT_FRONT`'s swing; the mound ahead is avoided: its cutting
resistance is the force benches' subject, not the IK's). The waypoints are rotated into that plane and lifted,
keeping their shape:

- ``air``: the lowest waypoints (penetrate, drag) :data:`AIR_CLEARANCE` above the ground under the path;
- ``ground``: the drag :data:`GROUND_CLEARANCE` above the ground under the path (the ground at the path's lowest
  points read from the plant: the bench's set-up, not a controller input), i.e. skimming the ground; with the
  tracking error below that clearance the edge does not touch it (the run reports the closest it came and any
  contact). The bench_id_hqp depths (0.9 m below the tracks' plane) would be a dig into the soil: 60 kN of cutting
  resistance, the ID's case, not the IK's.

The controller reads the identified tables (``config/tms_rc/identified/zx200_piston_lut.yaml``, identified over
CAN; ``PISTON_LUTS=in_process``: identified on this plant first, as bench piston does) and the machine description;
the swing has no table (the identification covers boom, arm and bucket): its spool stays centred and the reference
lies in its plane. The start pose is the IK of the reference's first point, put into the plant.

Three loops per case, side by side in the same run: ``smith``, the default drive (the joint-space Smith predictor
over the identified dead time + lag of ``config/tms_rc/identified/zx200.yaml``, table feed-forward without the
piston PI, IK gains as the kinematic loop's; started one horizon before the reference's t = 0, as a planned motion
would be), ``plain`` (no predictor, IK Kp 0.8/s, piston PI on) and ``kinematic`` (the same ``CylinderIkHQP`` with
the default drive's IK settings, ``q += dt qd`` on its own joint velocities, as bench_id_hqp). Printed: tip RMS and
max error against the reference at the time (t >= 0), theta_w RMS error, the ratio plant / kinematic, per-step time
of the drive's step (sample + IK + piston controllers; wall and thread CPU: median, p99, max) and of the kinematic
loop's solve, per limit level the steps on which it needed a QP of its own (violated at the levels above's
solution, bench_id_hqp's count) and on which a row of it was at its bound at the final solution (it held a lower
task), the steps on which the position task gave way, pilots at the DBC's maximum, the swing's drift, the tip's
closest approach to the ground; and whether the tip tracked within what the valves' dead times allow: the error a
pure delay of the reference by the identified dead time + lag would leave, for the slowest (boom) and the fastest
(bucket) function.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import time
from dataclasses import dataclass

import numpy as np

from tests.bench.bench_force_steps import FLAT_FRONT, FlatRig
from tests.bench.bench_id_hqp import WAYPOINTS
from tests.bench.bench_piston import controller_luts
from tests.bench.stats import summary_ms
from tms_common.config import config_path
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics, load_kinematics
from tms_rc.excavator.controller import load_identified
from tms_rc.excavator.hermite import HermiteReference
from tms_rc.excavator.ik_cylinder import LEVEL_NAMES, CylinderIkHQP, IkReference
from tms_rc.excavator.ik_drive import SWING, IkDrive, IkDriveSettings
from tms_rc.excavator.piston import CYLINDER_FUNCTIONS, load_piston_settings

RATE_HZ = 100.0
HOLD_S = 2.0  # [s] the reference held at its end after the 10 s of waypoints
AIR_CLEARANCE = 1.0  # [m] the drag this high above the ground
GROUND_CLEARANCE = 0.10  # [m] the drag this close to the ground
LIMIT_LEVELS = LEVEL_NAMES[:4]
SWING_ANGLE = FLAT_FRONT["swing_joint"]
PLAIN_KP = 0.8  # [1/s] the drive without the predictor (Kp T ~ 0.9 for the boom's 1.1 s)


@dataclass
class Run:
    tip_err: list[float]
    theta_err: list[float]
    wall: list[float]
    cpu: list[float]
    bound: dict[str, int]
    gave_way: int
    active: dict[str, int] = dataclasses.field(default_factory=lambda: dict.fromkeys(LIMIT_LEVELS, 0))
    saturated: int = 0
    swing_drift: float = 0.0
    swing_cmd_max: float = 0.0
    min_clearance: float = math.inf
    contact_steps: int = 0
    lag_err: list[float] = dataclasses.field(default_factory=list)

    def rms(self, xs: list[float]) -> float:
        return math.sqrt(float(np.mean(np.square(xs))))


def active_levels(ik: CylinderIkHQP, res) -> list[str]:
    """The limit levels with a row at its bound (within 1 %) at the step's final solution: they held the lower
    tasks, whether or not they needed a QP of their own (``hqp.solved`` counts only the latter: a level violated
    at the levels above's solution). Reads the hierarchy's task buffers of this step."""
    x = res.v
    out = []
    for k, name in enumerate(LIMIT_LEVELS):
        a, b = ik._a[k], ik._b[k]  # the step's rows (private buffers: a bench's inspection)
        live = b < 1e8
        if np.any(a[live] @ x >= b[live] - 0.01 * np.maximum(np.abs(b[live]), 1e-3)):
            out.append(name)
    return out


def reference(kin: ExcavatorKinematics, lift: float) -> HermiteReference:
    """bench_id_hqp's waypoints lifted by ``lift`` [m] and rotated with the swing to :data:`SWING_ANGLE`; columns
    tip x, y, z (base_link) and theta_w."""
    y0 = float(kin.tip_position(kin.home)[1])
    o = np.asarray(kin.swing_origin[:2], dtype=float)
    c, s = math.cos(SWING_ANGLE), math.sin(SWING_ANGLE)
    times = np.cumsum([w[0] for w in WAYPOINTS])
    knots = []
    for _, x, z, th, _ in WAYPOINTS:
        rel = np.array([x, y0]) - o
        xy = o + np.array([c * rel[0] - s * rel[1], s * rel[0] + c * rel[1]])
        knots.append((xy[0], xy[1], z + lift, th))
    return HermiteReference.through(times, knots)


def lift_for(rig: FlatRig, kin: ExcavatorKinematics, clearance: float) -> float:
    """[m] the lift that puts the reference's tip ``clearance`` above the ground under it at its lowest (the
    ground read from the plant along the path: the bench's set-up; base_link = map here, the base at the origin)."""
    truth = rig.plant.truth(rig.plant.spec.excavator)
    assert abs(truth.x) < 1e-9 and abs(truth.y) < 1e-9 and abs(truth.yaw) < 1e-9, "the base is not at the origin"
    ref = reference(kin, 0.0)
    gap = math.inf
    for t in np.arange(ref.start, ref.end, 0.05):
        p = ref.sample(float(t))[0]
        gap = min(gap, float(p[2] + truth.z - rig.plant.ground.height(float(p[0]), float(p[1]))))
    return clearance - gap


def delay_error(ref: HermiteReference, t: float, delay: float) -> float:
    """[m] the tip error a pure delay of the reference by ``delay`` [s] would leave at ``t``."""
    return float(np.linalg.norm(ref.sample(t)[0][:3] - ref.sample(t - delay)[0][:3]))


def plant_run(kin: ExcavatorKinematics, ref: HermiteReference, settings: IkDriveSettings, luts, piston,
              steps: int, delays_s: np.ndarray | None) -> Run:
    p0 = ref.sample(0.0)[0]
    q0 = kin.ik_position_with_angle(p0[:3], float(p0[3]))
    rig = FlatRig(penetration=False, front=dict(zip(JOINTS, map(float, q0), strict=True)))
    assert tuple(rig.names) == JOINTS, rig.names
    rig.rest(1.0)  # the front settles on its oil
    drive = IkDrive(kin, luts, piston, rig.p_max, settings=settings, delays_s=delays_s)
    drive.start(ref)
    run = Run([], [], [], [], dict.fromkeys(LIMIT_LEVELS, 0), 0)
    swing0 = float(rig.front.q[0])
    lead = round(drive.horizon_s / drive.dt)  # the planned motion starts one horizon early (0 without predictor)
    for k in range(-lead, 0):
        out = drive.step(k * drive.dt, np.array(rig.front.q, dtype=float), np.array(rig.front.v, dtype=float))
        for fn, pair in out.pairs.items():
            rig.set_pair(fn, pair)
        rig.advance()
    gc.collect()
    gc.disable()
    try:
        for k in range(steps):
            t = k * drive.dt
            q = np.array(rig.front.q, dtype=float)
            qd = np.array(rig.front.v, dtype=float)
            start, cpu_start = time.perf_counter(), time.thread_time()
            out = drive.step(t, q, qd)
            run.wall.append(time.perf_counter() - start)
            run.cpu.append(time.thread_time() - cpu_start)
            # the measured state against the reference now (the predictor solved for one T ahead)
            now = sample(ref, t)
            run.tip_err.append(float(np.linalg.norm(kin.tip_position(q) - now.position)))
            run.theta_err.append(abs(kin.theta_w(q) - now.theta_w))
            for name in LIMIT_LEVELS:
                run.bound[name] += bool(out.ik.hqp.solved.get(name, False))
            for name in active_levels(drive.ik, out.ik):
                run.active[name] += 1
            run.gave_way += out.ik.gave_way
            run.saturated += any(max(p.plus, p.minus) >= rig.p_max - 1e-9 for p in out.pairs.values())
            run.swing_cmd_max = max(run.swing_cmd_max, abs(out.swing_speed_cmd))
            for fn, pair in out.pairs.items():
                rig.set_pair(fn, pair)
            rig.advance()
            depth = rig.tip_depth()
            run.min_clearance = min(run.min_clearance, -depth)
            run.contact_steps += depth > 0.0
            run.swing_drift = max(run.swing_drift, abs(float(rig.front.q[0]) - swing0))
    finally:
        gc.enable()
    return run


def sample(ref: HermiteReference, t: float) -> IkReference:
    """The reference at ``t`` as the drive samples it."""
    p, v = ref.sample(t)
    return IkReference(position=p[:3].copy(), velocity=v[:3].copy(), theta_w=float(p[3]), theta_w_rate=float(v[3]))


def kinematic_run(kin: ExcavatorKinematics, ref: HermiteReference, settings: IkDriveSettings, steps: int) -> Run:
    ctl = CylinderIkHQP(kin, settings.ik)
    p0 = ref.sample(0.0)[0]
    q = kin.ik_position_with_angle(p0[:3], float(p0[3]))
    qd = np.zeros(4)
    run = Run([], [], [], [], dict.fromkeys(LIMIT_LEVELS, 0), 0)
    gc.collect()
    gc.disable()
    try:
        for k in range(steps):
            r = sample(ref, k * ctl.dt)
            start, cpu_start = time.perf_counter(), time.thread_time()
            res = ctl.solve(q, r, qd=qd)
            run.wall.append(time.perf_counter() - start)
            run.cpu.append(time.thread_time() - cpu_start)
            run.tip_err.append(float(np.linalg.norm(kin.tip_position(q) - r.position)))
            run.theta_err.append(abs(kin.theta_w(q) - r.theta_w))
            for name in LIMIT_LEVELS:
                run.bound[name] += bool(res.hqp.solved.get(name, False))
            for name in active_levels(ctl, res):
                run.active[name] += 1
            run.gave_way += res.gave_way
            run.swing_cmd_max = max(run.swing_cmd_max, abs(float(res.v[0])))
            qd = res.qd
            q = q + ctl.dt * qd
    finally:
        gc.enable()
    return run


def delays() -> np.ndarray:
    """[s] dead time + lag per joint, as ``tms_rc_identify`` identified them on the machine (the predictor's model,
    as :meth:`IkDrive.for_machine` reads them)."""
    ident = load_identified(config_path("tms_rc", "identified", "zx200.yaml"), "zx200")
    return ident.dead_time_s + ident.lag_s


def report(label: str, lift: float, ref: HermiteReference, runs: dict[str, Run], delay: np.ndarray,
           steps: int) -> None:
    dt = 1.0 / RATE_HZ
    names = list(runs)
    kinem = runs["kinematic"]
    print(f"  [{label}] waypoints lifted {lift:+.2f} m (drag at z {min(w[2] for w in WAYPOINTS) + lift:+.2f} m "
          f"base_link), {steps} steps; " + " | ".join(names) + ":")

    def col(f) -> str:
        return " | ".join(f(runs[n]) for n in names)

    kr = kinem.rms(kinem.tip_err)
    print("    tip RMS " + col(lambda r: f"{1000 * r.rms(r.tip_err):.1f}") + " mm (plant / kinematic: "
          + ", ".join(f"{n} {runs[n].rms(runs[n].tip_err) / kr:.0f}x" for n in names[:-1]) + "); max "
          + col(lambda r: f"{1000 * max(r.tip_err):.1f}") + " mm; theta_w RMS "
          + col(lambda r: f"{1000 * r.rms(r.theta_err):.1f}") + " mrad")
    for n in names:
        what = "CylinderIkHQP.solve" if n == "kinematic" else "IkDrive.step: reference + IK + 3 piston controllers"
        print(f"    per step, {n} ({what}), wall: " + summary_ms(runs[n].wall))
        print(f"    per step, {n}, thread CPU: " + summary_ms(runs[n].cpu))
    print("    steps a limit level needed a QP of its own (violated at the levels above's solution) ("
          + " | ".join(names) + "): " + ", ".join(f"{lv} " + col(lambda r, lv=lv: str(r.bound[lv]))
                                                   for lv in LIMIT_LEVELS))
    print("    steps a limit level was at its bound at the final solution (held a lower task): "
          + ", ".join(f"{lv} " + col(lambda r, lv=lv: str(r.active[lv])) for lv in LIMIT_LEVELS)
          + "; position task gave way (> 1 mm/s short) " + col(lambda r: str(r.gave_way)))
    for n in names[:-1]:
        r = runs[n]
        print(f"    {n}: steps with a pilot at the DBC maximum {r.saturated}; swing (spool centred) drifted "
              f"{1000 * r.swing_drift:.2f} mrad, IK asked up to {1000 * r.swing_cmd_max:.2f} mrad/s of it; tip "
              f"closest to the ground {100 * r.min_clearance:.1f} cm, {r.contact_steps} steps in contact")
    allow = {}
    for fn in ("boom_joint", "bucket_joint"):
        d = float(delay[JOINTS.index(fn)])
        e = [delay_error(ref, k * dt, d) for k in range(steps)]
        allow[fn] = (d, math.sqrt(float(np.mean(np.square(e)))), max(e))
    (db, rb, mb), (dk, rk, mk) = allow["boom_joint"], allow["bucket_joint"]
    print(f"    dead-time allowance: a pure delay of the reference by the boom's dead time + lag {db:.2f} s leaves "
          f"RMS {1000 * rb:.1f} mm (max {1000 * mb:.1f}), by the bucket's {dk:.2f} s RMS {1000 * rk:.1f} mm (max "
          f"{1000 * mk:.1f}); " + "; ".join(
              f"{n} {runs[n].rms(runs[n].tip_err) / rb:.2f} of the boom's, {runs[n].rms(runs[n].tip_err) / rk:.2f} of "
              f"the bucket's: {'within' if runs[n].rms(runs[n].tip_err) <= rb else 'NOT within'}"
              for n in names[:-1]))


def main() -> None:
    wall0 = time.monotonic()
    kin = load_kinematics("zx200")
    piston = load_piston_settings()
    settings = IkDriveSettings()
    #: without the predictor: the IK's Kp within ~pi / (2 T) of the boom's delay, the piston PI on (as bench piston)
    plain = IkDriveSettings(ik=dataclasses.replace(settings.ik, kp_position=PLAIN_KP, ki_position=0.1,
                                                   i_zone_position=0.05, kp_theta_w=PLAIN_KP),
                            piston_feedback=True, smith_predictor=False)
    steps = round((float(np.sum([w[0] for w in WAYPOINTS])) + HOLD_S) * RATE_HZ)
    probe = FlatRig(penetration=False)
    luts, source = controller_luts(probe, CYLINDER_FUNCTIONS, piston)
    ik = settings.ik
    print(f"ik_plant bench: CylinderIkHQP through PistonVelocityController on the plant core (config/sim/paper_plant"
          f".yaml, soil penetration off), ZX200 swung {SWING_ANGLE:+.2f} rad to the flat ground, bench_id_hqp's "
          f"waypoints; tables {source}; swing: {'its table' if SWING in luts else 'no table, spool centred'}; IK "
          f"PID Kp {ik.kp_position}/s Ki {ik.ki_position}/s^2, theta_w Kp {ik.kp_theta_w}/s, piston PI "
          f"{'on' if settings.piston_feedback else 'off'}, deadband {1000 * settings.velocity_deadband:.0f} mm/s "
          f"('smith', the default drive); 'plain': no predictor, Kp {PLAIN_KP}/s, piston PI on")
    delay = delays()
    print("  identified delays (dead time + lag) [s]: " + ", ".join(f"{j} {d:.2f}" for j, d in zip(JOINTS, delay,
                                                                                                   strict=True))
          + "; 'smith' predicts over the slowest driven (the boom's) and starts that much before the reference's t 0")
    for label, clearance in (("air", AIR_CLEARANCE), ("ground", GROUND_CLEARANCE)):
        lift = lift_for(probe, kin, clearance)
        ref = reference(kin, lift)
        runs = {"smith": plant_run(kin, ref, settings, luts, piston, steps, delay),
                "plain": plant_run(kin, ref, plain, luts, piston, steps, None),
                "kinematic": kinematic_run(kin, ref, settings, steps)}
        report(label, lift, ref, runs, delay, steps)
    print(f"  {time.monotonic() - wall0:.1f} s wall")


if __name__ == "__main__":
    main()
