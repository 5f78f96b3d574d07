"""``tms_ur_db_writer`` across processes: the original's pose-write service and topic reach the DB through
tms_db's parameter writer (``tms_db_param_data``); a write it refuses answers ``written: false`` and stores nothing."""

from __future__ import annotations

import pytest

from tests.rosproc import executable
from tests.tms_db.test_boundary_nodes import _until
from tests.tms_db.test_nodes import _call
from tms_db import RecordNotFound, open_store

pytestmark = pytest.mark.integration

PATH = {"model_name": "ic120", "record_name": "LOAD_PATH", "type": "dynamic",
        **{k: [0.0] for k in ("x", "y", "z", "qx", "qy", "qz")}, "qw": [1.0]}


def test_pose_writes_reach_the_db_through_the_parameter_writer(procs, ros_node, tmp_path) -> None:
    from tms_msg_ur.msg import TmsdbPoseWriteMsg
    from tms_msg_ur.srv import TmsdbTerrainDBPoseWriteSrv

    db = tmp_path / "db"
    with open_store(path=db) as store:
        store.upsert_parameter(PATH)
    ros = ["--ros-args", "-p", f"db_path:={db}"]
    ui = procs([executable("tms_ur", "tms_ur_db_writer")], name="ui_writer")
    assert ui.wait_for("tms_ur_db_writer ready", 60), ui.output
    client = ros_node.create_client(TmsdbTerrainDBPoseWriteSrv, "/input/DB_machine/data")
    _until(ros_node, lambda: client.service_is_ready(), 30, "the pose-write service", ui)

    def record(model: str, name: str) -> dict | None:
        with open_store(path=db) as store:
            try:
                return store.get_parameter(model, name)
            except RecordNotFound:
                return None

    def request(record_type: str, record: str, x: float, target: str = "", joints=()):
        r = TmsdbTerrainDBPoseWriteSrv.Request(record_type=record_type, machine_name="ic120", record_name=record,
                                               write_target=target)
        r.pose.pose.position.x, r.pose.pose.orientation.w = x, 1.0
        r.joints.position = list(joints)
        return r

    # with no parameter writer the query would reach no one: refused, not "written"
    lost = _call(ros_node, client, request("pose_query", "LOAD_PATH", 4.0))
    assert not lost.written and "no parameter writer subscribes to tms_db_param_data" in lost.log_data

    writer = procs([executable("tms_db", "tms_db_writer_param"), *ros], name="param_writer")
    # the writer's own publisher must have matched, not only this test's view of the graph
    assert ui.wait_for("tms_db_param_data: 1 parameter writer(s) subscribed", 30), ui.output
    reply = _call(ros_node, client, request("pose_query", "LOAD_PATH", 4.0))
    assert reply.written and "pose_query ic120/LOAD_PATH" in reply.log_data
    _until(ros_node, lambda: record("ic120", "LOAD_PATH")["x"] == [0.0, 4.0], 30,
           "the appended waypoint", writer)
    reply = _call(ros_node, client, request("pose_query", "LOAD_PATH", 9.0, target="over_write"))
    assert reply.written
    _until(ros_node, lambda: record("ic120", "LOAD_PATH")["x"] == [9.0], 30,
           "the over-written path", writer)

    refused = _call(ros_node, client, request("joint", "dig_pose", 0.0, joints=[0.1, 0.2]))
    assert not refused.written and "joints: 2 positions" in refused.log_data
    assert ui.wait_for("/input/DB_machine/data: refused, nothing written: joints: 2 positions", 10), ui.output

    # the topic path: a joint write of five positions becomes a static joint record
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    pub = ros_node.create_publisher(TmsdbPoseWriteMsg, "/input/WriteDB/pose_joint",
                                    QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    _until(ros_node, lambda: pub.get_subscription_count() > 0, 30, "the pose-write topic", ui)
    msg = TmsdbPoseWriteMsg(record_type="joint", machine_name="zx200", record_name="dig_pose")
    msg.joints.position = [0.1, 0.2, 0.3, 0.4, 0.5]
    pub.publish(msg)

    rec = _until(ros_node, lambda: record("zx200", "dig_pose"), 30, "the joint record", writer)
    assert (rec["type"], rec["trajectory"], rec["boom_joint"], rec["bucket_end_joint"]) == ("static", 1, 0.2, 0.5)
    assert all(p.popen.poll() is None for p in (writer, ui))
