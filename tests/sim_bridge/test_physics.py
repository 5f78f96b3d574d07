"""The physical plant against hand computation and the ZX200's published figures (no ROS, no CAN: the pure plant).

Statics (cylinder pressures from masses, lever arms and areas), ISO 6015 tool forces against the spec sheet, flow
and pump-limited speeds, step and chirp responses, the emergency stop with inertia, and the model's consistency
(MuJoCo's tendon lengths against tms_model's cylinder kinematics, the masses against the operating weight).
Run with ``-s`` to see the figures.
"""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from sim_bridge.config import load_plant
from sim_bridge.plant import Plant
from sim_bridge.profiles.excavator import linkage_angles
from tms_model.cylinders import cylinder_length, moment_arm

G = 9.81
FRONT = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
#: Hitachi ZX200-5B operating weight [kg] (Hitachi table, https://phreeqc.blogspot.com/2014/12/blog-post_13.html)
OPERATING_WEIGHT = 19_800
#: ISO 6015 tool forces of the ZX200 class with the 2.91 m arm [N] (Hitachi ZX200-5 spec sheet, unverified)
ISO_BUCKET, ISO_ARM = 158e3, 111e3


@pytest.fixture(scope="module")
def spec():
    return load_plant()


def _plane(joint):
    return (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]


#: open ground of the paper site, away from the mound: the bucket moves through air (the soil tests dig)
OPEN_GROUND = (-12.0, -12.0, 0.0)


def _hold(plant: Plant, pose: dict[str, float], seconds: float = 3.0) -> None:
    zx = plant.excavator
    plant.set_truth(zx.name, *OPEN_GROUND, pose)
    zx.set_front_velocity(dict.fromkeys(FRONT, 0.0))
    for _ in range(round(seconds / plant.dt)):
        plant.step()


def _potential_gradient(plant: Plant, joint: str, q: dict[str, float], h: float = 1e-4) -> float:
    """dV/dq of the front's weight (V = sum m g z over every body, the four-bar's links included), by moving the
    joint +-h with the linkage closed: the hand computation's lever arms, taken from the model's geometry."""
    m, d = plant.model.model, plant.model.data
    zx = plant.excavator
    name = zx.name
    saved = d.qpos.copy()
    link = zx.description.cylinders.bucket.linkage
    bucket = zx.description.joint("bucket_joint")

    def energy(qq: dict[str, float]) -> float:
        for j, v in qq.items():
            plant.model.set_joint(f"{name}_{j}", v)
        g, s = linkage_angles(bucket, link, qq["bucket_joint"])
        plant.model.set_joint(f"{name}_guide_joint", g)
        plant.model.set_joint(f"{name}_side_joint", s)
        mujoco.mj_kinematics(m, d)
        bodies = [b for b in range(m.nbody) if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or "").startswith(
            f"{name}_") and not m.body_mocapid[b] >= 0]
        # the soil in the bucket (its weight acts at the bucket's centre of mass, as the plant applies it)
        soil = plant.soil.bucket * plant.spec.soil.loose_density
        return sum(m.body_mass[b] * G * d.xipos[b][2] for b in bodies) + soil * G * d.xipos[plant.model.bucket_body][2]

    up, down = dict(q), dict(q)
    up[joint] += h
    down[joint] -= h
    grad = (energy(up) - energy(down)) / (2 * h)
    d.qpos[:] = saved
    mujoco.mj_kinematics(m, d)
    return grad


POSES = [
    {"swing_joint": 0.0, "boom_joint": -0.5, "arm_joint": 1.658, "bucket_joint": 0.5},
    {"swing_joint": 0.0, "boom_joint": -0.9, "arm_joint": 1.2, "bucket_joint": 0.2},
    {"swing_joint": 0.0, "boom_joint": -0.3, "arm_joint": 2.2, "bucket_joint": 1.5},
    {"swing_joint": 0.0, "boom_joint": -1.0, "arm_joint": 0.9, "bucket_joint": -0.3},
    {"swing_joint": 0.0, "boom_joint": -0.6, "arm_joint": 1.9, "bucket_joint": 2.0},
]


def test_masses_add_up_to_the_operating_weight(spec):
    d = spec.description(spec.excavator)
    total = sum(d.masses.values())
    print(f"\nZX200 masses: {total:.0f} kg against {OPERATING_WEIGHT} kg operating weight "
          f"({100 * (total / OPERATING_WEIGHT - 1):+.1f} %)")
    assert abs(total / OPERATING_WEIGHT - 1) < 0.05


