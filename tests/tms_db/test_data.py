"""Environment data (the original's Tmsdb collections) on both backends: insert, the original reader's queries,
retention, refusals naming the field."""

from __future__ import annotations

import time

import pytest

from tms_db import Store, ValidationError
from tms_db.data import INSERTED_FIELD


def _doc(t: str, ident: int = 1, name: str = "zx200", kind: str = "machine_pose", **msg: object) -> dict:
    return {"time": t, "type": kind, "id": ident, "name": name, "msg": msg or {"x": 1.5, "ok": True}}


def test_insert_and_history_ascending_by_time(store: Store) -> None:
    # inserted out of order: the reader sorts by the string "time", as MongoDB does
    for t in ("2024-05-01T10:00:02.000000", "2024-05-01T10:00:00.500000", "2024-05-01T10:00:01.000000"):
        oid = store.insert_data(_doc(t, x=float(t[-8:])))
        assert isinstance(oid, str) and len(oid) == 24
    store.insert_data(_doc("2024-05-01T10:00:03.000000", ident=2))
    docs = store.find_data("machine_pose", 1)
    assert [d["time"] for d in docs] == ["2024-05-01T10:00:00.500000", "2024-05-01T10:00:01.000000",
                                         "2024-05-01T10:00:02.000000"]
    assert docs[0]["msg"] == {"x": 0.5} and docs[0]["type"] == "machine_pose" and docs[0]["id"] == 1
    assert [d["id"] for d in store.find_data("machine_pose", 2)] == [2]


def test_latest_only_is_the_newest_time(store: Store) -> None:
    store.insert_data(_doc("2024-05-01T10:00:05.000000", x=5))
    store.insert_data(_doc("2024-05-01T10:00:09.000000", x=9))
    store.insert_data(_doc("2024-05-01T10:00:07.000000", x=7))
    latest = store.find_data("machine_pose", 1, latest_only=True)
    assert len(latest) == 1 and latest[0]["msg"] == {"x": 9}
    assert store.find_data("machine_pose", 99, latest_only=True) == []


def test_name_filter_only_when_not_empty(store: Store) -> None:
    store.insert_data(_doc("t1", name="zx200", v=1))
    store.insert_data(_doc("t2", name="ic120", v=2))
    store.insert_data(_doc("t3", name="zx200", v=3))
    assert [d["msg"]["v"] for d in store.find_data("machine_pose", 1, name="zx200")] == [1, 3]
    assert [d["msg"]["v"] for d in store.find_data("machine_pose", 1, name="ic120", latest_only=True)] == [2]
    assert [d["msg"]["v"] for d in store.find_data("machine_pose", 1)] == [1, 2, 3]
    assert store.find_data("machine_pose", 1, name="d37pxi") == []


def test_unknown_collection_is_empty_and_types_listed(store: Store) -> None:
    assert store.find_data("never_written", 1) == []
    assert store.find_data("never_written", 1, latest_only=True) == []
    store.insert_data(_doc("t", kind="terrain_points"))
    store.insert_data(_doc("t", kind="machine_pose"))
    assert store.data_types() == ["machine_pose", "terrain_points"]
    assert "task" not in store.data_types() and "parameter" not in store.data_types()


def test_msg_keeps_json_values(store: Store) -> None:
    msg = {"pose": {"x": 1, "y": -2.25}, "list": [1, "a", None, True, [2.5]], "big": 2**40, "empty": {}}
    store.insert_data({"time": "t", "type": "json_values", "id": 0, "name": "", "msg": msg})
    store.insert_data({"time": "u", "type": "json_values", "id": 0, "name": "", "msg": "a bare string"})
    got = store.find_data("json_values", 0)
    assert got[0]["msg"] == msg and type(got[0]["msg"]["list"][3]) is bool and got[1]["msg"] == "a bare string"
    assert got[0][INSERTED_FIELD].tzinfo is not None  # the store's stamp, beside the original's string time


def test_retention_by_count_keeps_the_newest(store: Store) -> None:
    for i in (3, 1, 4, 0, 2):
        store.insert_data(_doc(f"2024-01-01T00:00:0{i}.0", v=i))
    assert store.prune_data("machine_pose", max_count=2) == 3
    assert [d["msg"]["v"] for d in store.find_data("machine_pose", 1)] == [3, 4]
    assert store.prune_data("machine_pose", max_count=2) == 0
    assert store.prune_data("machine_pose", max_count=0) == 2
    assert store.find_data("machine_pose", 1) == [] and store.data_types() == []


