"""The original's DB boundary without ROS (tms_db.boundary) against a real store (both backends)."""

from __future__ import annotations

import json

import pytest

from tms_db import BlobTooLarge, RecordNotFound, StoreError, ValidationError, open_store
from tms_db import boundary as b

POSE = {"x": 1.5, "y": -2.0, "z": 0.25, "qx": 0.0, "qy": 0.0, "qz": 0.6, "qw": 0.8}
PATH = {"model_name": "ic120", "record_name": "LOAD_PATH", "type": "dynamic",
        **{k: [0.0] for k in ("x", "y", "z", "qx", "qy", "qz")}, "qw": [1.0]}


def test_data_document_round_trip(store) -> None:
    for t in ("2025-01-01T10:00:00.000002", "2025-01-01T10:00:00.000001", "2025-01-01T10:00:00.000003"):
        store.insert_data(b.data_document(t, "machine_pose", 3012, "zx200", json.dumps({"t": t, "v": [1, 2.5]})))
    store.insert_data(b.data_document("2025-01-01T10:00:00.000009", "machine_pose", 3012, "ic120", '{"t": 0}'))
    store.insert_data(b.data_document("2025-01-01T10:00:00.000010", "machine_pose", 7, "zx200", '{"t": 1}'))
    history = b.read_data(store, "machine_pose", 3012, "zx200", False)
    assert [r["time"][-1] for r in history] == ["1", "2", "3"]  # ascending by time, not by arrival
    assert history[0] == {"time": "2025-01-01T10:00:00.000001", "type": "machine_pose", "id": 3012, "name": "zx200",
                          "msg": json.dumps({"t": "2025-01-01T10:00:00.000001", "v": [1, 2.5]})}
    assert [r["name"] for r in b.read_data(store, "machine_pose", 3012, "", False)] == ["zx200"] * 3 + ["ic120"]
    latest = b.read_data(store, "machine_pose", 3012, "zx200", True)
    assert len(latest) == 1 and json.loads(latest[0]["msg"])["t"].endswith("03")
    assert b.read_data(store, "machine_pose", 3012, "nobody", True) == []
    assert b.read_data(store, "never_written", 1, "", False) == []


@pytest.mark.parametrize("text", ["{bad", "", "NaN", '{"a": Infinity}', "{'single': 1}"])
def test_data_document_msg_not_json(text: str) -> None:
    with pytest.raises(ValidationError, match="field 'msg' is not JSON") as exc:
        b.data_document("t", "machine_pose", 3012, "zx200", text)
    assert "'machine_pose' id 3012 name 'zx200'" in str(exc.value)


def test_data_reply_of_non_json_values() -> None:
    import datetime as dt

    from bson import ObjectId

    reply = b.data_reply({"time": "t", "type": "x", "id": 1, "name": "n",
                          "msg": {"when": dt.datetime(2025, 1, 2, tzinfo=dt.UTC), "oid": ObjectId("0" * 24),
                                  "blob": b"abc"}})
    assert json.loads(reply["msg"]) == {"when": "2025-01-02T00:00:00+00:00", "oid": "0" * 24, "blob": "<3 bytes>"}


def test_query_pose_and_joint_write_records(store) -> None:
    doc = b.apply_query(store, "pose", "", "P1", "ic120", POSE, [])
    assert {k: doc[k] for k in ("model_name", "x", "y", "qx", "qy", "qz", "qw")} == {
        "model_name": "ic120", "x": 1.5, "y": -2.0, "qx": 0.0, "qy": 0.0, "qz": 0.6, "qw": 0.8}
    assert "z" not in doc  # the original's pose write has no z
    b.apply_query(store, "pose", "", "P1", "ic120", {**POSE, "x": 9.0}, [])
    assert store.get_parameter("ic120", "P1")["x"] == 9.0  # replaced, not a second document
    assert len([d for d in store.list_parameters("ic120") if d["record_name"] == "P1"]) == 1
    doc = b.apply_query(store, "joint", "", "dig", "zx200", POSE, [0.1, 0.2, 0.3, 0.4, 0.5, 9.9])
    assert doc["type"] == "static" and doc["trajectory"] == 1
    assert [doc[k] for k in b.JOINT_FIELDS] == [0.1, 0.2, 0.3, 0.4, 0.5]