def test_mujoco_tendons_are_the_description_cylinders(spec):
    """MuJoCo's spatial tendons between the pin sites (through the closed four-bar) have the lengths tms_model's
    cylinder kinematics gives, at every pose."""
    plant = Plant(spec)
    zx = plant.excavator
    d = zx.description
    m, data = plant.model.model, plant.model.data
    for pose in POSES:
        _hold(plant, pose, seconds=0.5)
        for c in d.cylinders.all:
            j = d.joint(c.joint)
            tendon = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TENDON, f"{zx.name}_{c.joint.removesuffix('_joint')}_cyl")
            q = zx.front.q[FRONT.index(c.joint)]
            expected = cylinder_length(c, *_plane(j), q)
            assert data.ten_length[tendon] == pytest.approx(expected, abs=3e-3), (c.joint, pose)


@pytest.mark.parametrize("pose", POSES, ids=[f"pose{i}" for i in range(len(POSES))])
def test_statics_cylinder_pressures_match_the_hand_computation(spec, pose):
    plant = Plant(spec)
    zx = plant.excavator
    _hold(plant, pose)
    q = dict(zip(FRONT, zx.front.q, strict=True))
    assert max(abs(v) for v in zx.front.v) < 1e-3, zx.front.v  # held still
    d = zx.description
    tank = zx.front.tank
    rows = []
    for i, c in enumerate(d.cylinders.all, start=1):
        j = d.joint(c.joint)
        # virtual work: F dl - dV = 0  ->  F = (dV/dq) / (dl/dq); the loaded chamber carries F over the tank pressure on
        # the other side
        force = _potential_gradient(plant, c.joint, q) / moment_arm(c, *_plane(j), q[c.joint])
        if force >= 0:
            hand, plant_p = (force + tank * c.rod_area) / c.cap_area, zx.front.p_ext[i]
        else:
            hand, plant_p = (-force + tank * c.cap_area) / c.rod_area, zx.front.p_ret[i]
        rows.append((c.joint, force, hand, plant_p))
    print("\n" + "; ".join(f"{n}: F {f / 1e3:+.1f} kN, hand {h / 1e6:.2f} MPa, plant {p / 1e6:.2f} MPa"
                           for n, f, h, p in rows))
    for name, _, hand, plant_p in rows:
        assert plant_p == pytest.approx(hand, rel=0.05), name


def _iso_forces(d):
    """ISO 6015 tool forces at the implement relief, from the cylinder kinematics: bucket = max over the bucket's
    range of p A dl/dq / |bucket pin -> edge|; arm = max over the arm's range of p A dl/dq / |arm pin -> edge|, the
    bucket at the angle that puts its edge farthest from the arm pin (edge in line with the arm: the rated radius)."""
    cyl = d.cylinders
    p = cyl.relief_pa
    bucket, arm = d.joint("bucket_joint"), d.joint("arm_joint")
    tip = d.bucket.tip_xyz
    r_bucket = math.hypot(tip[0], tip[2])
    qs = np.linspace(bucket.lower, bucket.upper, 400)
    f_bucket = max(p * cyl.bucket.cap_area * moment_arm(cyl.bucket, *_plane(bucket), q) for q in qs) / r_bucket
    o, pitch = _plane(bucket)
    radii = []
    for q in qs:
        x, z = o[0] + math.cos(pitch + q) * tip[0] + math.sin(pitch + q) * tip[2], \
            o[1] - math.sin(pitch + q) * tip[0] + math.cos(pitch + q) * tip[2]
        radii.append(math.hypot(x, z))
    r_arm = max(radii)
    qa = np.linspace(arm.lower, arm.upper, 400)
    f_arm = max(p * cyl.arm.cap_area * moment_arm(cyl.arm, *_plane(arm), q) for q in qa) / r_arm
    return f_bucket, f_arm, r_bucket, r_arm


