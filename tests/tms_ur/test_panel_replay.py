"""Replay into the 3-D view: a short live run recorded (real processes over DDS: ``tms_sp_tf`` turns this test's
odometry into /tf, ``tms_ur_recorder`` writes it into a rosbag2 MCAP directory and is stopped with SIGINT), then
``tms_ur_panel`` started with ``replay:=<bag>``; headless Chromium moves the view to recorded log times and the view
shows the poses recorded at those times, with their stamps. Seeking back rebuilds the view from the recording's
start."""

from __future__ import annotations

import math
import signal
import time

import numpy as np
import pytest
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2, PointField

from tests.rosproc import executable
from tests.tms_ur.conftest import free_port
from tms_model.fleet import load_named
from tms_model.transform import quaternion_from_axis_angle
from tms_model.urdf import machine_tree
from tms_sp.config import load_sensing_config
from tms_ur.recording import read_bag

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]

MACHINES = ["zx200", "ic120"]
SCAN = "/sim/sensors/mound/points"
GRID = load_sensing_config().mound_grid
HOLE = (GRID.x_min + 0.3 * (GRID.x_max - GRID.x_min), GRID.y_min + 0.5 * (GRID.y_max - GRID.y_min))  # dug out


def _scan(dug: bool) -> PointCloud2:
    """The mound region as a scan: 1.0 m high, and 0.4 m where the second scan finds it dug (a 2 m square)."""
    xs, ys = np.meshgrid(np.arange(GRID.x_min + 0.05, GRID.x_max, 0.1), np.arange(GRID.y_min + 0.05, GRID.y_max, 0.1))
    z = np.full(xs.shape, 1.0)
    if dug:
        z[(abs(xs - HOLE[0]) < 1.0) & (abs(ys - HOLE[1]) < 1.0)] = 0.4
    pts = np.stack([xs.ravel(), ys.ravel(), z.ravel()], axis=1).astype("<f4")
    msg = PointCloud2()
    msg.header.frame_id = "map"
    msg.height, msg.width = 1, len(pts)
    msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")]
    msg.is_bigendian, msg.point_step, msg.row_step, msg.is_dense = False, 12, 12 * len(pts), True
    msg.data = pts.tobytes()
    return msg
BASE_FRAMES = {machine_tree(load_named(m)).frame("base_link"): m for m in MACHINES}


def _spin(node, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        node.executor_for_test.spin_once(timeout_sec=0.02)


def _odom(frame: str, stamp: float, x: float, y: float, yaw: float) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(stamp), int(round((stamp % 1) * 1e9))
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    q = quaternion_from_axis_angle((0.0, 0.0, 1.0), yaw)
    o = msg.pose.pose.orientation
    o.x, o.y, o.z, o.w = q
    return msg


def _record(procs, ros_node, tmp_path):
    """Drive both machines along known paths for ~4 s while ``tms_ur_recorder`` records /tf and /tf_static, and two
    mound scans: the whole mound first, then with a hole dug."""
    tf = procs([executable("tms_sp", "tms_sp_tf"), "--ros-args", "-p",
                f"machines:={MACHINES!r}".replace("'", '"')])
    assert tf.wait_for("tms_sp_tf ready", timeout=60), tf.output
    bag = tmp_path / "bag"
    rec = procs([executable("tms_ur", "tms_ur_recorder"), "--ros-args", "-p", f"output:={bag}",
                 "-p", f'topics:=["/tf", "/tf_static", "{SCAN}"]'])
    pubs = {m: ros_node.create_publisher(Odometry, f"/{m}/odom_pose", 10) for m in MACHINES}
    scan_pub = ros_node.create_publisher(PointCloud2, SCAN, 2)
    deadline = time.monotonic() + 60
    # the recorder subscribes once its graph poll sees tms_sp_tf's publishers
    while time.monotonic() < deadline and not (
            all(p.get_subscription_count() > 0 for p in pubs.values()) and ros_node.count_subscribers("/tf") > 0
            and scan_pub.get_subscription_count() > 0):
        _spin(ros_node, 0.2)
    assert ros_node.count_subscribers("/tf") > 0, rec.output
    _spin(ros_node, 1.0)
    for i in range(40):
        stamp = 100.0 + 0.1 * i
        pubs["zx200"].publish(_odom("map", stamp, 10.0 + 0.05 * i, 5.0, 0.02 * i))
        pubs["ic120"].publish(_odom("map", stamp, 30.0, 8.0 + 0.1 * i, -0.01 * i))
        if i in (5, 30):
            scan_pub.publish(_scan(dug=i == 30))
        _spin(ros_node, 0.1)
    _spin(ros_node, 1.0)
    rec.signal(signal.SIGINT)  # the recorder closes the bag on SIGINT
    assert rec.wait(30) is not None, rec.output
    tf.kill()
    assert (bag / "metadata.yaml").is_file(), rec.output
    return bag


def _replay_view(procs, page, bag, tmp_path):
    """``tms_ur_panel`` replaying ``bag``, and the browser page on its 3-D view with the time slider shown."""
    port = free_port()
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", f"port:={port}",
                   "-p", f"db_path:={tmp_path / 'db'}", "-p", f"replay:={bag}",
                   "-p", f"machines:={MACHINES!r}".replace("'", '"')])
    assert panel.wait_for("serving http://127.0.0.1", timeout=60), panel.output
    page.goto(f"http://127.0.0.1:{port}/3d")
    page.wait_for_selector("#conn.ok", timeout=30000)
    page.wait_for_selector("#replay.on", timeout=30000)  # the time slider is shown in replay
    return panel, page


