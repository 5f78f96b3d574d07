"""The original's DB boundary across processes: our writer and reader nodes, each its own process over DDS, driven
by a client built only on the original's types (tms_msg_db, sensor_msgs, geometry_msgs), as its nodes are; on the
embedded store and on a MongoDB server (the ``backend`` param)."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from tests.mongo_server import unique_database, with_database
from tests.rosproc import executable
from tests.tms_db.test_nodes import _call
from tms_db import open_store

pytestmark = pytest.mark.integration

PATH = {"model_name": "ic120", "record_name": "LOAD_PATH", "type": "dynamic",
        **{k: [0.0] for k in ("x", "y", "z", "qx", "qy", "qz")}, "qw": [1.0]}


@dataclass(frozen=True)
class Db:
    """Where the nodes' store is: the node parameter naming it, and how the test opens it."""

    param: str
    open: Callable


@pytest.fixture(params=["embedded", "mongodb"])
def backend(request: pytest.FixtureRequest, tmp_path) -> Iterator[Db]:
    if request.param == "embedded":
        yield Db(f"db_path:={tmp_path / 'db'}", lambda: open_store(path=tmp_path / "db"))
        return
    uri = with_database(request.getfixturevalue("mongodb_uri"), unique_database())
    yield Db(f"db_uri:={uri}", lambda: open_store(uri=uri))
    with open_store(uri=uri) as store:
        store._client.drop_database(store.database)  # test cleanup


def _node(name: str, db: Db, *params: str) -> list:
    args = [executable("tms_db", name), "--ros-args", "-p", db.param]
    for p in params:
        args += ["-p", p]
    return args


def _publisher(ros_node, msg_type, topic: str, proc):
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    pub = ros_node.create_publisher(msg_type, topic, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    _until(ros_node, lambda: pub.get_subscription_count() > 0, 30, f"a subscriber on {topic}", proc)
    return pub


def _until(ros_node, cond, timeout: float, what: str, proc=None):
    deadline = time.monotonic() + timeout
    while True:
        value = cond()
        if value:
            return value
        assert time.monotonic() < deadline, f"timed out waiting for {what}" + (f"\n{proc.output}" if proc else "")
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)


def _get_data(ros_node, client, kind: str, ident: int, name: str = "", latest_only: bool = False) -> list:
    from tms_msg_db.srv import TmsdbGetData

    reply = _call(ros_node, client, TmsdbGetData.Request(type=kind, id=ident, name=name, latest_only=latest_only))
    return [(m.time, m.type, m.id, m.name, json.loads(m.msg)) for m in reply.tmsdbs]


def test_tmsdb_written_and_read_back(procs, ros_node, backend) -> None:
    """``tms_db_data`` -> ``tms_db_writer`` -> store -> ``tms_db_reader`` (latest and history); a msg that is not
    JSON is refused naming topic and field and stores nothing; retention keeps the newest per collection."""
    from tms_msg_db.msg import Tmsdb
    from tms_msg_db.srv import TmsdbGetData

    db = backend
    writer = procs(_node("tms_db_writer", db, "retention_max_count:=3", "retention_period_s:=0.3"))
    reader = procs(_node("tms_db_reader", db))
    pub = _publisher(ros_node, Tmsdb, "/tms_db_data", writer)
    get = ros_node.create_client(TmsdbGetData, "/tms_db_reader")

    for second, name in ((2, "zx200"), (1, "zx200"), (3, "ic120")):
        pub.publish(Tmsdb(time=f"2025-06-01T10:00:0{second}.000000", type="machine_pose", id=3012, name=name,
                          msg=json.dumps({"pose": {"x": float(second)}})))
    pub.publish(Tmsdb(time="2025-06-01T10:00:04.000000", type="machine_pose", id=3012, name="zx200", msg="{x: 1"))
    for i in range(5):
        pub.publish(Tmsdb(time=f"2025-06-01T11:00:0{i}.000000", type="probe", id=1, name="p", msg=str(i)))

    history = _until(ros_node, lambda: len(rows := _get_data(ros_node, get, "machine_pose", 3012)) == 3 and rows,
                     30, "three machine_pose documents", writer)
    assert [(r[0][-9:-7], r[3], r[4]["pose"]["x"]) for r in history] == [
        ("01", "zx200", 1.0), ("02", "zx200", 2.0), ("03", "ic120", 3.0)]  # ascending by time
    assert history[0][1:3] == ("machine_pose", 3012)
    assert [r[4]["pose"]["x"] for r in _get_data(ros_node, get, "machine_pose", 3012, "zx200")] == [1.0, 2.0]
    latest = _get_data(ros_node, get, "machine_pose", 3012, "zx200", latest_only=True)
    assert [(r[0], r[4]) for r in latest] == [("2025-06-01T10:00:02.000000", {"pose": {"x": 2.0}})]
    assert _get_data(ros_node, get, "machine_pose", 99) == [] and _get_data(ros_node, get, "nothing", 1) == []

    assert writer.wait_for("/tms_db_data dropped: Tmsdb type 'machine_pose' id 3012 name 'zx200': field 'msg' is "
                           "not JSON", 10), writer.output
    # retention: of the five probes the newest three stay
    _until(ros_node, lambda: [r[4] for r in _get_data(ros_node, get, "probe", 1)] == [2, 3, 4], 30,
           "retention to keep the newest three probes", writer)
    assert writer.wait_for("retention: removed 2 documents of 'probe'", 10), writer.output
    assert _get_data(ros_node, get, "parameter", 1) == []  # not a data collection: refused, logged
    assert reader.wait_for("field 'type': 'parameter' is a reserved collection", 10), reader.output
    with db.open() as store:
        assert len(store.find_data("machine_pose", 3012)) == 3  # the bad one stored nothing
    assert writer.popen.poll() is None and reader.popen.poll() is None