def test_iso6015_tool_forces_against_the_spec_sheet(spec):
    d = spec.description(spec.excavator)
    f_bucket, f_arm, rb, ra = _iso_forces(d)
    print(f"\nISO 6015 at {d.cylinders.relief_mpa} MPa: bucket {f_bucket / 1e3:.0f} kN (radius {rb:.2f} m) against "
          f"{ISO_BUCKET / 1e3:.0f} kN ({100 * (f_bucket / ISO_BUCKET - 1):+.0f} %); arm {f_arm / 1e3:.0f} kN "
          f"(radius {ra:.2f} m) against {ISO_ARM / 1e3:.0f} kN ({100 * (f_arm / ISO_ARM - 1):+.0f} %)")
    assert f_bucket == pytest.approx(ISO_BUCKET, rel=0.15)
    assert f_arm == pytest.approx(ISO_ARM, rel=0.15)


def test_bucket_holds_below_its_relief_and_gives_above_it(spec):
    """The plant's force path ends at the relief valve: at the bucket's best pose, a couple between arm and bucket
    (the bucket cylinder alone carries it) opening the bucket with 90 % of what the relief allows is held; 110 %
    opens the relief and the bucket gives way and keeps going."""
    d = spec.description(spec.excavator)
    cyl = d.cylinders.bucket
    bucket = d.joint("bucket_joint")
    qs = np.linspace(bucket.lower, bucket.upper, 200)
    q_best = float(qs[np.argmax([moment_arm(cyl, *_plane(bucket), q) for q in qs])])
    pose = dict(POSES[0], bucket_joint=q_best)
    moved, speed = {}, {}
    for share in (0.9, 1.1):
        plant = Plant(spec)
        zx = plant.excavator
        _hold(plant, pose, seconds=1.0)
        data = plant.model.data
        body, arm = plant.model.bucket_body, plant.model.body_ids[f"{zx.name}_arm_link"]
        axis = data.xmat[body].reshape(3, 3)[:, 1]  # the bucket joint's axis (+ = curl)
        q0 = zx.front.q[3]
        limit = d.cylinders.relief_pa * cyl.cap_area * moment_arm(cyl, *_plane(bucket), q0)
        # what the cylinder already carries of the bucket's weight stays on it
        force = zx.front.p_ext[3] * cyl.cap_area - zx.front.p_ret[3] * cyl.rod_area
        held = force * moment_arm(cyl, *_plane(bucket), q0)
        couple = -axis * (share * limit - held)

        def load(data=data, body=body, arm=arm, couple=couple) -> None:
            data.xfrc_applied[:] = 0.0
            data.xfrc_applied[body, 3:] = couple
            data.xfrc_applied[arm, 3:] = -couple

        plant._loads = load  # the test's couple instead of the soil's weight
        for _ in range(200):
            plant.step()
        moved[share] = zx.front.q[3] - q0
        speed[share] = zx.front.v[3]
    print(f"\nbucket at q = {q_best:.2f} rad: 90 % of the relief torque moved it {moved[0.9]:+.4f} rad (the oil "
          f"column's give) and it came to rest; 110 % {moved[1.1]:+.4f} rad in 2 s")
    assert abs(moved[0.9]) < 0.1 and abs(speed[0.9]) < 0.01
    assert moved[1.1] < -0.5


def _run(plant: Plant, cmd: dict[str, float], seconds: float) -> list[tuple[float, list[float]]]:
    zx = plant.excavator
    zx.set_front_velocity(cmd)
    out = []
    for _ in range(round(seconds / plant.dt)):
        plant.step()
        out.append((plant.time, list(zx.front.v)))
    return out


