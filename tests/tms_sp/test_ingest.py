"""The sensing PC's write rule (:mod:`tms_sp.ingest`), without ROS, on the embedded store."""

from __future__ import annotations

import array

import pytest

from tms_db import open_store
from tms_sp.errors import SensingError
from tms_sp.ingest import FLAGS_TOPIC, SENSING_TOPICS, SensingWriter, sensed_fields

FLAGS = {"record_name": "GLOBAL_BLACKBOARD_EARTHWORK", "model_name": "global_blackboard", "type": "dynamic",
         "description": "flags", "CONTINUE_FLG": True, "LOADED_FLG": False, "SENSING_ARRIVAL_FLG": False,
         "SENSING_LOADED_FLG": False, "SENSING_CHECK_MOUND_FLG": True}
POSE = {"model_name": "zx200", "record_name": "dig_pose", "type": "dynamic", "trajectory": 1,
        "swing_joint": 0.0, "boom_joint": 0.0, "arm_joint": 0.0, "bucket_joint": 0.0}
PATH = {"model_name": "ic120", "record_name": "LOAD_PATH", "type": "dynamic",
        "x": [0.0], "y": [0.0], "z": [0.0], "qx": [0.0], "qy": [0.0], "qz": [0.0], "qw": [1.0]}


@pytest.fixture
def writer(tmp_path):
    store = open_store(path=tmp_path / "db")
    for doc in (FLAGS, POSE, PATH, {**POSE, "record_name": "home", "type": "static"}):
        store.upsert_parameter(doc)
    yield SensingWriter(store)
    store.close()


def test_flags_message_sets_the_flags_it_carries_except_the_kept_ones(writer) -> None:
    msg = {"record_name": "GLOBAL_BLACKBOARD_EARTHWORK", "continue_flg": False, "sensing_arrival_flg": True,
           "sensing_loaded_flg": True, "keep_val_flgs": ["SENSING_LOADED_FLG"]}
    assert writer.write_message(FLAGS_TOPIC, msg) == {"CONTINUE_FLG": False, "SENSING_ARRIVAL_FLG": True}
    doc = writer.store.get_record("GLOBAL_BLACKBOARD_EARTHWORK")
    assert doc["SENSING_ARRIVAL_FLG"] is True and doc["CONTINUE_FLG"] is False
    assert doc["SENSING_LOADED_FLG"] is False and doc["SENSING_CHECK_MOUND_FLG"] is True  # kept / not carried
    assert doc["description"] == "flags" and "timestamps" in doc


def test_subtask_message_sets_matching_fields_of_its_models_record(writer) -> None:
    topic = next(t for t in SENSING_TOPICS if t.topic == "/tms_sp_change_pose")
    msg = {"model_name": "zx200", "record_name": "dig_pose", "swing_joint": 0.5, "boom_joint": -0.25,
           "arm_joint": 1.0, "bucket_joint": 0.75, "bucket_end_joint": 0.1}
    assert writer.write_message(topic, msg) == {"swing_joint": 0.5, "boom_joint": -0.25, "arm_joint": 1.0,
                                                "bucket_joint": 0.75}
    assert "bucket_end_joint" not in writer.store.get_parameter("zx200", "dig_pose")  # not in the seeded record
    waypoints = next(t for t in SENSING_TOPICS if t.topic == "/tms_sp_follow_waypoints")
    msg = {"model_name": "ic120", "record_name": "LOAD_PATH", **{k: array.array("d", [v, v + 1.0]) for k, v in
           (("x", 1.0), ("y", 2.0), ("z", 0.0), ("qx", 0.0), ("qy", 0.0), ("qz", 0.0), ("qw", 1.0))}}
    writer.write_message(waypoints, msg)
    doc = writer.store.get_parameter("ic120", "LOAD_PATH")
    assert doc["x"] == [1.0, 2.0] and doc["qw"] == [1.0, 2.0] and type(doc["y"][0]) is float


@pytest.mark.parametrize(
    ("topic", "msg", "match"),
    [
        ("/tms_sp_change_pose", {"model_name": "zx200", "record_name": "nope", "swing_joint": 1.0},
         r"record \(zx200, nope\) not in the DB"),
        ("/tms_sp_change_pose", {"model_name": "zx200", "record_name": "home", "swing_joint": 1.0},
         r"record \(zx200, home\) has type 'static': sensing only writes 'dynamic' records"),
        ("/tms_sp_change_pose", {"model_name": "", "record_name": "dig_pose", "swing_joint": 1.0},
         "without a model_name"),
        ("/Flgs", {"record_name": "", "continue_flg": True}, "without a record_name"),
    ],
)
def test_what_cannot_be_written_is_named(writer, topic: str, msg: dict, match: str) -> None:
    with pytest.raises(SensingError, match=match):
        writer.write_message(next(t for t in SENSING_TOPICS if t.topic == topic), msg)


def test_a_value_of_the_wrong_shape_is_refused_by_the_store_naming_the_field(writer) -> None:
    from tms_db.errors import ValidationError

    topic = next(t for t in SENSING_TOPICS if t.topic == "/tms_sp_navigate_through_poses")
    msg = {"model_name": "ic120", "record_name": "LOAD_PATH", "x": [1.0], "y": [1.0], "z": [0.0],
           "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}
    with pytest.raises(ValidationError, match="record 'LOAD_PATH' .*field 'qx'"):
        writer.write_message(topic, msg)
    assert writer.store.get_parameter("ic120", "LOAD_PATH")["x"] == [0.0]  # nothing written


def test_strict_writes_name_fields_the_record_lacks(writer) -> None:
    with pytest.raises(SensingError, match=r"has no field\(s\) \['SENSING_NEW_FLG'\]"):
        writer.write("GLOBAL_BLACKBOARD_EARTHWORK", {"SENSING_NEW_FLG": True}, strict=True)
    assert writer.write("GLOBAL_BLACKBOARD_EARTHWORK", {"SENSING_NEW_FLG": True}) == {}


def test_sensed_fields_match_case_insensitively_and_skip_bookkeeping() -> None:
    record = {"_id": 1, "record_name": "r", "type": "dynamic", "description": "d", "FLG": False, "x": 0.0}
    assert sensed_fields(record, {"flg": True, "X": 2.0, "description": "new", "type": "static"}) == {
        "FLG": True,
        "x": 2.0,
    }
    assert sensed_fields(record, {"flg": True, "x": 1.0}, keep=["FLG"]) == {"x": 1.0}
