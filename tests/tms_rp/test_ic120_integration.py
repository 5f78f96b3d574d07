"""IC120 over the MuJoCo plant and COM3 CAN: sim_plant + com3_bridge + our nodes as separate processes.

GNSS faults (outage, 5 m jump) are injected at the ROS layer: the localisation node reads a relayed
``gnss/fix_in`` that the test feeds from the bridge's ``gnss/fix`` (dropped or shifted).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from tests.rosutil import ActionCall, Truth, pose_stamped, spin_for, spin_until, yaw_of
from tests.tracked_stack import start_ours, start_plant_and_bridge
from tms_common.config import config_path, load_yaml

pytestmark = pytest.mark.integration


def _plant_config(tmp_path, gnss_sigma: float) -> str:
    data, _ = load_yaml(config_path("sim", "plant.yaml"))
    data["sensors"]["gnss_sigma_h"] = gnss_sigma
    import yaml

    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _wait_for_estimate(node) -> None:
    from nav_msgs.msg import Odometry

    got = []
    sub = node.create_subscription(Odometry, "/ic120/odometry/global", got.append, 10)
    assert spin_until(node, lambda: len(got) > 20, 90.0), "no odometry/global from ic120_localization"
    node.destroy_subscription(sub)
    spin_for(node, 2.0)


def test_localization_over_can_rms_outage_and_jump(procs, domain, ros_node, tmp_path):
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import NavSatFix

    start_plant_and_bridge(procs, domain, extra_plant=["-p", f"config:={_plant_config(tmp_path, 0.02)}"])
    # compared at the estimate's stamp (com3_bridge's wall clock at the odometry frame) with the truth
    # re-timed to wall clock (sim stamp + least delivery delay): this process being starved on the loaded
    # 2-core machine does not turn into apparent error
    extra = ["-p", f"nav_config:={os.environ['IC120_NAV_CONFIG']}"] if os.environ.get("IC120_NAV_CONFIG") else []
    nodes = start_ours(procs, nodes=("ic120_localization",), params=["-r", "gnss/fix:=gnss/fix_in", *extra])
    loc = nodes["ic120_localization"]
    node = ros_node
    truth = Truth(node)
    phase = {"name": "normal"}
    est: list[tuple[float, str, float, float, float, float]] = []
    est_recv: list[float] = []  # wall receive times (for IC120_DUMP analysis)
    relay = node.create_publisher(NavSatFix, "/ic120/gnss/fix_in", 10)
    dlat = 5.0 / 111_000.0  # about 5 m north

    def on_fix(m: NavSatFix) -> None:
        if phase["name"] == "outage":
            return
        if phase["name"] == "jump":
            m.latitude += dlat
        relay.publish(m)

    def on_est(m: Odometry) -> None:
        p = m.pose.pose
        est_recv.append(time.time())
        est.append(
            (
                m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                phase["name"],
                p.position.x,
                p.position.y,
                yaw_of(p.orientation),
                m.pose.covariance[0] + m.pose.covariance[7],
            )
        )

    node.create_subscription(NavSatFix, "/ic120/gnss/fix", on_fix, 50)
    node.create_subscription(Odometry, "/ic120/odometry/global", on_est, 50)
    assert spin_until(node, lambda: len(est) > 20 and len(truth.poses) > 20, 60.0), loc.output
    cmd = node.create_publisher(Twist, "/ic120/cmd_vel", 10)
    schedule = [(8.0, "normal"), (10.0, "outage"), (6.0, "settle"), (3.0, "jump"), (6.0, "after")]
    for duration, name in schedule:
        phase["name"] = name
        t_end = time.monotonic() + duration
        while time.monotonic() < t_end:
            tw = Twist()
            tw.linear.x, tw.angular.z = 0.6, 0.12
            cmd.publish(tw)
            spin_for(node, 0.1)
    cmd.publish(Twist())
    errors: dict[str, list[float]] = {}
    covs: dict[str, list[float]] = {}
    series = truth.wall_series(window=0.5)  # short: a loaded plant runs below real time, the offset drifts
    for t, name, x, y, _yaw, cov in est:
        tr = truth.at(t, series=series)
        if tr is not None:
            errors.setdefault(name, []).append(math.hypot(x - tr[0], y - tr[1]))
            covs.setdefault(name, []).append(cov)
    if os.environ.get("IC120_DUMP"):
        np.savez(os.environ["IC120_DUMP"], est=np.array([e[:1] + e[2:] for e in est]), truth=np.array(truth.poses),
                 phase=np.array([e[1] for e in est]), est_recv=np.array(est_recv),
                 truth_stamped=np.array(truth.stamped), truth_recv=np.array(truth.recv_wall))
    moving = errors["normal"][len(errors["normal"]) // 3:] + errors["after"]
    rms = math.sqrt(float(np.mean(np.square(moving))))
    print(f"localisation over CAN: RMS {rms * 100:.2f} cm (n={len(moving)}), outage max {max(errors['outage']):.3f} m, "
          f"jump max {max(errors['jump']):.3f} m, cov trace {covs['outage'][0]:.2e} -> {covs['outage'][-1]:.2e}")
    dist = sum(math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in zip(truth.stamped, truth.stamped[1:], strict=False))
    # 33 s at 0.6 m/s is 20 m in real time; a plant slowed by a loaded machine drives less in the same wall time
    assert dist > 5.0, "the plant did not drive"
    # goals 5 cm / 0.5 m (see README for measured figures); margins for a heavily loaded shared machine
    # gross-failure guards (a broken filter or a leaked jump is metres off); the 5 cm goal is measured by
    # tests/bench/bench_ic120.py, since CPU starvation on a loaded machine shows up as apparent error here
    assert rms < 0.20
    assert max(errors["outage"]) < 1.0
    assert covs["outage"][-1] > 3.0 * covs["outage"][0]
    assert max(errors["jump"]) < 0.5, "the 5 m jump leaked into the estimate"
    assert "GNSS outlier rejected" in loc.output


def test_navigation_and_vessel_over_can(procs, domain, ros_node):
    """Clients on the peers' types only: Nav2's NavigateThroughPoses, OPERA com3_msgs' SetDumpAngle."""
    from com3_msgs.action import SetDumpAngle
    from nav2_msgs.action import NavigateThroughPoses
    from tests.tms_rp.harness import site_points
    from tms_rp.tracked.config import load_nav_config

    start_plant_and_bridge(procs, domain)
    ours = start_ours(procs)
    node = ros_node
    truth = Truth(node)
    pts = site_points()
    goal = NavigateThroughPoses.Goal()
    goal.poses = [pose_stamped(*pts["P2"]), pose_stamped(*pts["P1"])]
    _wait_for_estimate(node)
    call = ActionCall(node, NavigateThroughPoses, "/ic120/navigate_through_poses", goal)
    status, result = call.wait(240.0)
    x, y, yaw = truth.last
    e_xy = math.hypot(x - pts["P1"][0], y - pts["P1"][1])
    e_yaw = abs((yaw - pts["P1"][2] + math.pi) % (2 * math.pi) - math.pi)
    print(f"P1 over CAN: error {e_xy:.3f} m, {e_yaw:.3f} rad; result {result.error_code} {result.error_msg!r}")
    assert status == 4 and result.error_code == 0, result.error_msg  # STATUS_SUCCEEDED
    assert e_xy < 0.2 and e_yaw < 0.1
    tr = np.array([p[1:] for p in truth.poses])
    costmap = load_nav_config(machine="ic120").build_costmap()
    assert not costmap.footprint_hits(tr[:, 0], tr[:, 1], tr[:, 2]).any(), "footprint touched the mound or the ZX200"
    moving = np.hypot(np.diff(tr[:, 0]), np.diff(tr[:, 1])) > 1e-3
    heading = np.column_stack([np.cos(tr[1:, 2]), np.sin(tr[1:, 2])])
    along = (np.diff(tr[:, :2], axis=0) * heading).sum(axis=1)
    assert (along[moving] < 0).mean() > 0.9, "P1 was not reached in reverse"
    fb = call.feedback
    assert fb and fb[0].distance_remaining > fb[-1].distance_remaining
    assert {f.number_of_poses_remaining for f in fb} >= {1, 2}
    # vessel: raise to 40 deg, then lower
    for target in (math.radians(40.0), 0.0):
        g = SetDumpAngle.Goal()
        g.target_angle = target
        vcall = ActionCall(node, SetDumpAngle, "/ic120/set_dump_angle", g)
        status, result = vcall.wait(60.0)
        assert status == 4 and result.success, ours["ic120_vessel"].output[-2000:]

        def vessel_truth() -> float | None:
            return truth.joints.get("vessel_joint", truth.joints.get(next(iter(truth.joints), ""), None))

        # The plant's truth topic can trail the converter's state frames the controller judged by when
        # the machine is loaded (seen: a 2.28 deg reading right after SUCCEEDED at load 30): wait for it.
        spin_until(
            node, lambda t=target: (v := vessel_truth()) is not None and abs(abs(v) - t) < math.radians(2.0), 5.0
        )
        vessel = vessel_truth()
        assert vessel is not None
        assert abs(abs(vessel) - target) < math.radians(2.0), f"vessel truth {vessel} vs target {target}"
        assert vcall.feedback
    g = SetDumpAngle.Goal()
    g.target_angle = 2.0  # above the 65 deg limit
    status, result = ActionCall(node, SetDumpAngle, "/ic120/set_dump_angle", g).wait(10.0)
    assert status == 6 and not result.success  # STATUS_ABORTED
    # the peer's result carries no reason: the server's log names the value and the range
    assert spin_until(
        node, lambda: "FAILED" in ours["ic120_vessel"].output and "outside" in ours["ic120_vessel"].output, 5.0
    ), ours["ic120_vessel"].output[-2000:]