def test_speeds_empty_full_bucket_and_pump_saturation_follow_the_flow_model(spec):
    """Boom raise alone with an empty and a full bucket (load-sensing: the same speed while the pumps keep their
    margin and power; slower once the pressure asks more power than the engine gives), then all four functions at
    full command (the pumps share their flow): every cylinder's speed is the flow model's Q_i * scale / A."""
    rows = {}
    for label, load in (("empty", 0.0), ("full", spec.description(spec.excavator).bucket.capacity)):
        plant = Plant(spec)
        plant.soil.bucket = load
        zx = plant.excavator
        _hold(plant, POSES[2], seconds=1.0)
        out = _run(plant, {"boom_joint": -0.45}, 2.0)
        rows[label] = (out[-1][1][1], zx.front.pump_pressure, zx.front.flow_scale, zx.front.p_ext[1])
        plant.soil.bucket = 0.0
    for label, (v, pp, sc, pl) in rows.items():
        print(f"\nboom raise, {label} bucket: {v:+.3f} rad/s, boom cap {pl / 1e6:.1f} MPa, pump {pp / 1e6:.1f} MPa, "
              f"pump flow share {sc:.2f}")
    # the full bucket needs more pressure; the pumps' power limit sets how much slower it goes
    assert rows["full"][3] > rows["empty"][3]
    (ve, _, sce, _), (vf, _, scf, _) = rows["empty"], rows["full"]
    assert abs(vf / ve) == pytest.approx(scf / sce, rel=0.08)

    plant = Plant(spec)
    zx = plant.excavator
    _hold(plant, POSES[0], seconds=1.0)
    full = {j: (-1 if j == "boom_joint" else 1) * zx.description.joint(j).velocity for j in FRONT}
    _run(plant, full, 2.5)
    f = zx.front
    measured = [f.drive_speed[i] for i in range(4)]
    predicted = [f.flow[i] / (f.a_ext[i] if f.flow[i] > 0 else f.a_ret[i]) for i in range(4)]
    total = sum(abs(q) for q in f.flow) * 60000
    print(f"all four at full command: pump {f.pump_pressure / 1e6:.1f} MPa, {total:.0f} L/min, "
          f"share {f.flow_scale:.2f}; "
          + ", ".join(f"{n} {m:+.3f} (model {p:+.3f})" for n, m, p in zip(FRONT, measured, predicted, strict=True)))
    assert f.flow_scale < 1.0  # the pumps are saturated
    assert total <= zx.front.pump_flow * 60000 * 1.01
    for n, mv, pv in zip(FRONT, measured, predicted, strict=True):
        assert mv == pytest.approx(pv, rel=0.15, abs=0.01), n


def _rise_time(t: np.ndarray, v: np.ndarray, final: float) -> tuple[float, float]:
    """(dead time to 10 %, 10-90 % rise time) of a step response."""
    t10 = t[np.argmax(np.abs(v) >= 0.1 * abs(final))]
    t90 = t[np.argmax(np.abs(v) >= 0.9 * abs(final))]
    return float(t10), float(t90 - t10)


def test_step_and_chirp_of_each_function(spec):
    """Each function alone: a step of half its rated speed (dead time, 10-90 % rise time), then sines of rising
    frequency (gain against the low-frequency gain; the -3 dB bandwidth). Printed; the rise times must be those of
    a valve with its spool lag behind a dead time, not of a kinematic jump."""
    dt = spec.dt
    for i, joint in enumerate(FRONT):
        plant = Plant(spec)
        zx = plant.excavator
        _hold(plant, POSES[0], seconds=1.0)
        j = zx.description.joint(joint)
        cmd = (-0.5 if joint == "boom_joint" else 0.5) * min(j.velocity, 0.6)
        out = _run(plant, {joint: cmd}, 3.0)
        t = np.array([o[0] for o in out]) - out[0][0] + dt
        v = np.array([o[1][i] for o in out])
        window = (t > zx.description.drives[joint].dead_time + 1.2) & (t < zx.description.drives[joint].dead_time + 1.7)
        final = float(np.mean(v[window]))
        dead, rise = _rise_time(t, v, final)
        gains = []
        freqs = (0.1, 0.25, 0.5, 1.0, 1.5, 2.5)
        for fhz in freqs:
            plant = Plant(spec)
            zx = plant.excavator
            _hold(plant, POSES[0], seconds=1.0)
            amp = 0.3 * cmd / 0.5 * 0.5
            n = round(max(3.0, 4.0 / fhz) / dt)
            vs, cs = [], []
            for k in range(n):
                c = amp * math.sin(2 * math.pi * fhz * k * dt)
                zx.set_front_velocity({joint: c})
                plant.step()
                vs.append(zx.front.v[i])
                cs.append(c)
            half = n // 2  # steady part
            ts = np.arange(half, n) * dt
            basis = np.column_stack([np.sin(2 * math.pi * fhz * ts), np.cos(2 * math.pi * fhz * ts)])
            coef, *_ = np.linalg.lstsq(basis, np.array(vs[half:]), rcond=None)
            gains.append(float(np.hypot(*coef)) / abs(amp))
        g = np.array(gains) / gains[0]
        below = np.nonzero(g < 10 ** (-3 / 20))[0]
        bw = freqs[below[0]] if below.size else float("inf")
        print(f"\n{joint}: step {cmd:+.2f} rad/s -> {final:+.3f}; dead time {dead:.2f} s, rise {rise:.2f} s; gain "
              + ", ".join(f"{fr} Hz {20 * math.log10(x):+.1f} dB" for fr, x in zip(freqs, g, strict=True))
              + f"; -3 dB below {bw} Hz")
        assert final == pytest.approx(cmd, rel=0.1)
        assert dead >= 0.8 * zx.description.drives[joint].dead_time
        assert rise >= 1.5 * zx.description.drives[joint].time_constant  # a lag, not a jump
        assert g[-1] < g[0]  # the valve and the load roll the response off


