"""Unit tests of the plant core (no ROS, no CAN): hydraulics, tracks, soil, MJCF, GNSS, config errors."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sim_bridge.config import load_description, load_plant
from sim_bridge.errors import ReplayError, SimConfigError
from sim_bridge.hydraulics import DeadTimeLag, JointBank
from sim_bridge.model import SiteModel
from sim_bridge.plant import Plant, stamp_parts
from sim_bridge.runner import PlantRunner, TruthLog, TruthRecorder
from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
from sim_bridge.sensors import Gnss, Noise
from tms_common.config import config_path


@pytest.fixture(scope="module")
def spec():
    return load_plant()


def test_dead_time_then_first_order_lag():
    act = DeadTimeLag(dead_time=0.3, time_constant=0.2, limit=1.0, dt=0.01)
    out = [act.step(0.5) for _ in range(200)]
    assert all(v == 0.0 for v in out[:30])  # nothing during the dead time
    assert out[30] > 0.0
    # one time constant after the dead time: 1 - 1/e of the step
    assert out[30 + 19] == pytest.approx(0.5 * (1 - math.exp(-1)), rel=0.03)
    assert out[-1] == pytest.approx(0.5, rel=1e-3)


def test_command_above_limit_saturates_at_velocity_limit():
    act = DeadTimeLag(dead_time=0.0, time_constant=0.1, limit=0.45, dt=0.01)
    for _ in range(300):
        v = act.step(5.0)
    assert v == pytest.approx(0.45, rel=1e-6)


def test_joint_stops_at_position_limit(spec):
    zx = spec.description(spec.excavator)
    boom = zx.joint("boom_joint")
    bank = JointBank([boom], zx.drives, spec.dt)
    bank.q[0] = -0.5
    bank.command[0] = 0.4  # + = down, towards the upper limit -0.1
    for _ in range(800):
        bank.step()
    assert bank.q[0] == pytest.approx(boom.upper)
    assert bank.v[0] == 0.0


def test_shared_pump_flow_slows_arm_joints_together(spec):
    zx = spec.description(spec.excavator)
    bank = JointBank(zx.joints, zx.drives, spec.dt, pump_flow=zx.pump_flow)
    bank.set_positions({"boom_joint": -0.2, "arm_joint": 1.0, "bucket_joint": 0.0})
    names = bank.names
    sign = {"boom_joint": -1.0, "arm_joint": 1.0, "bucket_joint": 1.0, "swing_joint": 0.0}
    for i, n in enumerate(names):  # all three at their velocity limits: demand 750 > 424 L/min
        bank.command[i] = sign[n] * zx.joint(n).velocity
    for _ in range(200):
        bank.step()
    assert bank.flow_scale < 1.0
    assert sum(bank.flows()) == pytest.approx(zx.pump_flow, rel=1e-6)  # the pumps give all they have
    ratios = [abs(bank.v[i]) / zx.joint(n).velocity for i, n in enumerate(names) if n != "swing_joint"]
    assert max(ratios) < 0.7  # every shared joint is well below its own limit
    # one joint alone is not flow-limited
    solo = JointBank(zx.joints, zx.drives, spec.dt, pump_flow=zx.pump_flow)
    solo.set_positions({"arm_joint": 0.7})
    solo.command[names.index("arm_joint")] = 1.1
    for _ in range(160):
        solo.step()
    assert solo.v[names.index("arm_joint")] == pytest.approx(1.1, rel=1e-2)
    assert solo.flow_scale == 1.0


def test_tracks_slip_and_odometry_drift(spec):
    plant = Plant(spec)
    ic = plant.carrier
    ic.set_centre_velocity(1.0, 0.0)
    x0 = ic.base.x
    odo = 0.0
    for _ in range(1000):
        plant.step()
        odo += 0.5 * (ic.base.vl + ic.base.vr) * plant.dt
    travelled = ic.base.x - x0
    assert travelled == pytest.approx(odo * (1 - spec.description(spec.carrier).track_drive.slip), rel=1e-6)
    assert odo - travelled > 0.3  # track odometry over-reads by the slip


def test_mjcf_kinematics_match_urdf_zero_pose(spec):
    model = SiteModel(spec)
    model.set_base("zx200", 0.0, 0.0, 0.0, 0.0)
    for name in ("swing_joint", "boom_joint", "arm_joint", "bucket_joint"):
        model.set_joint(f"zx200_{name}", 0.0)
    model.forward()
    # zx200_ros2 URDF (derived): tip at (10.435, -0.087, 1.957) in base_link at q = 0
    assert model.bucket_tip() == pytest.approx([10.435, -0.087, 1.957], abs=2e-3)
    assert "<hfield" in model.xml and "ic120_vessel_joint" in model.xml


def test_soil_conserved_over_scripted_dig_load_dump(spec):
    plant = Plant(spec)
    plant.set_truth("ic120", 1.2, 6.5, 0.0, {"vessel_joint": 0.0})  # site point P1
    zx, ic = plant.excavator, plant.carrier
    names = zx.front.names
    v0 = plant.total_volume()
    for _cycle in range(2):
        for target in DIG_CYCLE:
            t0 = plant.time
            while plant.time - t0 < 30.0:
                q = dict(zip(names, zx.front.q, strict=True))
                if pose_reached(q, target):
                    break
                zx.set_front_velocity(servo_velocity(q, target))
                plant.step()
            zx.set_front_velocity(dict.fromkeys(names, 0.0))
            for _ in range(150):
                plant.step()
    loaded = plant.soil.vessel
    assert plant.soil.dug > 1.0
    # the scripted cycle's cut goes deeper than the cylinders can drag the bucket: it stalls at relief and lifts out
    # with less than a heaped bucket (sim_bridge.soil_force)
    assert loaded > 0.6
    ic.set_vessel_target(ic.vessel.max_angle)
    for _ in range(2000):
        plant.step()
    ic.set_vessel_target(0.0)
    for _ in range(800):
        plant.step()
    assert plant.soil.vessel == pytest.approx(0.0, abs=1e-9)
    assert plant.soil.dumped == pytest.approx(loaded, rel=1e-9)
    assert plant.total_volume() == pytest.approx(v0, rel=1e-9)


def test_gnss_round_trip_and_site_origin(spec):
    gnss = Gnss(spec.site)
    lat, lon, alt = gnss.map_to_geodetic(0.0, 0.0, 0.0)
    assert lat == pytest.approx(36.12626, abs=1e-5)  # the OPERA test field's map origin
    assert lon == pytest.approx(140.07103, abs=1e-5)
    noise = Noise(spec.sensors)
    errs = []
    for i in range(200):
        x, y, z = 10.0 + i, -5.0, 1.0
        back = gnss.geodetic_to_map(*gnss.fix(x, y, z, noise))
        errs.append(math.hypot(back[0] - x, back[1] - y))
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    assert 0.5 * spec.sensors.gnss_sigma_h < rms / math.sqrt(2) < 2 * spec.sensors.gnss_sigma_h


def _write_broken(tmp_path: Path, old: str, new: str) -> Path:
    text = config_path("machines", "zx200.yaml").read_text()
    assert old in text
    path = tmp_path / "zx200.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_malformed_machine_yaml_names_the_key(tmp_path):
    bad = _write_broken(tmp_path, "velocity: 0.45", 'velocity: "fast"')
    with pytest.raises(SimConfigError, match=r"zx200\.yaml:\d+: joints\.boom_joint\.velocity: expected a number"):
        load_description(bad)
    typo = _write_broken(tmp_path, "pump_flow_lpm:", "pump_flow_lmp:")
    with pytest.raises(SimConfigError, match=r"hydraulics\.pump_flow_lmp: unknown key"):
        load_description(typo)
    missing = _write_broken(tmp_path, "arm_joint: 0.4255, ", "")
    plant = tmp_path / "plant.yaml"  # the plant YAML naming the broken file for its machine zx200
    text = config_path("sim", "plant.yaml").read_text()
    assert "zx200: machines/zx200.yaml" in text
    plant.write_text(text.replace("zx200: machines/zx200.yaml", f"zx200: {missing}"))
    with pytest.raises(SimConfigError, match=r"hydraulics\.dead_time_s\.arm_joint: missing required key"):
        load_plant(plant)


def test_plant_yaml_machine_must_be_on_the_site_as_that_kind(tmp_path):
    text = config_path("sim", "plant.yaml").read_text()
    path = tmp_path / "plant.yaml"
    path.write_text(text.replace("ic120: machines/ic120.yaml", "ic120: machines/mst110cr.yaml"))
    with pytest.raises(SimConfigError, match=r"plant\.yaml:\d+: machines\.ic120: .*mst110cr\.yaml describes a "
                                             r"mst110cr, but 'ic120' is a ic120 on the site"):
        load_plant(path)


def test_malformed_plant_yaml_names_the_key(tmp_path):
    text = config_path("sim", "plant.yaml").read_text()
    for old, new, pattern in [
        ("step_s:", "step_x:", r"plant\.yaml:\d+: step_x: unknown key; expected one of \["),
        ("watchdog_s:", "watchdog_s: -1 #", r"plant\.yaml:\d+: watchdog_s: must be >= 0\.01, got -1"),
    ]:
        assert old in text
        path = tmp_path / "plant.yaml"
        path.write_text(text.replace(old, new, 1))
        with pytest.raises(SimConfigError, match=pattern):
            load_plant(path)


def test_truth_record_and_replay(spec, tmp_path):
    plant = Plant(spec)
    plant.carrier.set_centre_velocity(1.0, 0.2)
    plant.excavator.set_front_velocity({"swing_joint": 0.5})
    rec = TruthRecorder(tmp_path / "truth.jsonl", 0.1)
    PlantRunner(plant, None, speed=0.0, on_step=rec).run(duration=5.0)
    rec.close()
    final = (plant.carrier.base.x, plant.carrier.base.y, plant.excavator.front.q[0])
    log = TruthLog(tmp_path / "truth.jsonl")
    assert log.machines == ("zx200", "ic120")  # every machine of the plant, by name
    replayed = Plant(spec)
    PlantRunner(replayed, None, speed=0.0, replay=log).run(duration=log.duration)
    got = (replayed.carrier.base.x, replayed.carrier.base.y, replayed.excavator.front.q[0])
    assert got == pytest.approx(final, abs=0.11)
    assert replayed.carrier.base.x > spec.initial_poses["ic120"][0] + 2.0  # it really moved
    (tmp_path / "bad.jsonl").write_text('{"t": 0}\n')
    with pytest.raises(ReplayError, match=r"bad\.jsonl:1: not a truth record"):
        TruthLog(tmp_path / "bad.jsonl")
    kinds = Plant(load_plant(config_path("sim", "kinds_plant.yaml")))  # other machines than the log's
    with pytest.raises(ReplayError, match=r"truth\.jsonl: the log holds the machines \['ic120', 'zx200'\], the plant"):
        PlantRunner(kinds, None, speed=0.0, replay=log)


def test_plant_time_on_the_step_grid_and_stamps_carry_the_second(spec):
    """time = steps * dt (no drift), and a time a hair below a whole second is stamped as that second."""
    assert stamp_parts(2.99999999999998) == (3, 0)  # what 300 summed 0.01 steps gave: was stamped (2, 0)
    assert stamp_parts(2.9999999999999996) == (3, 0)
    assert stamp_parts(160.02) == (160, 20_000_000)
    assert stamp_parts(0.0) == (0, 0)
    last = (-1, 0)
    for n in range(1, 40_000):  # the 0.01 s step grid over 400 s: strictly increasing, exact
        st = stamp_parts(n * 0.01)
        assert st > last and st == (n // 100, (n % 100) * 10_000_000), (n, st)
        last = st
    plant = Plant(spec)
    for _ in range(300):
        plant.step()
    assert plant.steps == 300 and plant.time == 300 * plant.dt and stamp_parts(plant.time) == (3, 0)


class _WallClock:
    """A wall clock the runner's sleeps advance; a step costs ``step_s``, one step stalls ``stall_s``."""

    def __init__(self, step_s: float, stall_at: int, stall_s: float) -> None:
        self.t, self.step_s, self.stall_at, self.stall_s = 0.0, step_s, stall_at, stall_s

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s

    def on_step(self, plant: Plant) -> None:
        self.t += self.step_s + (self.stall_s if plant.steps == self.stall_at else 0.0)