def test_the_view_shows_the_recorded_poses_at_the_recorded_times(procs, ros_node, browser_page, tmp_path):
    bag = _record(procs, ros_node, tmp_path)
    # the recorded base_link edges, by log time: what the view must show when moved to that time
    recorded = []  # (log_time_ns, child frame, stamp, x, y)
    for m in read_bag(bag, topics=["/tf"]):
        for t in m.msg.transforms:
            if t.child_frame_id in BASE_FRAMES:
                stamp = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9
                recorded.append((m.log_time_ns, t.child_frame_id, stamp, t.transform.translation.x,
                                 t.transform.translation.y))
    assert len(recorded) >= 40, f"only {len(recorded)} base_link transforms recorded"
    panel, page = _replay_view(procs, browser_page, bag, tmp_path)
    page.wait_for_function(f"{MACHINES}.every(n => window.site3d.loaded(n))", timeout=30000)
    # later, earlier (a seek back), then the middle: each time the newest recorded pose at or before the time
    picks = [recorded[int(len(recorded) * f)] for f in (0.8, 0.2, 0.5)]
    for log_ns, frame, stamp, x, y in picks:
        machine = BASE_FRAMES[frame]
        # 1 us after the log time: a double of ~1.8e9 s resolves only ~0.24 us (messages are 0.1 s apart)
        page.evaluate(f"window.site3dReplay({{seek: {log_ns * 1e-9 + 1e-6!r}, play: false}})")
        try:
            page.wait_for_function(f"Math.abs(window.site3d.stamp({machine!r}) - {stamp!r}) < 1e-6", timeout=15000)
        except Exception:  # noqa: BLE001 - playwright's TimeoutError: fail with what the page shows
            shown = page.evaluate(f"[window.site3d.stamp({machine!r}), document.querySelector('#replay-t').innerText]")
            pytest.fail(f"{machine}: the view shows {shown}, expected stamp {stamp} at log time {log_ns}:\n"
                        + panel.output[-3000:])
        links = page.evaluate(f"window.site3d.links({machine!r})")
        m = links[frame]
        assert math.hypot(m[12] - x, m[13] - y) < 0.01, (machine, stamp, m[12:14], (x, y))
    shown = page.inner_text("#replay-t")
    assert "/" in shown, shown
    # play runs the replay on: the stamp shown moves forward
    page.evaluate(f"window.site3dReplay({{seek: {recorded[0][0] * 1e-9!r}, play: true}})")
    first = recorded[0][2]
    page.wait_for_function(f"window.site3d.stamp('zx200') > {first + 1.0!r}", timeout=20000)


def test_the_view_replays_the_terrain_of_the_recorded_scans(procs, ros_node, browser_page, tmp_path):
    bag = _record(procs, ros_node, tmp_path)
    scans = [m.log_time_ns for m in read_bag(bag, topics=[SCAN])]
    assert len(scans) == 2, scans
    panel, page = _replay_view(procs, browser_page, bag, tmp_path)
    beside = (HOLE[0] + 3.0, HOLE[1])
    # after the first scan, before the second: the whole mound; after the second: the hole; back: the mound again
    for log_ns, hole_z in ((scans[0], 1.0), (scans[1], 0.4), (scans[0], 1.0)):
        page.evaluate(f"window.site3dReplay({{seek: {log_ns * 1e-9 + 1e-6!r}, play: false}})")
        try:
            page.wait_for_function(f"Math.abs(window.site3d.heightAt({HOLE[0]!r}, {HOLE[1]!r}) - {hole_z}) < 0.05",
                                   timeout=15000)
        except Exception:  # noqa: BLE001 - playwright's TimeoutError: fail with what the page shows
            shown = page.evaluate(f"window.site3d.heightAt({HOLE[0]!r}, {HOLE[1]!r})")
            pytest.fail(f"terrain at the hole {shown}, expected {hole_z} at log time {log_ns}:\n"
                        + panel.output[-3000:])
        assert abs(page.evaluate(f"window.site3d.heightAt({beside[0]!r}, {beside[1]!r})") - 1.0) < 0.05
    assert page.evaluate("window.site3d.terrainLayers().map(l => l.kind)") == ["dynamic"]
