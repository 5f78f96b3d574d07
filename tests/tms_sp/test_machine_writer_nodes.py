"""``tms_sp_machine`` -> ``/tms_db_data`` -> ``tms_db_writer`` -> ``tms_db_reader``, each its own process over DDS:
two machines' joints, odometry and pose appear as the original's machine_joints / machine_pose documents."""

from __future__ import annotations

import json

import pytest

from tests.rosproc import executable
from tests.tms_db.test_boundary_nodes import _get_data, _publisher, _until

pytestmark = pytest.mark.integration


def test_machine_states_of_two_machines_reach_the_db(procs, ros_node, tmp_path) -> None:
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState

    from tms_msg_db.srv import TmsdbGetData

    db = tmp_path / "db"
    writer = procs([executable("tms_db", "tms_db_writer"), "--ros-args", "-p", f"db_path:={db}"])
    reader = procs([executable("tms_db", "tms_db_reader"), "--ros-args", "-p", f"db_path:={db}"])
    machine = procs([executable("tms_sp", "tms_sp_machine"), "--ros-args", "-p", "machines:=[zx200, ic120_1]",
                     "-p", "rate_hz:=4.0", "-p", "pose_topic:=pose"])
    assert machine.wait_for("tms_sp_machine ready: 6 inputs", 30), machine.output
    joints = _publisher(ros_node, JointState, "/zx200/joint_states", machine)
    odom = _publisher(ros_node, Odometry, "/ic120_1/odometry/global", machine)
    pose = _publisher(ros_node, PoseStamped, "/zx200/pose", machine)
    get = ros_node.create_client(TmsdbGetData, "/tms_db_reader")

    sent = 0

    def publish_some() -> None:
        nonlocal sent
        sent += 1
        joints.publish(JointState(name=["swing_joint", "boom_joint"], position=[0.01 * sent, -0.5]))
        o = Odometry(child_frame_id="ic120_1_tf/base_link")
        o.header.frame_id, o.pose.pose.position.x = "map", 10.0 + sent
        odom.publish(o)
        p = PoseStamped()
        p.header.frame_id, p.pose.position.y = "map", 3.0
        pose.publish(p)

    def latest(kind: str, name: str) -> list:
        publish_some()
        return _get_data(ros_node, get, kind, 3012, name, latest_only=True)

    zx_joints = _until(ros_node, lambda: latest("machine_joints", "zx200"), 30, "zx200's joints in the DB", writer)
    ic_pose = _until(ros_node, lambda: latest("machine_pose", "ic120_1"), 30, "ic120_1's odometry in the DB", writer)
    time_text, kind, ident, name, msg = zx_joints[0]
    assert (kind, ident, name) == ("machine_joints", 3012, "zx200") and time_text[10] == "T" and len(time_text) == 26
    assert set(msg) == {"header", "name", "position", "velocity", "effort"}
    assert msg["name"] == ["swing_joint", "boom_joint"] and msg["position"][1] == -0.5
    odom_doc = ic_pose[0][4]
    assert odom_doc["child_frame_id"] == "ic120_1_tf/base_link" and odom_doc["pose"]["pose"]["position"]["x"] > 10.0
    assert len(odom_doc["pose"]["covariance"]) == 36
    zx_pose = _until(ros_node, lambda: [r for r in _get_data(ros_node, get, "machine_pose", 3012, "zx200")
                                        if "child_frame_id" not in r[4]], 30, "zx200's PoseStamped in the DB")
    assert zx_pose[0][4]["pose"]["position"]["y"] == 3.0 and set(zx_pose[0][4]) == {"header", "pose"}
    assert _get_data(ros_node, get, "machine_joints", 3012, "ic120_1") == []  # nothing was published for it

    # 4 Hz: many more messages than documents
    for _ in range(60):
        publish_some()
        ros_node.executor_for_test.spin_once(timeout_sec=0.01)
    stored = _get_data(ros_node, get, "machine_joints", 3012, "zx200")
    assert 0 < len(stored) < sent / 2, (len(stored), sent)
    assert [r[0] for r in stored] == sorted(r[0] for r in stored)
    assert all(p.popen.poll() is None for p in (writer, reader, machine))
    assert "dropped" not in writer.output, writer.output
    json.dumps(stored)  # plain values only
