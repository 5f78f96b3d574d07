"""The store contract (issue 7, contract [C]), run against both backends through the ``store`` fixture."""

from __future__ import annotations

import datetime as dt

import pytest

from tms_db import RecordNotFound, StoreError, ValidationError, open_store
from tms_db.schema import require_arrays, require_numbers

TREE = """<root main_tree_to_execute="BehaviorTree">
  <BehaviorTree ID="BehaviorTree">
    <Sequence>
      <Action ID="LeafNodeZx200" subtask_name="subtask_zx200_change_pose"
              record_name="initial_pose" model_name="zx200"/>
      <Action ID="LeafNodeIc120" subtask_name="st_ic120_follow_waypoints" record_name="LOAD_PATH"
              model_name="ic120"/>
    </Sequence>
  </BehaviorTree>
</root>
"""
OTHER_TREE = TREE.replace("initial_pose", "finish_pose")


def test_add_get_list_remove_task(store) -> None:
    tid = store.add_task(TREE, description="dig and haul")
    assert tid == 1
    doc = store.get_task(tid)
    assert doc["task_id"] == 1 and doc["type"] == "task"
    assert doc["model_name"] == "zx200,ic120"
    assert doc["description"] == "dig and haul"
    # stored as one line, as the original task_generator does, and still the same tree
    assert "\n" not in doc["task_sequence"]
    assert 'subtask_name="subtask_zx200_change_pose" record_name="initial_pose"' in doc["task_sequence"]
    assert store.add_task(OTHER_TREE, task_id=7, model_name="zx200") == 7
    assert store.add_task(OTHER_TREE.replace("finish_pose", "pending_pose")) == 2  # smallest free id
    assert [t["task_id"] for t in store.list_tasks()] == [1, 2, 7]
    store.remove_task(2)
    assert [t["task_id"] for t in store.list_tasks()] == [1, 7]
    with pytest.raises(RecordNotFound, match="task_id 2"):
        store.get_task(2)
    with pytest.raises(RecordNotFound, match="task_id 2"):
        store.remove_task(2)


def test_task_duplicates_and_replace(store) -> None:
    store.add_task(TREE)
    with pytest.raises(StoreError, match="already stored as task_id 1"):
        store.add_task(TREE)
    with pytest.raises(StoreError, match="task_id 1: already exists"):
        store.add_task(OTHER_TREE, task_id=1)
    store.add_task(OTHER_TREE, task_id=1, replace=True)
    assert "finish_pose" in store.get_task(1)["task_sequence"]