def test_query_pose_query_appends_and_overwrites(store) -> None:
    store.upsert_parameter(PATH)
    doc = b.apply_query(store, "pose_query", "", "LOAD_PATH", "ic120", POSE, [])
    assert doc["x"] == [0.0, 1.5] and doc["qw"] == [1.0, 0.8] and doc["z"] == [0.0, 0.25]  # flat numbers
    doc = b.apply_query(store, "pose_query", "add", "LOAD_PATH", "ic120", POSE, [])
    assert len(doc["qz"]) == 3
    doc = b.apply_query(store, "pose_query", "over_write", "LOAD_PATH", "ic120", POSE, [])
    assert {k: doc[k] for k in b.POSE_FIELDS} == {k: [v] for k, v in POSE.items()}
    assert store.get_parameter("ic120", "LOAD_PATH")["x"] == [1.5]


def test_query_refusals_store_nothing(store) -> None:
    store.upsert_parameter(PATH)
    before = store.list_parameters()
    with pytest.raises(RecordNotFound, match="record 'NO_SUCH_PATH'"):
        b.apply_query(store, "pose_query", "", "NO_SUCH_PATH", "ic120", POSE, [])
    with pytest.raises(RecordNotFound, match="record 'LOAD_PATH' of model 'zx200'"):
        b.apply_query(store, "pose_query", "", "LOAD_PATH", "zx200", POSE, [])
    with pytest.raises(ValidationError, match=r"field 'add_joints.position': 4 values"):
        b.apply_query(store, "joint", "", "dig", "zx200", POSE, [0.1, 0.2, 0.3, 0.4])
    with pytest.raises(ValidationError, match="field 'type': 'poses' is not a query type"):
        b.apply_query(store, "poses", "", "P1", "ic120", POSE, [])
    with pytest.raises(ValidationError, match=r"field 'add_path.pose.position.x': must be a finite number"):
        b.apply_query(store, "pose_query", "", "LOAD_PATH", "ic120", {**POSE, "x": float("nan")}, [])
    with pytest.raises(ValidationError, match="field 'record_name'"):
        b.apply_query(store, "pose", "", "", "ic120", POSE, [])
    assert store.list_parameters() == before


def test_query_pose_query_append_is_the_stores_atomic_append(store) -> None:
    """The append is ``Store.append_fields`` (one atomic update; tests/tms_db/test_concurrency.py has the processes
    racing), with the refusals it always gave: a missing record, a field that holds no array (naming the vehicle)."""
    store.upsert_parameter(PATH)
    calls = []
    append = store.append_fields

    def spy(*args, **kwargs):
        calls.append((args, kwargs))
        return append(*args, **kwargs)

    store.append_fields = spy
    doc = b.apply_query(store, "pose_query", "", "LOAD_PATH", "", POSE, [])  # no vehicle: by record alone
    assert calls == [(("LOAD_PATH", POSE), {"model_name": None})]
    assert {k: doc[k] for k in b.POSE_FIELDS} == {k: [PATH[k][0], v] for k, v in POSE.items()}
    assert doc == store.get_parameter("ic120", "LOAD_PATH")
    b.apply_query(store, "pose_query", "over_write", "LOAD_PATH", "ic120", POSE, [])
    assert len(calls) == 1  # over_write sets one-element arrays, no append
    b.apply_query(store, "pose", "", "P1", "ic120", POSE, [])  # scalar x, y, q*: no waypoint arrays
    before = store.list_parameters()
    with pytest.raises(ValidationError, match=r"^record 'P1' \(vehicle 'ic120'\): field 'x': holds 1.5, not an array "
                                              "to append to$"):
        b.apply_query(store, "pose_query", "", "P1", "ic120", POSE, [])
    with pytest.raises(ValidationError, match=r"^record 'P1': field 'x': holds 1.5, not an array to append to$"):
        b.apply_query(store, "pose_query", "add", "P1", "", POSE, [])
    with pytest.raises(RecordNotFound, match=r"^record 'NO_SUCH_PATH' of model 'ic120' not found in collection "
                                             "'parameter'$"):
        b.apply_query(store, "pose_query", "", "NO_SUCH_PATH", "ic120", POSE, [])
    assert store.list_parameters() == before