def test_retention_by_age_uses_the_insert_stamp(store: Store) -> None:
    # "time" strings say the old one is newest: age must go by when the store received them
    store.insert_data(_doc("2099-01-01T00:00:00.0", v="old"))
    time.sleep(1.2)
    store.insert_data(_doc("2000-01-01T00:00:00.0", v="new"))
    assert store.prune_data("machine_pose", max_age_s=0.6) == 1
    assert [d["msg"]["v"] for d in store.find_data("machine_pose", 1)] == ["new"]
    assert store.prune_data("machine_pose", max_age_s=3600) == 0
    assert store.prune_data("unknown_type", max_age_s=1, max_count=1) == 0


def test_retention_refuses_bad_arguments(store: Store) -> None:
    with pytest.raises(ValidationError, match="max_age_s and / or max_count"):
        store.prune_data("machine_pose")
    with pytest.raises(ValidationError, match="max_count"):
        store.prune_data("machine_pose", max_count=-1)
    with pytest.raises(ValidationError, match="max_age_s"):
        store.prune_data("machine_pose", max_age_s=float("nan"))
    with pytest.raises(ValidationError, match="'type'"):
        store.prune_data("parameter", max_count=0)


@pytest.mark.parametrize(("change", "field"), [
    ({"type": None}, "'type'"),
    ({"type": ""}, "'type'"),
    ({"type": 3}, "'type'"),
    ({"type": "task"}, "'type'"),
    ({"type": "parameter"}, "'type'"),
    ({"type": "fs.files"}, "'type'"),
    ({"type": "fs.chunks"}, "'type'"),
    ({"type": "system.users"}, "'type'"),
    ({"type": "a$b"}, "'type'"),
    ({"type": "a\x00b"}, "'type'"),
    ({"id": "1"}, "'id'"),
    ({"id": 1.0}, "'id'"),
    ({"id": True}, "'id'"),
    ({"id": 2**64}, "'id'"),
    ({"time": 17.0}, "'time'"),
    ({"time": None}, "'time'"),
    ({"name": 5}, "'name'"),
    ({"msg": {1, 2}}, "'msg'"),
    ({"msg": float("nan")}, "'msg'"),
    ({"msg": {"$date": "2024-01-01T00:00:00.000Z"}}, "'\\$date'"),
    ({"msg": {"a.b": 1}}, "'a.b'"),
    ({"msg": object()}, "'msg'"),
    ({"extra": b"x", "other": {1: 2}}, "'other'"),
    ({INSERTED_FIELD: "forged"}, INSERTED_FIELD),
])
def test_bad_documents_refused_naming_the_field(store: Store, change: dict, field: str) -> None:
    doc = {**_doc("t"), **change}
    with pytest.raises(ValidationError, match=field):
        store.insert_data(doc)
    assert store.data_types() == [], "nothing stored"


@pytest.mark.parametrize("missing", ["type", "time", "id", "name", "msg"])
def test_missing_field_refused(store: Store, missing: str) -> None:
    doc = _doc("t")
    del doc[missing]
    with pytest.raises(ValidationError, match=f"'{missing}'"):
        store.insert_data(doc)
    assert store.data_types() == []


def test_queries_refuse_bad_arguments(store: Store) -> None:
    with pytest.raises(ValidationError, match="'type'"):
        store.find_data("task", 1)
    with pytest.raises(ValidationError, match="'id'"):
        store.find_data("machine_pose", "1")  # type: ignore[arg-type]
    with pytest.raises(ValidationError, match="'name'"):
        store.find_data("machine_pose", 1, name=None)  # type: ignore[arg-type]


def test_data_does_not_touch_tasks_or_parameters(store: Store) -> None:
    store.upsert_parameter({"record_name": "flags", "type": "dynamic", "go": False})
    store.insert_data(_doc("t", kind="flags_log"))
    assert store.get_record("flags")["go"] is False
    assert [p["record_name"] for p in store.list_parameters()] == ["flags"]
    assert store.check() == []