@pytest.mark.parametrize(("catch_up_s", "lost_s"), [(0.0, 0.3), (0.1, 0.2), (0.5, 0.0)])
def test_paced_runner_makes_up_a_stall_within_catch_up_s(spec, catch_up_s, lost_s):
    """At 2x real time, a 0.3 s stall at step 50: the runner makes up at most ``catch_up_s`` of it by steps
    without sleep, and the rest shifts the schedule (wall time lost for good)."""
    plant = Plant(spec)
    clock = _WallClock(step_s=0.001, stall_at=50, stall_s=0.3)
    runner = PlantRunner(plant, None, speed=2.0, on_step=clock.on_step, catch_up_s=catch_up_s)
    runner._now, runner._sleep = clock.now, clock.sleep
    runner.run(duration=2.0)
    ideal = 2.0 / 2.0 - plant.dt / 2.0 + 0.001  # the last step starts at its deadline, then costs one step
    assert plant.steps == 200
    assert runner.wall_elapsed == pytest.approx(ideal + lost_s, abs=0.006)
    assert runner.late_steps >= 1


def test_paced_runner_refuses_a_negative_catch_up(spec):
    with pytest.raises(ValueError, match="catch_up_s must be >= 0"):
        PlantRunner(Plant(spec), None, speed=1.0, catch_up_s=-0.1)