def test_param_reader_param_and_flg(store) -> None:
    store.upsert_parameter({**PATH, "Release_Count": [2]})
    store.upsert_parameter({"record_name": "GLOBAL_BB", "type": "global", "LOCK_FLG": True, "N": 3})
    found, problems = b.param_replies(store, "parameter", "param", "", ["LOAD_PATH", "MISSING", "GLOBAL_BB"])
    assert problems == ["record 'MISSING' not found in 'parameter'"]
    assert [(r["name"], r["type"]) for r in found] == [("LOAD_PATH", "dynamic"), ("GLOBAL_BB", "global")]
    assert json.loads(found[0]["msg"]) == {**{k: PATH[k] for k in b.POSE_FIELDS}, "Release_Count": [2]}
    assert json.loads(found[1]["msg"]) == {**{k: [] for k in b.POSE_FIELDS}, "Release_Count": []}
    found, problems = b.param_replies(store, "parameter", "flg", "GLOBAL_BB", [])
    msg = json.loads(found[0]["msg"])
    assert problems == [] and msg["LOCK_FLG"] is True and msg["N"] == 3 and isinstance(msg["_id"], str)
    assert "type" not in msg and "record_name" not in msg
    assert b.param_replies(store, "parameter", "both", "GLOBAL_BB", [])[1] == [
        "field 'flgorparam': 'both' is neither 'param' nor 'flg'"]
    assert b.param_replies(store, "task", "flg", "GLOBAL_BB", [])[0] == []
    assert b.param_replies(store, "parameter", "flg", "", [])[1] == [
        "neither field 'name' nor 'recordnames' names a record"]


def test_cloud_text_matches_the_original() -> None:
    data = bytes([0, 1, 9, 10, 99, 100, 255])
    assert b.encode_cloud_data(data) == ",".join(str(i) for i in data).encode()  # the original's writer
    assert b.decode_cloud_data(b.encode_cloud_data(data), "w") == data
    assert b.decode_cloud_data(b"", "w") == b""
    for bad in (b"1,2,x", b"1,,2", b"1,256", b"-1,2", b"1.5,2"):
        with pytest.raises(ValidationError, match="blob 7"):
            b.decode_cloud_data(bad, "blob 7")


def test_point_field_repr_is_parsed_not_evaluated() -> None:
    from sensor_msgs.msg import PointField

    spec = b.PointFieldSpec("intensity", 12, 7, 1)
    original = repr(PointField(name="intensity", offset=12, datatype=7, count=1))  # what the original stores
    assert b.field_repr(spec) == original
    assert b.parse_field_repr(original, "w") == spec
    for bad in ("__import__('os').system('true')", "PointField(1, 2)", "PointField(name=open('x'))", "x = 1"):
        with pytest.raises(ValidationError, match="field 'fields'"):
            b.parse_field_repr(bad, "w")