def test_tmsdb_query_updates_records(procs, ros_node, backend) -> None:
    """``tms_db_param_data`` (TmsdbQuery) -> records, read back with ``tms_db_reader_parameter`` and the original's
    param reader; a query for a record that does not exist is refused naming it."""
    from tms_msg_db.msg import TmsdbQuery
    from tms_msg_db.srv import TmsdbGetData, TmsdbGetParameter

    db = backend
    with db.open() as store:
        store.upsert_parameter(PATH)
    writer = procs(_node("tms_db_writer_param", db))
    reader = procs(_node("tms_db_reader", db))
    param_reader = procs(_node("tms_db_reader_param", db))
    pub = _publisher(ros_node, TmsdbQuery, "/tms_db_param_data", writer)
    get_param = ros_node.create_client(TmsdbGetParameter, "/tms_db_reader_parameter")
    get_rec = ros_node.create_client(TmsdbGetData, "/tms_db_param_reader")

    def query(kind: str, record: str, vehicle: str, x: float, writemode: str = "", joints=()) -> TmsdbQuery:
        q = TmsdbQuery(type=kind, writemode=writemode, record_name=record, vehicle_name=vehicle)
        q.add_path.pose.position.x, q.add_path.pose.position.y, q.add_path.pose.orientation.w = x, 2.0 * x, 1.0
        q.add_joints.position = list(joints)
        return q

    def xs() -> list[str]:
        reply = _call(ros_node, get_param, TmsdbGetParameter.Request(model_name="ic120", record_name="LOAD_PATH"))
        return [v for k, v in zip(reply.keys, reply.values, strict=True) if k == "x"]

    pub.publish(query("pose_query", "LOAD_PATH", "ic120", 5.0))
    pub.publish(query("pose_query", "LOAD_PATH", "ic120", 6.0))
    _until(ros_node, lambda: xs() == ["0.0", "5.0", "6.0"], 30, "two appended waypoints", writer)
    pub.publish(query("pose_query", "LOAD_PATH", "ic120", 7.0, writemode="over_write"))
    _until(ros_node, lambda: xs() == ["7.0"], 30, "the over-written waypoints", writer)
    pub.publish(query("joint", "dig_pose", "zx200", 0.0, joints=[0.1, 0.2, 0.3, 0.4, 0.5]))
    pub.publish(query("pose_query", "NO_SUCH_PATH", "ic120", 1.0))
    pub.publish(query("joint", "short", "zx200", 0.0, joints=[0.1]))
    assert writer.wait_for("/tms_db_param_data dropped: record 'NO_SUCH_PATH' of model 'ic120' not found", 20), \
        writer.output
    assert writer.wait_for("/tms_db_param_data dropped: record 'short' (vehicle 'zx200'): field "
                           "'add_joints.position': 1 values", 20), writer.output

    reply = _call(ros_node, get_rec, TmsdbGetData.Request(type="parameter", flgorparam="param",
                                                          recordnames=["LOAD_PATH", "dig_pose", "NO_SUCH_PATH"]))
    assert [(m.name, m.type) for m in reply.tmsdbs] == [("LOAD_PATH", "dynamic"), ("dig_pose", "static")]
    pose = json.loads(reply.tmsdbs[0].msg)
    assert pose["x"] == [7.0] and pose["y"] == [14.0] and pose["qw"] == [1.0] and pose["Release_Count"] == []
    assert param_reader.wait_for("record 'NO_SUCH_PATH' not found", 10), param_reader.output
    reply = _call(ros_node, get_rec, TmsdbGetData.Request(type="parameter", flgorparam="flg", name="dig_pose"))
    flg = json.loads(reply.tmsdbs[0].msg)
    assert flg["trajectory"] == 1 and flg["bucket_end_joint"] == 0.5 and flg["model_name"] == "zx200"
    with db.open() as store:
        assert {d["record_name"] for d in store.list_parameters()} == {"LOAD_PATH", "dig_pose"}  # nothing else
    assert all(p.popen.poll() is None for p in (writer, reader, param_reader))


