"""The running ``sim_plant`` process driven only over COM3 CAN (udp_multicast by default).

Step responses of every ZX200 joint, velocity and position limits, the 500 ms command watchdog,
out-of-range frames ignored and counted, GNSS back to the truth, and soil conservation over a
scripted dig-load-dump.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64MultiArray

from sim_bridge.config import load_plant
from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
from sim_bridge.sensors import Gnss
from tms_model.geometry import Pose2D, yaw_from_quaternion
from tms_sp.arrival import ArrivalDetector
from tms_sp.config import load_sensing_config

pytestmark = pytest.mark.integration

SPEC = load_plant()
ZX = SPEC.description(SPEC.excavator)  # the descriptions of the machines the peers command
IC = SPEC.description(SPEC.carrier)
FIELD = {"swing_joint": "swing", "boom_joint": "boom", "arm_joint": "arm", "bucket_joint": "bucket"}


def _settle_lag(joint: str) -> float:
    """Dead time + 4 spool time constants + 1 s for the oil column and the links' inertia to settle (the plant's
    dynamics, sim_bridge.physics; the valve alone would be within 2 % after dead time + 4 tau)."""
    j = ZX.drives[joint]
    return j.dead_time + 4.0 * j.time_constant + 1.0


def test_step_velocity_reaches_command_within_lag_and_stops_at_limits(start_plant, ros_node):
    # the front in the air (the paper's initial pose): from the home pose the bucket starts in the mound, and the
    # soil's cutting resistance slows the crowd and the curl until they leave it
    plant = start_plant(speed=1.0, front={"swing_joint": 0.0, "boom_joint": -0.9, "arm_joint": 1.8,
                                          "bucket_joint": 1.2})
    zx = plant.zx200
    zx.get("Front_Angle")
    # Frame arrival (wall) -> simulated time through /clock: a loaded machine runs the plant below real
    # time, and the lags under test are simulated-time properties.
    clock: list[tuple[float, float]] = []
    ros_node.create_subscription(
        Clock, "/clock", lambda m: clock.append((time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)), 100
    )
    deadline = time.monotonic() + 30
    while len(clock) < 5 and time.monotonic() < deadline:
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    assert clock, "no /clock from sim_plant"

    def sim_at(wall: float) -> float:
        walls, sims = zip(*clock, strict=True)
        return float(np.interp(wall, walls, sims))

    # Boom up (-), arm crowd (+), bucket curl (+), swing, within their limits and together within the pumps' flow and
    # power at the start pose (a faster swing start takes the pumps to relief pressure and slows every function:
    # tests/sim_bridge/test_physics.py).
    cmd = {"boom_joint": -0.08, "arm_joint": 0.15, "bucket_joint": 0.2, "swing_joint": 0.3}
    expect = dict(cmd)
    t0 = time.monotonic()
    zx.command("Velocity_Cmd_1", **{f"{FIELD[j]}_target_anguler_velocity": v for j, v in cmd.items()})
    reached: dict[str, float] = {}  # wall time of the first frame at speed
    moved: dict[str, float] = {}
    deadline = t0 + 60
    while time.monotonic() < deadline and len(reached) < 4:
        for t, name, values in list(zx.history):
            if name != "Front_Angular_Velocity" or t < t0:
                continue
            for j, target in expect.items():
                v = values[f"{FIELD[j]}_relative_angular_velocity"]
                if j not in moved and abs(v) > 0.02:  # a commanded motion, not the oil columns settling
                    moved[j] = t
                if j not in reached and abs(v - target) <= 0.03 * abs(target):
                    reached[j] = t
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    for _ in range(5):  # /clock samples past the last frame, so the interpolation does not clamp
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    assert set(reached) == set(expect), f"not reached: {set(expect) - set(reached)}; moved {moved}"
    s0 = sim_at(t0)
    for j in expect:
        lag = _settle_lag(j)
        moved_s, reached_s = sim_at(moved[j]) - s0, sim_at(reached[j]) - s0
        # no motion during most of the dead time; at speed within the configured lag (+0.3 s: command
        # transit and the 10 ms frame period, in simulated time)
        assert moved_s >= 0.6 * ZX.drives[j].dead_time, (j, moved_s)
        assert reached_s <= lag + 0.3, (j, reached_s, lag)
    # Keep commanding: boom, arm and bucket end at their position limits with zero velocity.
    limits = {"boom_joint": ZX.joint("boom_joint").lower, "arm_joint": ZX.joint("arm_joint").upper,
              "bucket_joint": ZX.joint("bucket_joint").upper}

    def at_limits(_values: dict[str, float]) -> bool:
        a, w = zx.get("Front_Angle"), zx.get("Front_Angular_Velocity")
        return all(
            # the stroke's end stop holds the joint within the oil column's give (mm of rod; near full curl the bucket
            # linkage's small ratio turns that into up to 0.03 rad)
            abs(a[f"{FIELD[j]}_relative_angle"] - lim) < 0.03
            and abs(w[f"{FIELD[j]}_relative_angular_velocity"]) < 0.003
            for j, lim in limits.items()
        )

    assert zx.wait_until("Front_Angle", at_limits, timeout=30) is not None, zx.get("Front_Angle")


def test_watchdog_brings_machine_to_rest_when_commands_stop(start_plant):
    plant = start_plant(speed=1.0)
    ic = plant.ic120
    ic.command("Velocity_Cmd", target_travel_center_velocity=0.8)
    assert ic.wait_until("Track_Velocity", lambda v: v["left_track_velocity"] > 0.78, timeout=20) is not None
    assert ic.get("Machine_State")["control_state"] == 0  # commanded
    t_stop = time.monotonic()
    ic.silence()
    t_rest = ic.wait_until(
        "Track_Velocity", lambda v: abs(v["left_track_velocity"]) < 0.002 and abs(v["right_track_velocity"]) < 0.002,
        timeout=20,
    )
    assert t_rest is not None, ic.get("Track_Velocity")
    tracks = IC.track_drive
    # watchdog 0.5 s + dead time + lag to 0.25% of 0.8 m/s (6 tau), with 1 s of scheduling slack
    assert t_rest - t_stop <= SPEC.watchdog_s + tracks.dead_time + 6 * tracks.time_constant + 1.0
    assert t_rest - t_stop >= SPEC.watchdog_s  # not before the watchdog expired
    assert ic.wait_until("Machine_State", lambda v: v["control_state"] == 1, timeout=5) is not None


def test_out_of_range_command_frame_is_ignored_and_counted(start_plant, ros_node):
    plant = start_plant(speed=1.0)
    zx = plant.zx200
    before = zx.get("Front_Angle")
    frame_id = zx.codec.frame_id("Velocity_Cmd_1")
    # raw 0xFFFF on every field = +16.7675 rad/s, above the DBC maximum of 16 rad/s
    for _ in range(20):
        zx.send_raw(frame_id, bytes([0xFF] * 8))
        time.sleep(0.01)
    counts: dict[str, int] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            if st.name == "sim_plant/zx200":
                counts.update({kv.key: int(kv.value) for kv in st.values})

    ros_node.create_subscription(DiagnosticArray, "/sim/diagnostics", on_diag, 10)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and counts.get("ignored_out_of_range", 0) < 20:
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)
    assert counts.get("ignored_out_of_range") == 20, counts
    time.sleep(1.5)  # longer than any dead time: a wrongly applied frame would move the joints
    after = zx.get("Front_Angle")
    assert after == pytest.approx(before, abs=1e-3)


def test_gnss_converts_back_to_truth_within_noise(start_plant, ros_node):
    plant = start_plant(speed=1.0)
    truth: dict[str, PoseStamped] = {}
    for m in ("zx200", "ic120"):
        ros_node.create_subscription(
            PoseStamped, f"/sim/truth/{m}/pose", lambda msg, m=m: truth.__setitem__(m, msg), 10
        )
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and len(truth) < 2:
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)
    assert len(truth) == 2
    gnss = Gnss(SPEC.site)
    tol = 5 * SPEC.sensors.gnss_sigma_h
    errors = []
    for _ in range(10):
        lat = plant.ic120.get("GNSS_Latitude")["latitude"]
        lon = plant.ic120.get("GNSS_Longitude")["longitude"]
        alt = plant.ic120.get("GNSS_Altitude_Status")["altitude"]
        x, y, _z = gnss.geodetic_to_map(lat, lon, alt)
        p = truth["ic120"].pose.position
        errors.append(math.hypot(x - p.x, y - p.y))
        time.sleep(0.1)
    assert max(errors) < tol, errors
    assert max(errors) > 0.0  # the fix is noisy, not the truth itself
    # ZX200: swing-centre plane coordinates (x = easting, y = northing) vs the truth base + swing origin
    e = plant.zx200.get("Swing_Center_Position_1")["swing_center_position_x"]
    n = plant.zx200.get("Swing_Center_Position_2")["swing_center_position_y"]
    p = truth["zx200"].pose.position
    ox, oy, _ = ZX.joint("swing_joint").origin_xyz
    assert e - SPEC.site.origin_plane[0] == pytest.approx(p.x + ox, abs=tol)
    assert n - SPEC.site.origin_plane[1] == pytest.approx(p.y + oy, abs=tol)


def test_soil_conserved_over_scripted_dig_load_dump_over_can(start_plant, ros_node):
    plant = start_plant(speed=2.0, ic120_pose="P1")
    zx, ic = plant.zx200, plant.ic120
    soil: list[list[float]] = []
    ros_node.create_subscription(Float64MultiArray, "/sim/truth/soil", lambda m: soil.append(list(m.data)), 10)

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ros_node.executor_for_test.spin_once(timeout_sec=0.02)

    deadline = time.monotonic() + 30
    while not soil and time.monotonic() < deadline:
        spin(0.1)
    assert soil, "no /sim/truth/soil"
    initial = soil[-1]
    for target in DIG_CYCLE:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline:
            a = zx.get("Front_Angle")
            q = {j: a[f"{FIELD[j]}_relative_angle"] for j in FIELD}
            if pose_reached(q, target):
                break
            v = servo_velocity(q, target)
            zx.command("Velocity_Cmd_1", **{f"{FIELD[j]}_target_anguler_velocity": v[j] for j in FIELD})
            spin(0.02)
        zx.command("Velocity_Cmd_1")  # neutral
        spin(1.0)
    # Let the release finish (a loaded machine runs the plant slower than the wall clock): wait until the
    # vessel load has not changed for 1 s of samples.
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        before = soil[-1][2]
        spin(1.0)
        if abs(soil[-1][2] - before) < 1e-6:
            break
    vessel_after_load = soil[-1][2]
    assert vessel_after_load > 0.5, soil[-1]
    ic.command("Vessel_Cmd", target_vessel_angle=IC.vessel.max_angle, vessel_control_enable=1)
    end = time.monotonic() + 40
    while time.monotonic() < end and soil[-1][2] > 1e-6:
        spin(0.2)
    ic.command("Vessel_Cmd", target_vessel_angle=0.0, vessel_control_enable=1)
    spin(1.0)
    mound, bucket, vessel, dumped, _err, ground = soil[-1]
    assert vessel == pytest.approx(0.0, abs=1e-6)
    assert dumped == pytest.approx(vessel_after_load, rel=0.01)
    # All soil on the ground (the dump pile included) + bucket + vessel is conserved; the mound lost
    # what was dumped elsewhere (it counts only the mound's own area).
    total0 = initial[5] + initial[1] + initial[2]
    assert ground + bucket + vessel == pytest.approx(total0, rel=0.01)
    assert mound <= initial[0] - dumped + 0.05, (mound, initial[0], dumped)  # (spills at P1 are not mound either)
    assert ground > mound + 0.9 * dumped, (ground, mound, dumped)  # the dump pile lies outside the mound


def test_truth_stamps_and_clock_never_go_back_so_arrival_holds_at_p1(start_plant, ros_node):
    """IC120 parked at P1: /sim/truth/ic120/pose and /clock stamps rise by one period across whole seconds.

    The node once split ``int(t)`` off the accumulated plant time and wrapped the rounded nanoseconds:
    3.0 s (summed as 2.99999999999998) was stamped 2.000, 0.95 s back, at every whole second of
    3-17 s, 44-72 s and from 160 s on. tms_sp's arrival detector takes a stamp going back as a sim
    reset, so SENSING_ARRIVAL_FLG fell at every such second while the IC120 stood at P1 (demo of
    08:20, 160-357 s).
    """
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    poses: list[tuple[int, int, float, float, float]] = []
    clock: list[tuple[int, int]] = []

    def on_pose(m: PoseStamped) -> None:
        q = m.pose.orientation
        poses.append((m.header.stamp.sec, m.header.stamp.nanosec, m.pose.position.x, m.pose.position.y,
                       yaw_from_quaternion(q)))

    ros_node.create_subscription(PoseStamped, "/sim/truth/ic120/pose", on_pose, qos)
    ros_node.create_subscription(Clock, "/clock", lambda m: clock.append((m.clock.sec, m.clock.nanosec)), qos)
    start_plant(speed=2.0, ic120_pose="P1", clock_period_s=0.02)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (poses and poses[-1][0] >= 9):
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    assert poses and poses[-1][0] >= 9, f"truth poses up to {poses[-1][:2] if poses else None}"
    stamps = [s + ns * 1e-9 for s, ns, *_ in poses]
    whole = [t for t in stamps if 3.0 <= t and abs(t - round(t)) < 1e-6]
    assert len(whole) >= 3, f"too few whole-second samples from 3 s on: {stamps[:3]} .. {stamps[-3:]}"
    steps = [(b - a, a, b) for a, b in zip(stamps, stamps[1:], strict=False)]
    back = [(a, b) for d, a, b in steps if d <= 0.0]
    assert not back, f"truth pose stamp went back: {back[:5]}"
    # one truth period apart (a multiple where DDS dropped a sample under load: keep-last 10 publisher);
    # the first pose goes out after the first step (0.01 s), the next on the 0.05 s grid
    grid = [d for d, a, _ in steps if a >= 0.05 - 1e-9]
    assert all(abs(d / 0.05 - round(d / 0.05)) < 1e-4 for d in grid), sorted({round(d, 9) for d in grid})
    clock_t = [s + ns * 1e-9 for s, ns in clock]
    clock_back = [(a, b) for a, b in zip(clock_t, clock_t[1:], strict=False) if b <= a]
    assert len(clock_t) > 100 and not clock_back, f"/clock went back: {clock_back[:5]}"
    # The symptom: the arrival flag on these poses (config/tms_sp/sensing.yaml) rises once and stays up.
    cfg = load_sensing_config()
    det = ArrivalDetector(cfg.points[cfg.arrival_point], cfg.arrival)
    flags = [(t, det.update(t, Pose2D(x, y, yaw))) for t, (_s, _ns, x, y, yaw) in zip(stamps, poses, strict=True)]
    rises = [t for (_, a), (t, b) in zip(flags, flags[1:], strict=False) if b and not a]
    falls = [t for (_, a), (t, b) in zip(flags, flags[1:], strict=False) if a and not b]
    assert len(rises) == 1 and not falls, f"SENSING_ARRIVAL_FLG rose at {rises}, fell at {falls}"


def test_mound_scanned_at_its_own_period_vessels_at_theirs(start_plant, ros_node):
    """``mound_scan_period_s`` 2.0 beside ``scan_period_s`` 0.5: over 8 s of simulated time the vessel cloud
    comes every 0.5 s and the mound cloud every 2 s (the fleet scans its mound less often: fleet.yaml)."""
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    stamps: dict[str, list[float]] = {"mound": [], "vessel": []}
    for key, topic in (("mound", "/sim/sensors/mound/points"), ("vessel", "/sim/sensors/ic120/vessel_points")):
        ros_node.create_subscription(
            PointCloud2, topic,
            lambda m, key=key: stamps[key].append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9), qos)
    start_plant(speed=2.0, scan_period_s=0.5, mound_scan_period_s=2.0)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (stamps["vessel"] and stamps["vessel"][-1] >= 8.0):
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    assert stamps["vessel"] and stamps["vessel"][-1] >= 8.0, stamps
    # the first scan goes out at the first plant step (one step after 0), the next ones on the period's grid
    gaps = {key: sorted({round(b - a, 6) for a, b in zip(s[1:], s[2:], strict=False)}) for key, s in stamps.items()}
    assert all(abs(t / 0.5 - round(t / 0.5)) < 1e-6 for t in stamps["vessel"][1:]), stamps["vessel"]
    assert gaps["vessel"] == [0.5], gaps
    assert gaps["mound"] == [2.0] and len(stamps["mound"]) >= 4, (gaps, stamps["mound"])