def test_bad_goals_blocked_path_and_cancel_over_can(procs, domain, ros_node):
    """A NavigateToPose client on nav2_msgs only: failures carry the codes a Nav2 jazzy navigator reports (the
    planner's ComputePathToPose codes), a good goal drives the IC120 there, a cancel ends with it at rest."""
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from nav2_msgs.action import NavigateToPose
    from tms_rp.tracked.config import load_nav_config

    start_plant_and_bridge(procs, domain)
    ours = start_ours(procs, nodes=("ic120_localization", "ic120_navigator"))
    node = ros_node
    truth = Truth(node)
    _wait_for_estimate(node)

    def nav(x, y, yaw, timeout=20.0, qz=None, qw=None):
        g = NavigateToPose.Goal()
        g.pose = pose_stamped(x, y, yaw)
        if qz is not None:
            g.pose.pose.orientation.z, g.pose.pose.orientation.w = qz, qw
        return ActionCall(node, NavigateToPose, "/ic120/navigate_to_pose", g)

    unknown, goal_outside_map, goal_occupied, no_valid_path = 200, 204, 206, 208  # nav2_msgs ComputePathToPose
    cases = [
        ((float("nan"), 10.0, 0.0), unknown, "not finite"),
        ((30.0, 10.0, 0.0, 20.0, 0.0, 0.0), unknown, "zero quaternion"),
        ((6.5, 0.0, 0.0), goal_occupied, "inside an obstacle"),
        ((90.0, 10.0, 0.0), goal_outside_map, "outside the map"),
    ]
    for args, code, text in cases:
        status, result = nav(*args).wait(20.0)
        assert status == 6 and result.error_code == code and text in result.error_msg, (args, result.error_msg)
    # unreachable: a new map with a wall across the site
    cm = load_nav_config(machine="ic120").build_costmap()
    grid = cm.map.grid.copy()
    c0 = cm.map.world_to_cell(33.0, 0.0)[1]
    grid[:, c0:c0 + 10] = 100
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    map_pub = node.create_publisher(OccupancyGrid, "/ic120/map", latched)

    def publish(g: np.ndarray) -> None:
        m = OccupancyGrid()
        m.header.frame_id = "map"
        m.info.resolution = cm.map.resolution
        m.info.width, m.info.height = g.shape[1], g.shape[0]
        m.info.origin.position.x, m.info.origin.position.y = cm.map.origin
        m.info.origin.orientation.w = 1.0
        m.data = g.ravel().astype(int).tolist()
        map_pub.publish(m)

    publish(grid)
    assert spin_until(node, lambda: "map updated" in ours["ic120_navigator"].output, 20.0)
    status, result = nav(40.0, 10.0, 0.0).wait(30.0)
    assert status == 6 and result.error_code == no_valid_path and "unreachable" in result.error_msg
    # blocked while driving: restore the map, drive east, then drop a block on the straight line
    publish(cm.map.grid.copy())
    spin_for(node, 1.0)
    call = nav(36.0, 10.0, 0.0)
    spin_for(node, 3.0)
    grid = cm.map.grid.copy()
    r0, c0 = cm.map.world_to_cell(30.0, 9.0)
    grid[r0:r0 + 20, c0:c0 + 15] = 100
    publish(grid)
    status, result = call.wait(120.0)
    assert status == 4, result.error_msg
    assert max(f.number_of_recoveries for f in call.feedback) >= 1, "no replan reported"
    x, y, _ = truth.last
    assert math.hypot(x - 36.0, y - 10.0) < 0.2
    # cancel: the machine is at rest when CANCELED arrives
    call = nav(22.0, 10.0, math.pi)
    spin_for(node, 6.0)
    call.cancel()
    status, result = call.wait(20.0)
    assert status == 5  # STATUS_CANCELED
    t_cancel = time.monotonic()
    spin_for(node, 0.3)
    recent = [p for p in truth.poses if t_cancel - 0.3 <= p[0] <= t_cancel + 0.3]
    moved = (
        max(math.hypot(b[1] - a[1], b[2] - a[2]) for a, b in zip(recent, recent[1:], strict=False))
        if len(recent) > 1
        else 0.0
    )
    assert moved < 0.02 * 0.1, f"still moving at {moved / 0.05:.3f} m/s when CANCELED arrived"