@pytest.mark.parametrize(
    ("xml", "match"),
    [
        ("<root><BehaviorTree ID='x'><Sequence></root>", "task_sequence': XML does not parse at line 1"),
        ("<root><Other/></root>", "no <BehaviorTree>"),
        ("   ", "empty behavior-tree XML"),
    ],
)
def test_bad_task_xml_is_refused_naming_field(store, xml: str, match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        store.add_task(xml, task_id=3)
    assert store.list_tasks() == []


@pytest.mark.parametrize("bad", [0, -1, True, "3", 1.5])
def test_bad_task_id(store, bad) -> None:
    with pytest.raises(ValidationError, match="task_id"):
        store.get_task(bad)


JOINT_POSE = {
    "model_name": "zx200", "type": "static", "record_name": "initial_pose", "description": "home",
    "trajectory": 1, "swing_joint": 0.0, "boom_joint": -0.5, "arm_joint": 1, "bucket_joint": 0.25,
    "bucket_end_joint": 0.0,
}
WAYPOINTS = {
    "model_name": "ic120", "type": "dynamic", "record_name": "LOAD_PATH",
    "x": [1.0, 2.0, 3.0], "y": [0.0, 0.5, 1], "z": [0.0, 0.0, 0.0],
    "qx": [0.0, 0.0, 0.0], "qy": [0.0, 0.0, 0.0], "qz": [0.0, 0.0, 0.0], "qw": [1.0, 1.0, 1.0],
}
BLACKBOARD = {"record_name": "SAMPLE_GLOBAL_BLACKBOARD", "sample_val_int": 1, "sample_val_double": 1.0,
              "sample_flg": False, "label": "go", "big": 2**40}


def test_parameters_keep_types(store) -> None:
    for doc in (JOINT_POSE, WAYPOINTS, BLACKBOARD):
        store.upsert_parameter(doc)
    pose = store.get_parameter("zx200", "initial_pose")
    assert {k: v for k, v in pose.items() if k != "_id"} == JOINT_POSE
    assert type(pose["arm_joint"]) is int and type(pose["boom_joint"]) is float
    bb = store.get_record("SAMPLE_GLOBAL_BLACKBOARD")
    assert type(bb["sample_val_int"]) is int and type(bb["sample_val_double"]) is float
    assert bb["sample_flg"] is False and bb["big"] == 2**40
    assert store.get_parameter("", "SAMPLE_GLOBAL_BLACKBOARD")["label"] == "go"
    assert require_numbers(pose, ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")) == (0.0, -0.5, 1, 0.25)
    points = require_arrays(store.get_parameter("ic120", "LOAD_PATH"), ("x", "y", "z", "qx", "qy", "qz", "qw"))
    assert points[2] == (3.0, 1, 0.0, 0.0, 0.0, 0.0, 1.0)
    assert [d["record_name"] for d in store.list_parameters()] == [
        "initial_pose",
        "LOAD_PATH",
        "SAMPLE_GLOBAL_BLACKBOARD",
    ]
    assert [d["record_name"] for d in store.list_parameters("ic120")] == ["LOAD_PATH"]


def test_upsert_replaces_same_key(store) -> None:
    store.upsert_parameter(JOINT_POSE)
    first_id = store.get_parameter("zx200", "initial_pose")["_id"]
    store.upsert_parameter({**JOINT_POSE, "swing_joint": 1.5})
    doc = store.get_parameter("zx200", "initial_pose")
    assert doc["swing_joint"] == 1.5 and doc["_id"] == first_id
    assert len(store.list_parameters()) == 1
    store.remove_parameter("initial_pose", model_name="zx200")
    assert store.list_parameters() == []


def test_unknown_record_names_record_model_and_field(store) -> None:
    store.upsert_parameter(JOINT_POSE)
    with pytest.raises(
        RecordNotFound, match=r"record 'initial_pose' of model 'ic120' .*exists for model\(s\) \['zx200'\]"
    ):
        store.get_parameter("ic120", "initial_pose")
    with pytest.raises(RecordNotFound, match="record 'NOPE'"):
        store.get_record("NOPE")
    with pytest.raises(RecordNotFound, match=r"record 'NOPE' .*setting field\(s\) 'FLG'"):
        store.set_fields("NOPE", {"FLG": True})
    with pytest.raises(KeyError):  # RecordNotFound is a KeyError too
        store.compare_and_set("NOPE", "FLG", False, True)


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ({**WAYPOINTS, "y": 0.5}, "record 'LOAD_PATH' .*field 'y': waypoint records need arrays"),
        ({**WAYPOINTS, "qw": [1.0, 1.0]}, "field 'qw': 2 elements"),
        ({**WAYPOINTS, "x": [1.0, "two", 3.0]}, r"field 'x'\[1\]: expected a number"),
        ({**JOINT_POSE, "boom_joint": "up"}, "record 'initial_pose' .*field 'boom_joint': expected a number"),
        ({k: v for k, v in JOINT_POSE.items() if k != "arm_joint"}, "field 'arm_joint' is missing"),
        ({**JOINT_POSE, "swing_joint": True}, "field 'swing_joint': expected a number, got True"),
        ({"record_name": "r", "target_angle": [1.0]}, r"field 'target_angle'"),
        ({"record_name": "r", "type": 3}, "field 'type' must be a string, got 3"),
        ({"record_name": ""}, "'record_name' must be a non-empty string"),
        ({"record_name": "r", "a.b": 1}, "field 'a.b'"),
        ({"record_name": "r", "v": float("nan")}, "field 'v': non-finite"),
        ({"record_name": "r", "v": {1, 2}}, "field 'v': unsupported value type set"),
    ],
)
def test_malformed_parameter_documents_are_refused(store, doc, match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        store.upsert_parameter(doc)
    assert store.list_parameters() == []


def test_set_fields_is_validated_and_stamps_timestamps(store) -> None:
    store.upsert_parameter(WAYPOINTS)
    before = dt.datetime.now(dt.UTC) - dt.timedelta(seconds=1)
    doc = store.set_fields("LOAD_PATH", {"x": [5.0, 6.0, 7.0]}, model_name="ic120")
    assert doc["x"] == [5.0, 6.0, 7.0] and doc["y"] == [0.0, 0.5, 1]
    # a waypoint record gets no stamp (the original's array reader throws on a Date; test_seed_shapes), others do
    assert "timestamps" not in store.get_parameter("ic120", "LOAD_PATH")
    store.upsert_parameter({"record_name": "flags", "GO": False})
    store.set_fields("flags", {"GO": True})
    stamp = store.get_record("flags")["timestamps"]
    assert isinstance(stamp, dt.datetime) and stamp.tzinfo is not None and stamp >= before
    with pytest.raises(ValidationError, match="record 'LOAD_PATH' .*field 'x': waypoint records need arrays"):
        store.set_fields("LOAD_PATH", {"x": 1.0}, model_name="ic120")
    assert store.get_parameter("ic120", "LOAD_PATH")["x"] == [5.0, 6.0, 7.0]  # nothing written
    with pytest.raises(ValidationError, match="field '_id' cannot be set"):
        store.set_fields("LOAD_PATH", {"_id": 3})
    with pytest.raises(ValidationError, match="non-empty mapping"):
        store.set_fields("LOAD_PATH", {})


def test_append_fields_appends_atomically_and_refuses_what_set_fields_would(store) -> None:
    store.upsert_parameter(WAYPOINTS)
    point = {"x": 4.0, "y": 1.5, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.6, "qw": 0.8}
    doc = store.append_fields("LOAD_PATH", point, model_name="ic120")
    assert doc["x"] == [1.0, 2.0, 3.0, 4.0] and doc["y"] == [0.0, 0.5, 1, 1.5] and doc["qw"] == [1.0, 1.0, 1.0, 0.8]
    assert doc["model_name"] == "ic120" and doc["type"] == "dynamic"
    doc = store.append_fields("LOAD_PATH", {**point, "x": 5}, model_name=None)  # by record alone, as get_parameter
    stored = store.get_parameter("ic120", "LOAD_PATH")
    assert stored == doc and stored["x"] == [1.0, 2.0, 3.0, 4.0, 5]
    assert type(stored["x"][-1]) is int  # types kept
    assert "timestamps" not in stored  # a waypoint record: no stamp, as set_fields
    assert len(store.list_parameters()) == 1
    # a missing field becomes an array; a record that is not a waypoint record is stamped
    store.upsert_parameter({"record_name": "LOG", "events": [], "n": 1})
    doc = store.append_fields("LOG", {"events": "start", "fresh": 2})
    assert doc["events"] == ["start"] and doc["fresh"] == [2] and doc["n"] == 1
    assert isinstance(store.get_record("LOG")["timestamps"], dt.datetime)

    # refusals: the same record missing as get_parameter says it, a field that holds no array, a broken shape;
    # nothing written then
    with pytest.raises(RecordNotFound, match=r"^record 'NOPE' not found in collection 'parameter'$"):
        store.append_fields("NOPE", point)
    with pytest.raises(RecordNotFound, match=r"record 'LOAD_PATH' of model 'zx200' .*exists for model\(s\) "
                                             r"\['ic120'\]"):
        store.append_fields("LOAD_PATH", point, model_name="zx200")
    store.upsert_parameter({"model_name": "ic120", "record_name": "P1", "x": 1.5, "y": -2.0, "qw": 1.0})
    before = store.list_parameters()
    with pytest.raises(ValidationError, match=r"^record 'P1' of model 'ic120': field 'x': holds 1.5, not an array "
                                              "to append to$"):
        store.append_fields("P1", {"trail": 1.0, "x": 2.0}, model_name="ic120")
    with pytest.raises(ValidationError, match=r"^record 'LOG': field 'n': holds 1, not an array to append to$"):
        store.append_fields("LOG", {"events": "stop", "n": 2})
    with pytest.raises(ValidationError, match="record 'LOAD_PATH' .*field 'y': 5 elements, other waypoint fields "
                                              "have 6"):
        store.append_fields("LOAD_PATH", {"x": 6.0}, model_name="ic120")  # one pose field alone: lengths differ
    with pytest.raises(ValidationError, match=r"field 'x'\[5\]: expected a number"):
        store.append_fields("LOAD_PATH", {**point, "x": "six"}, model_name="ic120")
    with pytest.raises(ValidationError, match="field 'record_name' cannot be set"):
        store.append_fields("LOG", {"record_name": "x"})
    with pytest.raises(ValidationError, match="non-empty mapping"):
        store.append_fields("LOG", {})
    assert store.list_parameters() == before


def test_append_fields_refuses_a_field_made_scalar_after_its_read(store) -> None:
    """MongoDB: the shape check reads the record before the ``$push``; a writer that makes the field a scalar in
    between makes the server refuse the ``$push``, and the refusal is the same ValidationError (the embedded store
    reads and writes in one transaction: nothing can come between)."""
    store.upsert_parameter(WAYPOINTS)
    if not hasattr(store, "_params"):  # the embedded store: the same refusal, without a race
        store.set_fields("LOAD_PATH", {"x": 7.0, "y": 0.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0},
                         model_name="ic120")
    else:
        read = store._current

        def read_then_other_writer(record_name, model_name):
            doc = read(record_name, model_name)
            store._params.update_one({"_id": doc["_id"]}, {"$set": {"x": 7.0}})  # another client, after our read
            store._current = read
            return doc

        store._current = read_then_other_writer
    with pytest.raises(ValidationError, match=r"^record 'LOAD_PATH' of model 'ic120': field 'x': holds 7.0, not an "
                                              "array to append to$"):
        store.append_fields("LOAD_PATH", {k: 4.0 for k in ("x", "y", "z", "qx", "qy", "qz", "qw")}, model_name="ic120")
    stored = store.get_parameter("ic120", "LOAD_PATH")
    assert stored["x"] == 7.0 and stored["y"] in (0.0, [0.0, 0.5, 1])  # nothing appended


def test_set_fields_upsert_creates_record(store) -> None:
    doc = store.set_fields("BB", {"ARRIVAL_FLG": True, "N": 0}, upsert=True)
    assert doc["record_name"] == "BB" and doc["ARRIVAL_FLG"] is True
    again = store.get_record("BB")
    assert again["N"] == 0 and type(again["N"]) is int and "timestamps" in again


def test_compare_and_set_is_type_aware(store) -> None:
    store.upsert_parameter({"record_name": "BB", "FLG": False, "N": 1, "S": "a"})
    assert store.compare_and_set("BB", "FLG", 0, True) is False  # bool never equals a number
    assert store.compare_and_set("BB", "FLG", False, True) is True
    assert store.get_record("BB")["FLG"] is True
    assert store.compare_and_set("BB", "FLG", False, True) is False
    assert store.compare_and_set("BB", "N", 1.0, 2) is True  # 1 == 1.0 as in MongoDB
    assert store.get_record("BB")["N"] == 2 and type(store.get_record("BB")["N"]) is int
    assert store.compare_and_set("BB", "MISSING", None, "x") is True  # None matches a missing field
    assert store.get_record("BB")["MISSING"] == "x"
    assert store.compare_and_set("BB", "S", "b", "c") is False


def test_increment(store) -> None:
    store.upsert_parameter({"record_name": "C", "n": 5, "s": "x"})
    assert store.increment("C", "n") == 6
    assert store.increment("C", "n", 2.5) == 8.5
    assert store.increment("C", "fresh") == 1
    with pytest.raises(ValidationError, match="field 's'"):
        store.increment("C", "s")


def test_store_reopens_with_data(tmp_path) -> None:
    path = tmp_path / "db"
    with open_store(path=path) as s:
        s.upsert_parameter(BLACKBOARD)
        s.add_task(TREE)
    with open_store(path=path) as s:
        assert s.get_record("SAMPLE_GLOBAL_BLACKBOARD")["sample_flg"] is False
        assert s.get_task(1)["model_name"] == "zx200,ic120"
        assert s.check() == []


def test_open_store_choices(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("TMS_DB_PATH", str(tmp_path / "env"))
    with open_store() as s:
        assert s.directory == tmp_path / "env"
    with pytest.raises(StoreError, match="'redis://x': unsupported scheme"):
        open_store(uri="redis://x")
    (tmp_path / "file").write_text("")
    with pytest.raises(StoreError, match="cannot create directory"):
        open_store(path=tmp_path / "file" / "db")


def test_corrupt_file_is_reported(tmp_path) -> None:
    path = tmp_path / "db"
    path.mkdir()
    (path / "rostmsdb.sqlite3").write_bytes(b"this is not a database" * 100)
    with pytest.raises(StoreError, match="rostmsdb.sqlite3: cannot open"):
        open_store(path=path)