def test_gridfs_file_put_get_and_removal(store, tmp_path) -> None:
    path = tmp_path / "terrain.ply"
    payload = bytes(range(256)) * 1000
    path.write_bytes(payload)
    file_id = b.put_gridfs(store, "static", 4, "2025-01-01T00:00:00.000000", str(path), None)
    assert not path.exists()  # handed over, as the original removes it
    meta, data = b.read_file_blob(store, "static", str(path))
    assert meta["_id"] == file_id and data == payload and (meta["type"], meta["id"]) == ("static", 4)
    path.write_bytes(b"newer")
    b.put_gridfs(store, "static", 4, "2025-01-01T00:00:01.000000", str(path), None, remove_file=False)
    assert path.read_bytes() == b"newer"  # remove_file false: kept
    assert b.read_file_blob(store, "static", str(path))[1] == b"newer"
    with pytest.raises(RecordNotFound, match="no 'mesh' blob with filename"):
        b.read_file_blob(store, "mesh", str(path))


def test_gridfs_refusals_store_nothing_and_keep_the_file(tmp_path) -> None:
    with open_store(path=tmp_path / "db", max_blob_bytes=1000) as store:
        big = tmp_path / "big.bin"
        big.write_bytes(b"x" * 1001)
        with pytest.raises(BlobTooLarge, match="type 'dem': field 'filename': blob '.*big.bin': 1,001 bytes, over the "
                                               "store's limit of 1,000"):
            b.put_gridfs(store, "dem", 1, "t", str(big), None)
        assert big.exists()
        with pytest.raises(StoreError, match=r"field 'filename': cannot read '.*missing.bin': No such file"):
            b.put_gridfs(store, "static", 1, "t", str(tmp_path / "missing.bin"), None)
        with pytest.raises(ValidationError, match="field 'type': 'terrain' is not a GridFS type"):
            b.put_gridfs(store, "terrain", 1, "t", str(big), None)
        with pytest.raises(BlobTooLarge, match="type 'dynamic': field 'pointcloud2': blob None: 1,199 bytes"):
            b.put_gridfs(store, "dynamic", 1, "t", "", b.Cloud(data=bytes(600)))  # 600 bytes are 1,199 of text
        assert store.find_blobs() == [] and big.exists()


def test_gridfs_clouds(store) -> None:
    fields = (b.PointFieldSpec("x", 0, 7, 1), b.PointFieldSpec("y", 4, 7, 1))
    clouds = [b.Cloud(height=1, width=2, fields=fields, point_step=8, row_step=16, data=bytes([i] * 16),
                      is_dense=True) for i in (3, 1, 2)]
    for t, cloud in zip(("t3", "t1", "t2"), clouds, strict=True):
        b.put_gridfs(store, "dynamic", 9, t, "", cloud)
    got = b.read_clouds(store, "dynamic", False)
    assert [c.time for c in got] == ["t1", "t2", "t3"] and [c.data[0] for c in got] == [1, 2, 3]
    assert got[0] == b.Cloud(height=1, width=2, fields=fields, point_step=8, row_step=16, data=bytes([1] * 16),
                             is_dense=True, time="t1")
    assert [c.time for c in b.read_clouds(store, "dynamic", True)] == ["t3"]


def test_collision_record(store, tmp_path) -> None:
    mesh = tmp_path / "dump_area.stl"
    mesh.write_bytes(b"solid\x00\x01")
    doc = b.write_collision(store, "zx200", "static", str(mesh))
    stored = store.get_parameter("zx200", "collision_object_dump_area")
    assert stored["data"] == b"solid\x00\x01" and stored["x"] == 8.0 and stored["qw"] == 1.0 and doc["type"] == "static"
    assert mesh.exists()
    store.set_fields("collision_object_dump_area", {"x": 2.0}, model_name="zx200")
    mesh.write_bytes(b"solid2")
    b.write_collision(store, "zx200", "static", str(mesh))
    stored = store.get_parameter("zx200", "collision_object_dump_area")
    assert stored["data"] == b"solid2" and stored["x"] == 2.0  # the pose someone set stays
    with pytest.raises(StoreError, match="field 'filepath': cannot read"):
        b.write_collision(store, "zx200", "static", str(tmp_path / "nope.stl"))