def _action(ros_node, client, goal, timeout: float = 120.0, server=None):
    # 60 s: a loaded CI machine once took over 30 s to discover the reader's server
    assert client.wait_for_server(timeout_sec=60), (
        "action server not available" + (f"; its output:\n{server.output}" if server is not None else ""))
    sent = client.send_goal_async(goal)
    handle = _until(ros_node, lambda: sent.done() and sent.result(), timeout, "goal acceptance")
    assert handle.accepted
    done = handle.get_result_async()
    _until(ros_node, done.done, timeout, "the action's result")
    return done.result(), bytes(handle.goal_id.uuid)


def _feedback_of(ros_node, seen: list, goal_id: bytes, count: int) -> list:
    """The goal's feedback messages, read from the feedback topic: rclpy's ActionClient drops feedback that arrives
    after the result (a topic and a service: either can come first), so its feedback_callback may miss the last."""
    _until(ros_node, lambda: len(mine := [f.feedback for f in seen if bytes(f.goal_id.uuid) == goal_id]) >= count
           and mine, 60, f"{count} feedback message(s)")
    return [f.feedback for f in seen if bytes(f.goal_id.uuid) == goal_id]


def test_gridfs_put_and_get_10mb(procs, ros_node, tmp_path, backend) -> None:
    """A 10 MB file (``static``) and a 10 MB point cloud (``dynamic``) through ``tms_db_gridfs_data`` and back
    intact through the ``tms_db_reader_gridfs`` action; a file that does not exist and one over the store's limit are
    refused naming topic and field, nothing stored, the big file left in place."""
    import numpy as np
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from sensor_msgs.msg import PointCloud2, PointField

    from tms_msg_db.action import TmsdbGridFS as GridFSAction
    from tms_msg_db.msg import TmsdbGridFS

    db = backend
    limit = 40_000_000
    writer = procs(_node("tms_db_writer_gridfs", db, f"max_blob_bytes:={limit}"))
    reader = procs(_node("tms_db_reader_gridfs", db))
    pub = _publisher(ros_node, TmsdbGridFS, "/tms_db_gridfs_data", writer)
    client = ActionClient(ros_node, GridFSAction, "/tms_db_reader_gridfs")
    seen: list = []
    ros_node.create_subscription(GridFSAction.Impl.FeedbackMessage, "/tms_db_reader_gridfs/_action/feedback",
                                 seen.append, 10)

    rng = np.random.default_rng(7)
    payload = rng.integers(0, 256, 10 * 1024 * 1024, dtype=np.uint8).tobytes()
    terrain = tmp_path / "terrain.ply"
    terrain.write_bytes(payload)
    big = tmp_path / "too_big.bin"
    with open(big, "wb") as f:
        f.truncate(limit + 1)
    pub.publish(TmsdbGridFS(time="2025-06-01T10:00:00.000000", type="static", id=2, filename=str(terrain)))
    pub.publish(TmsdbGridFS(time="2025-06-01T10:00:01.000000", type="static", id=2, filename=str(tmp_path / "no.ply")))
    pub.publish(TmsdbGridFS(time="2025-06-01T10:00:02.000000", type="dem", id=2, filename=str(big)))
    assert writer.wait_for("stored static", 60), writer.output
    assert not terrain.exists()  # handed over to the DB, as the original removes it
    assert writer.wait_for(f"/tms_db_gridfs_data dropped: type 'static': field 'filename': cannot read "
                           f"'{tmp_path / 'no.ply'}': No such file", 30), writer.output
    assert writer.wait_for(f"/tms_db_gridfs_data dropped: type 'dem': field 'filename': blob '{big}': "
                           f"{limit + 1:,} bytes, over the store's limit of {limit:,}", 30), writer.output
    assert big.exists() and os.path.getsize(big) == limit + 1

    result, _ = _action(ros_node, client, GridFSAction.Goal(type="static", filename=str(terrain)), server=reader)
    assert result.status == GoalStatus.STATUS_SUCCEEDED and result.result.result, result.result.msg
    assert terrain.read_bytes() == payload

    cloud = PointCloud2(height=1, width=len(payload) // 16, point_step=16, row_step=len(payload), is_dense=True,
                        fields=[PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                                for i, n in enumerate(("x", "y", "z", "intensity"))])
    cloud.data = payload
    pub.publish(TmsdbGridFS(time="2025-06-01T10:00:03.000000", type="dynamic", id=3, pointcloud2=cloud))
    small = PointCloud2(height=1, width=1, point_step=16, row_step=16, fields=cloud.fields)
    small.data = bytes(range(16))
    pub.publish(TmsdbGridFS(time="2025-06-01T09:00:00.000000", type="dynamic", id=3, pointcloud2=small))
    assert writer.wait_for("stored dynamic (cloud) time '2025-06-01T09", 120), writer.output
    assert writer.wait_for("stored dynamic (cloud) time '2025-06-01T10", 120), writer.output

    result, goal_id = _action(ros_node, client, GridFSAction.Goal(type="dynamic", latest_only=True))
    got = result.result.pointcloud2
    assert result.status == GoalStatus.STATUS_SUCCEEDED and result.result.result, result.result.msg
    assert bytes(got.data) == payload and (got.width, got.point_step, got.row_step) == (cloud.width, 16, len(payload))
    assert [(f.name, f.offset, f.datatype) for f in got.fields] == [(f.name, f.offset, f.datatype)
                                                                   for f in cloud.fields]
    feedback = _feedback_of(ros_node, seen, goal_id, 1)
    assert got.header.frame_id == "map" and got.is_dense and len(feedback) == 1
    assert bytes(feedback[0].pointcloud2.data) == payload
    result, goal_id = _action(ros_node, client, GridFSAction.Goal(type="dynamic", latest_only=False))
    feedback = _feedback_of(ros_node, seen, goal_id, 2)
    assert [f.msg for f in feedback] == ["2025-06-01T09:00:00.000000", "2025-06-01T10:00:03.000000"]  # by time
    assert bytes(feedback[0].pointcloud2.data) == bytes(range(16)) and bytes(result.result.pointcloud2.data) == payload

    result, _ = _action(ros_node, client, GridFSAction.Goal(type="mesh", filename=str(terrain)))
    assert result.status == GoalStatus.STATUS_ABORTED and not result.result.result
    assert result.result.msg == f"no 'mesh' blob with filename {str(terrain)!r}"
    with db.open() as store:
        assert [(m["type"], m["length"]) for m in store.find_blobs({"type": "static"})] == [("static", len(payload))]
        assert store.find_blobs({"type": "dem"}) == []
    assert writer.popen.poll() is None and reader.popen.poll() is None


def test_collision_writer(procs, ros_node, tmp_path, backend) -> None:
    from tms_msg_db.msg import TmsdbCollision

    db = backend
    writer = procs(_node("tms_db_writer_collision", db))
    pub = _publisher(ros_node, TmsdbCollision, "/tms_db_collision", writer)
    mesh = tmp_path / "dump_area.stl"
    mesh.write_bytes(b"solid dump_area\n" * 100)
    pub.publish(TmsdbCollision(model_name="zx200", type="static", filepath=str(mesh)))
    pub.publish(TmsdbCollision(model_name="zx200", type="static", filepath=str(tmp_path / "none.stl")))
    assert writer.wait_for("stored", 30) and writer.wait_for("field 'filepath': cannot read", 30), writer.output
    with db.open() as store:
        doc = store.get_parameter("zx200", "collision_object_dump_area")
        assert doc["data"] == mesh.read_bytes() and (doc["x"], doc["qw"], doc["type"]) == (8.0, 1.0, "static")
        assert len(store.list_parameters()) == 1
    assert writer.popen.poll() is None