@pytest.mark.parametrize("case", ["swing", "boom_lowering"])
def test_emergency_stop_with_inertia(spec, case):
    """Pilot cut-off at full swing speed or mid boom lowering: the swing is braked by its relief torque and its parking
    brake, which the cut-off applies (stop angle ~ w^2 / (2 (T_relief + T_brake) / I) after the solenoid and the
    spools), the boom stops in the oil's give; after the lock nothing moves."""
    plant = Plant(spec)
    zx = plant.excavator
    _hold(plant, POSES[0], seconds=1.0)
    i = 0 if case == "swing" else 1
    cmd = {"swing_joint": zx.description.joint("swing_joint").velocity} if case == "swing" else {"boom_joint": 0.3}
    # the controller's ramp (the swing's rated acceleration) so the start does not itself ride the relief
    for k in range(1, 400):
        c = {n: v * min(1.0, k * plant.dt / 3.0) for n, v in cmd.items()}
        zx.set_front_velocity(c)
        plant.step()
        if case == "boom_lowering" and zx.front.q[1] > -0.35:
            break
    w0, q0 = zx.front.v[i], zx.front.q[i]
    inertia = plant.drives.mass[0]
    cut = zx.description.pilot_cutoff
    zx.set_pilot_cutoff(True)
    t = 0.0
    while abs(zx.front.v[i]) > 0.005 and t < 10.0:
        plant.step()
        t += plant.dt
    angle = zx.front.q[i] - q0
    for _ in range(100):  # the oil columns settle
        plant.step()
    q_rest = list(zx.front.q)
    for _ in range(300):
        plant.step()
    drift = max(abs(a - b) for a, b in zip(zx.front.q, q_rest, strict=True))
    if case == "swing":
        torque = zx.description.cylinders.swing.relief_torque + zx.description.cylinders.swing.brake_torque
        predicted = w0**2 / (2 * torque / inertia) + abs(w0) * (cut.solenoid_delay + 3 * cut.front_time_constant)
        print(f"\nswing at {w0:.2f} rad/s (inertia {inertia / 1e3:.0f} t m^2), cut-off: at rest after {t:.2f} s, "
              f"{math.degrees(angle):.1f} deg (relief and brake: {math.degrees(predicted):.1f} deg predicted); "
              f"drift after the lock {drift:.2e} rad")
        assert 0.6 * predicted <= abs(angle) <= 1.3 * predicted
    else:
        print(f"\nboom lowering at {w0:.2f} rad/s, cut-off: at rest after {t:.2f} s, {math.degrees(angle):.2f} deg; "
              f"drift after the lock {drift:.2e} rad")
        assert abs(angle) < abs(w0) * (cut.solenoid_delay + 4 * cut.front_time_constant) + 0.02
    assert t < 10.0
    assert drift < 2e-3


def test_plant_cost_per_simulated_second_is_printed(spec):
    """Not a speed target (tests/bench/bench_sim_bridge.py has those): the figure, so a slow change shows."""
    import time

    plant = Plant(dataclasses.replace(spec))
    t0 = time.process_time()
    for _ in range(300):
        plant.step()
    cpu = time.process_time() - t0
    print(f"\nplant core, paper site idle: {cpu / (300 * plant.dt):.3f} core-s per simulated s")
    assert cpu > 0


def _pose_at_depth(plant: Plant, depth: float) -> dict[str, float]:
    """A front pose at the start position whose bucket edge is ``depth`` below the mound's surface there (the boom
    angle found by bisection on the plant's own kinematics)."""
    zx = plant.excavator
    x, y, yaw = zx.base.x, zx.base.y, zx.base.yaw
    lo, hi = -1.1, -0.1  # boom up .. down

    def below(boom: float) -> float:
        pose = {"swing_joint": 0.0, "boom_joint": boom, "arm_joint": 1.5, "bucket_joint": 0.6}
        plant.set_truth(zx.name, x, y, yaw, pose)
        tip = plant.model.bucket_tip()
        return plant.ground.height(tip[0], tip[1]) - tip[2]

    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if below(mid) > depth else (mid, hi)
    return {"swing_joint": 0.0, "boom_joint": (lo + hi) / 2, "arm_joint": 1.5, "bucket_joint": 0.6}


