"""The original's records load unchanged: binary fields, any ``type``, and a restore that reports a bad
document by its ``_id`` and stores nothing of a refused input.

The shapes are written from the original's writers (irvs/ros2_tms_for_construction, tms_db_manager
``tms_db_writer_collision``: a collision object is a parameter record ``{model_name, type, x, y, z, qx,
qy, qz, qw, record_name: "collision_object_<file stem>", data: <the mesh file's bytes>}``), not copied
from its data files.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import bson
from bson import Binary, Decimal128, ObjectId

from tests.rosproc import ROOT
from tms_db import open_store
from tms_db.dumpfmt import dump, dumps_doc, restore


def stl_mesh() -> bytes:
    """A binary STL file of one triangle: the kind of file the original stores in ``data``."""
    header = b"tms collision object".ljust(80, b"\0")
    triangle = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return header + struct.pack("<I", 1) + triangle


def collision_record(oid: str, stem: str, kind: str = "collision_object") -> dict:
    return {"_id": ObjectId(oid), "model_name": "zx200", "type": kind, "x": 8.0, "y": 0.0, "z": 0.0,
            "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0, "record_name": f"collision_object_{stem}", "data": stl_mesh()}


def test_binary_fields_and_any_type_through_the_store_api(store) -> None:
    doc = collision_record("66f0c0ffee00000000000101", "dump_truck")
    store.upsert_parameter(doc)
    got = store.get_parameter("zx200", "collision_object_dump_truck")
    assert got == doc and type(got["data"]) is bytes and got["type"] == "collision_object"
    # writes to such a record keep the mesh; a binary value can also be written and read back with its subtype
    store.set_fields("collision_object_dump_truck", {"x": 9.5, "uuid": Binary(b"\x01" * 16, 4)}, model_name="zx200")
    after = store.get_parameter("zx200", "collision_object_dump_truck")
    assert after["data"] == stl_mesh() and after["x"] == 9.5
    assert after["uuid"] == Binary(b"\x01" * 16, 4) and after["uuid"].subtype == 4


def test_import_is_all_or_nothing_and_names_every_refused_document(store) -> None:
    docs = [
        collision_record("66f0c0ffee00000000000111", "a"),
        {"_id": ObjectId("66f0c0ffee00000000000112"), "record_name": "bad", "when": {1, 2}},
        {"_id": ObjectId("66f0c0ffee00000000000113"), "model_name": "zx120", "type": "parameter", "parameter_id": 5},
        {**collision_record("66f0c0ffee00000000000114", "a")},
    ]  # same key as the first
    result = store.import_documents("parameter", docs)
    assert result.loaded == 0
    assert [(r.index, r.label, r.first) for r in result.rejected] == [(1, "_id 66f0c0ffee00000000000112", None),
                                                                       (3, "_id 66f0c0ffee00000000000114", 0)]
    assert "set" in result.rejected[0].reason
    assert list(store.export_collection("parameter")) == []  # nothing of a refused input is stored
    # without the refused ones the same input loads whole
    assert store.import_documents("parameter", [docs[0], docs[2]]).loaded == 2
    assert [d["_id"] for d in store.export_collection("parameter")] == [docs[0]["_id"], docs[2]["_id"]]
    # a key already in the store refuses the whole input too, naming it; the new document is not stored
    again = store.import_documents("parameter", [collision_record("66f0c0ffee00000000000115", "b"),
                                                 {**docs[0], "_id": ObjectId("66f0c0ffee00000000000116")}])
    assert again.loaded == 0 and [r.index for r in again.rejected] == [1]
    assert len(list(store.export_collection("parameter"))) == 2


def test_original_records_restore_dump_and_restore_unchanged(tmp_path) -> None:
    records = [
        collision_record("66f0c0ffee00000000000201", "mound"),
        collision_record("66f0c0ffee00000000000202", "ic120", kind="static"),
        {"_id": ObjectId("66f0c0ffee00000000000203"), "record_name": "SAMPLE_BLACKBOARD", "type": "blackboard",
         "ratio": Decimal128("0.125"), "FLG": True},
    ]
    src = tmp_path / "mongodump" / "rostmsdb"
    src.mkdir(parents=True)
    (src / "parameter.bson").write_bytes(b"".join(bson.encode(d) for d in records))
    with open_store(path=tmp_path / "db") as store:
        result = restore(store, tmp_path / "mongodump")
        assert result.counts == {"parameter": 3} and result.rejected == []
        assert list(store.export_collection("parameter")) == records
        dump(store, tmp_path / "out")
    text = (tmp_path / "out" / "rostmsdb" / "parameter.json").read_text()
    assert '"$binary"' in text and '"$numberDecimal": "0.125"' in text
    with open_store(path=tmp_path / "db2") as store2:
        assert restore(store2, tmp_path / "out").counts == {"parameter": 3}
        assert list(store2.export_collection("parameter")) == records
    # and the dump is what the original's MongoDB holds: canonical Extended JSON decodes to the same documents
    assert [bson.json_util.loads(line) for line in text.splitlines()] == records


def test_a_bad_document_is_reported_by_its_id_and_nothing_loads(tmp_path) -> None:
    good = [collision_record("66f0c0ffee00000000000301", "a"), collision_record("66f0c0ffee00000000000302", "b")]
    duplicate = {**good[0], "_id": ObjectId("66f0c0ffee00000000000303")}  # same (record_name, model_name)
    string_id = {**collision_record("66f0c0ffee00000000000305", "c"), "_id": "mesh-c"}
    src = tmp_path / "d" / "rostmsdb"
    src.mkdir(parents=True)
    (src / "parameter.json").write_text(
        "".join(dumps_doc(d) + "\n" for d in (good[0], duplicate, string_id, good[1])))
    tasks = [
        {
            "_id": ObjectId("66f0c0ffee00000000000311"),
            "task_id": 1,
            "type": "task",
            "model_name": "zx200",
            "description": "",
            "task_sequence": "<root><BehaviorTree/></root>",
        },
        {"_id": ObjectId("66f0c0ffee00000000000312"), "task_id": "two", "type": "task", "task_sequence": "<root/>"},
        {
            "_id": ObjectId("66f0c0ffee00000000000313"),
            "task_id": 3,
            "type": "task",
            "task_sequence": "<root><BehaviorTree><Sequence></root>",
        },
    ]
    (src / "task.json").write_text("".join(dumps_doc(d) + "\n" for d in tasks))
    with open_store(path=tmp_path / "db") as store:
        result = restore(store, tmp_path / "d")
        assert result.counts == {"parameter": 0, "task": 0}
        text = "\n".join(result.rejected)
        assert len(result.rejected) == 4, text
        assert ("parameter.json: line 2 (_id 66f0c0ffee00000000000303): duplicate record 'collision_object_a' of "
                "model 'zx200' (the same as line 1)") in text
        assert "parameter.json: line 3 (_id mesh-c): _id 'mesh-c' is not an ObjectId" in text
        assert "task.json: line 2 (_id 66f0c0ffee00000000000312): field 'task_id'" in text
        assert (
            "task.json: line 3 (_id 66f0c0ffee00000000000313): task_id 3: field 'task_sequence': XML does not parse"
            in text
        )
        # all or nothing: the good documents of both files are not stored either
        assert store.list_parameters() == [] and store.list_tasks() == []
        assert store.check() == []


def test_cli_restore_names_the_refused_documents_stores_nothing_and_exits_1(tmp_path) -> None:
    src = tmp_path / "d" / "rostmsdb"
    src.mkdir(parents=True)
    first = collision_record("66f0c0ffee00000000000401", "a")
    (src / "parameter.json").write_text(
        dumps_doc(first) + "\n" + dumps_doc({**first, "_id": ObjectId("66f0c0ffee00000000000402")}) + "\n"
    )
    exe = Path(sys.prefix) / "bin" / "tms-db"
    r = subprocess.run([str(exe), "--path", str(tmp_path / "db"), "restore", str(tmp_path / "d")],
                       capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 1 and "restored" not in r.stdout
    assert "tms-db: refused:" in r.stderr and "_id 66f0c0ffee00000000000402" in r.stderr and "line 1" in r.stderr
    assert r.stderr.splitlines()[-1] == (f"tms-db: error: restore {tmp_path / 'd'}: 1 document(s) refused "
                                         "(listed above); nothing restored")
    with open_store(path=tmp_path / "db") as store:
        assert store.list_parameters() == []
