"""Node tms_sp_sensing as a real process: clouds and poses over DDS in, flags and targets in the on-disk DB."""

from __future__ import annotations

import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from tests.rosproc import executable
from tests.tms_sp.treeutil import ROOT
from tms_sp import synthetic as syn
from tms_sp.config import load_sensing_config
from tms_sp.errors import SensingError
from tms_sp.pointcloud import FLOAT32, xyz_from_cloud

CFG = load_sensing_config()


def _cloud_fields(points: np.ndarray, frame: str = "map"):
    """PointCloud2 field values for xyz float32 points plus a padding field (as LiDAR drivers add)."""
    n = len(points)
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    rec["x"], rec["y"], rec["z"] = points[:, 0], points[:, 1], points[:, 2]
    return dict(height=1, width=n, point_step=16, row_step=16 * n, is_bigendian=False, is_dense=True,
                data=rec.tobytes(), frame=frame)


def test_pointcloud_decoding_and_errors():
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.5]])
    f = _cloud_fields(pts)
    fields = [
        SimpleNamespace(name=n, offset=o, datatype=FLOAT32, count=1)
        for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))
    ]
    msg = SimpleNamespace(fields=fields, **{k: v for k, v in f.items() if k != "frame"})
    assert np.allclose(xyz_from_cloud(msg), pts)
    msg.fields = fields[:2]
    with pytest.raises(SensingError, match=r"mound: PointCloud2 needs fields x, y, z"):
        xyz_from_cloud(msg, topic="mound")
    msg.fields = fields
    msg.data = msg.data[:20]
    with pytest.raises(SensingError, match=r"20 bytes for 2 points of 16 bytes"):
        xyz_from_cloud(msg)


def _to_msg(points: np.ndarray, frame: str):
    from sensor_msgs.msg import PointCloud2, PointField

    f = _cloud_fields(points, frame)
    msg = PointCloud2()
    msg.header.frame_id = f.pop("frame")
    msg.fields = [PointField(name=n, offset=o, datatype=PointField.FLOAT32, count=1)
                  for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))]
    for k, v in f.items():
        setattr(msg, k, v)
    return msg


def _seeded_db(path):
    from tms_db import open_store
    from tms_db.cli import seed

    store = open_store(path=path)
    seed(store, ROOT / "config" / "seeds" / "paper.yaml")
    return store


@pytest.mark.integration
def test_sensing_node_writes_flags_and_targets(procs, ros_node, tmp_path):
    from geometry_msgs.msg import PoseStamped

    db = tmp_path / "db"
    store = _seeded_db(db)
    before = store.get_parameter("zx200", "target_excavate_pose")
    node = procs([executable("tms_sp", "tms_sp_sensing"), "--ros-args", "-p", f"db_path:={db}", "-p", "rate_hz:=4.0"])
    mound_pub = ros_node.create_publisher(type(_to_msg(np.zeros((1, 3)), "map")), "/sim/sensors/mound/points", 2)
    vessel_pub = ros_node.create_publisher(
        type(_to_msg(np.zeros((1, 3)), "map")), "/sim/sensors/ic120/vessel_points", 2
    )
    pose_pub = ros_node.create_publisher(PoseStamped, "/sim/truth/ic120/pose", 10)
    rng = np.random.default_rng(0)
    m = CFG.mound
    g = CFG.mound_grid
    # A mound already dug at its near top: the target must move off the seeded value.
    surface = syn.dig_pit(syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height), 5.8, 0.0, 1.0, 1.0)
    mound = _to_msg(syn.scan(surface, (g.x_min, g.x_max), (g.y_min, g.y_max), 20000, rng), "map")
    vg = CFG.vessel_geom
    vs = vg.grid_spec(CFG.resolution)
    heap = syn.vessel_heap(0.9 * vg.capacity, vg.inner_length, vg.inner_width)
    vessel = _to_msg(syn.scan(heap, (vs.x_min, vs.x_max), (vs.y_min, vs.y_max), 5000, rng, noise=0.01), "ic120/vessel")
    p1 = CFG.points["P1"]
    deadline = time.monotonic() + 60.0
    flags = {}
    while time.monotonic() < deadline:
        pose = PoseStamped()
        pose.header.frame_id = "map"
        pose.header.stamp = ros_node.get_clock().now().to_msg()
        pose.pose.position.x, pose.pose.position.y = p1.x + 0.1, p1.y
        pose.pose.orientation.z, pose.pose.orientation.w = math.sin(p1.yaw / 2), math.cos(p1.yaw / 2)
        pose_pub.publish(pose)
        mound_pub.publish(mound)
        vessel_pub.publish(vessel)
        ros_node.executor_for_test.spin_once(timeout_sec=0.2)
        flags = store.get_record(CFG.blackboard_records[0])
        if flags["SENSING_ARRIVAL_FLG"] and flags["SENSING_LOADED_FLG"]:
            break
        assert node.popen.poll() is None, node.output
    assert flags["SENSING_ARRIVAL_FLG"] is True, node.output
    assert flags["SENSING_LOADED_FLG"] is True
    assert flags["SENSING_CHECK_MOUND_FLG"] is False  # Table 7: false = enough soil in the mound
    target = store.get_parameter("zx200", "target_excavate_pose")
    assert math.hypot(target["x"] - before["x"], target["y"] - before["y"]) > 0.5  # moved off the pit
    assert target["position_with_angle"] == 1 and "timestamps" in target
    angle = store.get_parameter("zx200", "release_angle")["target_angle"]
    assert 1.2 < angle < 1.9  # towards the vessel at P1, on the ZX200's left


@pytest.mark.integration
def test_sensing_node_refuses_an_unseeded_db(procs, tmp_path):
    from tms_db import open_store

    open_store(path=tmp_path / "empty").close()
    node = procs([executable("tms_sp", "tms_sp_sensing"), "--ros-args", "-p", f"db_path:={tmp_path / 'empty'}"])
    assert node.popen.wait(timeout=60) == 2  # a deliberate error (tms_common.node.run_node): one line, exit 2
    assert node.wait_for("seed it first", 10.0), node.output
    assert "GLOBAL_BLACKBOARD_EARTHWORK" in node.output and "Traceback" not in node.output, node.output


@pytest.mark.integration
def test_sensing_node_refuses_a_target_fill_out_of_range(procs, tmp_path):
    db = tmp_path / "db"
    _seeded_db(db).close()
    node = procs([executable("tms_sp", "tms_sp_sensing"), "--ros-args", "-p", f"db_path:={db}",
                  "-p", "target_fill:=2.0"])
    assert node.popen.wait(timeout=60) == 2, node.output
    assert node.wait_for("parameter target_fill", 10.0), node.output
    assert "(0, 1.5]" in node.output and "Traceback" not in node.output, node.output
