"""Records stay readable by the original's readers: the seeds pass the store's shape check, which refuses what the
original's waypoint (array) reader throws on; the store writes no ``timestamps`` into a waypoint record."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest

from tests.rosproc import ROOT
from tms_common.config import load_yaml
from tms_db import Store, ValidationError
from tms_db.cli import check_parameters
from tms_db.schema import ARRAY_READER_SKIPS, is_waypoint_record, validate_parameter

SEEDS = sorted((ROOT / "config" / "seeds").glob("*.yaml"))
PATH = {"model_name": "ic120", "record_name": "LOAD_PATH", "type": "static",
        "x": [1.0, 2.0], "y": [0.0, 0.5], "z": [0.0, 0.0], "qx": [0.0, 0.0], "qy": [0.0, 0.0], "qz": [0.0, 0.0],
        "qw": [1.0, 1.0]}


def test_the_seeds_are_there() -> None:
    assert {p.name for p in SEEDS} >= {"paper.yaml", "fleet.yaml", "original_202412.yaml"}


@pytest.mark.parametrize("seed", SEEDS, ids=lambda p: p.name)
def test_every_seed_record_passes_the_shape_check(seed: Path) -> None:
    data, where = load_yaml(seed)
    params = data.get("parameters") or []
    assert check_parameters(seed, params, where, ("parameters",)) == []
    for doc in params:
        if is_waypoint_record(doc):  # what the original's array reader reads: arrays of numbers only
            read = {k: v for k, v in doc.items() if k not in ARRAY_READER_SKIPS}
            assert all(isinstance(v, list) and all(isinstance(x, int | float) for x in v) for v in read.values()), (
                f"{seed.name}: {doc['record_name']}")


def test_the_original_readers_skip_list() -> None:
    # tms_ts_subtask/include/tms_ts_subtask/subtask_node_base.hpp: key != "_id" && != "model_name" && != "type"
    # && != "record_name"; every other field goes through element.get_array()
    assert ARRAY_READER_SKIPS == {"_id", "model_name", "type", "record_name"}


@pytest.mark.parametrize(("field", "value"), [
    ("description", "P3 -> P1"),
    ("timestamps", dt.datetime(2025, 1, 1, tzinfo=dt.UTC)),
    ("LOCK_FLG", False),
    ("count", 3),
])
def test_waypoint_record_with_a_non_array_field_refused(field: str, value: object) -> None:
    with pytest.raises(ValidationError, match=f"field '{field}': waypoint records need arrays"):
        validate_parameter({**PATH, field: value})
    validate_parameter(PATH if field in ("description", "timestamps") else {**PATH, field: [1.0, 2.0]})


def test_scalar_records_keep_their_description() -> None:
    # the original's scalar reader prints a type error for a string and goes on: description stays there
    validate_parameter({"model_name": "zx200", "record_name": "initial_pose", "type": "static", "description": "home",
                        "trajectory": 1, "swing_joint": 0.0, "boom_joint": -0.9, "arm_joint": 1.8,
                        "bucket_joint": 1.2})


def test_store_refuses_such_a_record_and_stores_nothing(store: Store) -> None:
    with pytest.raises(ValidationError, match="'description'"):
        store.upsert_parameter({**PATH, "description": "approach the loading point"})
    assert store.list_parameters() == []


def test_writes_into_a_waypoint_record_leave_no_timestamps(store: Store) -> None:
    store.upsert_parameter(PATH)
    doc = store.set_fields("LOAD_PATH", {"x": [3.0, 4.0]}, model_name="ic120")
    assert doc["x"] == [3.0, 4.0] and "timestamps" not in doc
    assert "timestamps" not in store.get_parameter("ic120", "LOAD_PATH")
    assert store.compare_and_set("LOAD_PATH", "y", [0.0, 0.5], [1.0, 1.5], model_name="ic120")
    assert "timestamps" not in store.get_parameter("ic120", "LOAD_PATH")
    # a flags record is still stamped
    store.upsert_parameter({"record_name": "flags", "type": "dynamic", "GO": False})
    assert isinstance(store.set_fields("flags", {"GO": True})["timestamps"], dt.datetime)


def test_a_stamp_restored_into_a_waypoint_record_goes_with_the_next_write(store: Store) -> None:
    # a dump from before this rule: the record carries a Date the original's array reader throws on
    result = store.import_documents("parameter", [{**PATH, "timestamps": dt.datetime(2025, 1, 1, tzinfo=dt.UTC)}])
    assert result.loaded == 1
    assert any("'timestamps'" in p for p in store.check())
    store.set_fields("LOAD_PATH", {"x": [5.0, 6.0]}, model_name="ic120")
    assert "timestamps" not in store.get_parameter("ic120", "LOAD_PATH") and store.check() == []