def _drag(spec, depth: float, seconds: float = 1.0, joint: str = "arm_joint") -> tuple[float, ...]:
    """Arm crowd at half its rated speed with the edge ``depth`` in the mound: (mean cutting resistance [N] over the
    first 0.1 s of the cut, the arm cylinder's mean cap pressure then [Pa], the distance the edge travelled [m], the
    mean depth of the edge over that 0.1 s)."""
    plant = Plant(spec)
    zx = plant.excavator
    pose = _pose_at_depth(plant, depth)
    zx.set_front_velocity(dict.fromkeys(FRONT, 0.0))
    for _ in range(50):
        plant.step()
    start = plant.model.bucket_tip()
    i = FRONT.index(joint)
    zx.set_front_velocity({joint: 0.5})
    forces, pressures, depths = [], [], []
    for _ in range(round((zx.description.drives[joint].dead_time + seconds) / plant.dt)):
        plant.step()
        tip = plant.model.bucket_tip()
        u = plant._tip_velocity[:2] / max(1e-9, float(np.linalg.norm(plant._tip_velocity[:2])))
        ahead = tip[:2] + u * 2 * plant.spec.soil.resolution
        here = plant.ground.height(*ahead) - tip[2]  # the uncut surface ahead of the edge
        if plant.cut_force is not None and zx.front.v[i] > 0.01 and len(forces) < 10:  # the first 0.1 s of the cut
            depths.append(here)
            forces.append(float(np.hypot(*plant.cut_force[0][:2])))  # the wedge's resistance in the arm's plane
            pressures.append(zx.front.p_ext[i])
    travel = float(np.linalg.norm(plant.model.bucket_tip() - start))
    assert pose["boom_joint"] is not None
    return (float(np.mean(forces)) if forces else 0.0, float(np.mean(pressures)) if pressures else zx.front.p_ext[i],
            travel, float(np.mean(depths)) if depths else depth, zx.front.p_ext[i], zx.front.v[i])


def test_digging_force_rises_with_cut_depth(spec):
    rows = [_drag(spec, d) for d in (0.1, 0.25, 0.4)]
    for f, p, travel, d, _, _ in rows:
        print(f"\ncut {d:.2f} m deep ({spec.soil.cutting.name}): resistance {f / 1e3:.1f} kN, "
              f"arm cap {p / 1e6:.1f} MPa, edge moved {travel:.2f} m in 1 s")
    forces = [r[0] for r in rows]
    assert forces[0] > 0.0 and forces[0] < forces[1] < forces[2]
    assert rows[0][1] < rows[2][1]  # the arm cylinder works harder in the deeper cut
    # the bucket curled through a shallow and a 2 m deep cut, and the arm crowded through the deep one: the deep
    # cut is deeper than the cylinders can drag the bucket through: they reach relief and the bucket stalls
    shallow = _drag(spec, 0.3, seconds=1.0, joint="bucket_joint")
    deep = _drag(spec, 2.0, seconds=1.0, joint="bucket_joint")
    crowd = _drag(spec, 2.0, seconds=1.0, joint="arm_joint")
    relief = spec.description(spec.excavator).cylinders.relief_pa
    runs = (("bucket curl", shallow), ("bucket curl", deep), ("arm crowd", crowd))
    for what, (_, p, travel, d, p_end, w_end) in runs:
        print(f"{what} {d:.2f} m deep: cylinder {p / 1e6:.1f} MPa as the cut starts, {p_end / 1e6:.1f} MPa after "
              f"1 s (relief {relief / 1e6:.1f}), at {w_end:+.3f} rad/s of 0.5 commanded, edge moved {travel:.3f} m")
    assert shallow[5] > 0.4  # the shallow curl goes through at nearly its commanded speed
    for stalled in (deep, crowd):
        assert stalled[4] > 0.97 * relief  # the cylinder at its relief setting ...
        assert abs(stalled[5]) < 0.05 and stalled[2] < 0.1  # ... and the edge stopped in the soil
