"""``tms-db`` CLI (run as a real process) and dump/restore round trips of the original's document shapes."""

from __future__ import annotations

import datetime as dt
import json
import re
import subprocess
import sys
from pathlib import Path

from bson import ObjectId

from tests.rosproc import ROOT
from tests.tms_db.test_store import BLACKBOARD, JOINT_POSE, TREE, WAYPOINTS
from tms_db import open_store
from tms_db.cli import main as cli_main
from tms_db.dumpfmt import dump, restore


def tms_db(db: Path, *args: str) -> subprocess.CompletedProcess:
    exe = Path(sys.prefix) / "bin" / "tms-db"
    return subprocess.run([str(exe), "--path", str(db), *args], capture_output=True, text=True, timeout=60, cwd=ROOT)


# Documents in the original's shapes (irvs/ros2_tms_for_construction, tms_db), with _ids and a BSON Date as
# mongorestore gives.
STAMP = dt.datetime(2025, 3, 14, 9, 26, 53, 589000, tzinfo=dt.UTC)
ORIGINAL_TASK = {"_id": ObjectId("66f0c0ffee00000000000001"), "task_id": 9, "type": "task", "model_name": "zx200",
                 "description": "No Commented", "task_sequence": " ".join(TREE.split())}
ORIGINAL_PARAMS = [
    {"_id": ObjectId("66f0c0ffee00000000000002"), **JOINT_POSE},
    {"_id": ObjectId("66f0c0ffee00000000000003"), **WAYPOINTS},
    {"_id": ObjectId("66f0c0ffee00000000000004"), **BLACKBOARD, "timestamps": STAMP},
    {"_id": ObjectId("66f0c0ffee00000000000005"), "model_name": "zx120", "type": "parameter",
     "description": "Static parameter for task(task_id: 2)", "parameter_id": 5, "zx120_bucket_goal_pos": 20,
     "parameter_type": "static", "parts_name": "zx120_bucket"},
    {"_id": ObjectId("66f0c0ffee00000000000006"), "model_name": "zx200", "type": "dynamic",
     "record_name": "release_angle", "target_angle": -1.5707963267948966, "LOCK_FLG": False},
]


def test_original_shapes_round_trip_through_restore_and_dump(tmp_path) -> None:
    src = tmp_path / "in" / "rostmsdb"
    src.mkdir(parents=True)
    from tms_db.dumpfmt import dumps_doc

    (src / "task.json").write_text(dumps_doc(ORIGINAL_TASK) + "\n")
    (src / "parameter.json").write_text("".join(dumps_doc(d) + "\n" for d in ORIGINAL_PARAMS))
    with open_store(path=tmp_path / "db") as store:
        assert restore(store, tmp_path / "in").counts == {"parameter": 5, "task": 1}
        assert store.get_task(9) == ORIGINAL_TASK
        got = list(store.export_collection("parameter"))
        assert got == ORIGINAL_PARAMS
        assert [type(v) for v in got[2].values()] == [type(v) for v in ORIGINAL_PARAMS[2].values()]
        assert dump(store, tmp_path / "out") == {"parameter": 5, "task": 1}
    # byte-identical files: nothing changed on the way through
    for name in ("task.json", "parameter.json"):
        assert (tmp_path / "out" / "rostmsdb" / name).read_text() == (src / name).read_text()
    # canonical Extended JSON, as mongoimport reads it: types are explicit
    first = json.loads((tmp_path / "out" / "rostmsdb" / "parameter.json").read_text().splitlines()[0])
    assert first["trajectory"] == {"$numberInt": "1"} and first["swing_joint"] == {"$numberDouble": "0.0"}
    # and into a second store, again unchanged
    with open_store(path=tmp_path / "db2") as store2:
        restore(store2, tmp_path / "out")
        assert list(store2.export_collection("parameter")) == ORIGINAL_PARAMS


def test_restore_reads_mongodump_bson(tmp_path) -> None:
    import bson

    src = tmp_path / "dump" / "rostmsdb"
    src.mkdir(parents=True)
    (src / "parameter.bson").write_bytes(b"".join(bson.encode(d) for d in ORIGINAL_PARAMS))
    (src / "parameter.metadata.json").write_text("{}")
    with open_store(path=tmp_path / "db") as store:
        assert restore(store, tmp_path / "dump").counts == {"parameter": 5}
        assert list(store.export_collection("parameter")) == ORIGINAL_PARAMS


def test_restore_reports_every_bad_line_and_document_and_loads_nothing(tmp_path) -> None:
    # all or nothing: a malformed line and a duplicate (named with the line of the first) refuse the whole file
    src = tmp_path / "d" / "rostmsdb"
    src.mkdir(parents=True)
    (src / "parameter.json").write_text(
        '{"record_name": "a"}\n{"record_name": \n{"record_name": "a"}\n{"record_name": "b"}\n'
    )
    with open_store(path=tmp_path / "db") as store:
        result = restore(store, tmp_path / "d")
        assert result.counts == {"parameter": 0}
        assert len(result.rejected) == 2
        assert "parameter.json:2: malformed Extended JSON" in result.rejected[0]
        assert re.search(r"parameter.json: line 3 \(record_name 'a'\): duplicate record 'a' of model '' "
                         r"\(the same as line 1\)", result.rejected[1])
        assert store.list_parameters() == []


def test_cli_task_and_param_commands(tmp_path) -> None:
    db = tmp_path / "db"
    tree = tmp_path / "t.xml"
    tree.write_text(TREE)
    r = tms_db(db, "task", "add", str(tree), "--id", "4", "--description", "demo")
    assert r.returncode == 0 and "task_id 4" in r.stdout, r.stderr
    r = tms_db(db, "task", "list")
    assert r.stdout.split("\n")[0] == "4\tzx200,ic120\tdemo"
    bad = tmp_path / "bad.xml"
    bad.write_text("<root><BehaviorTree>\n<Sequence>\n</root>")
    r = tms_db(db, "task", "add", str(bad))
    assert r.returncode == 1 and "bad.xml: malformed XML at line 3, column 3: mismatched tag" in r.stderr
    params = tmp_path / "p.yaml"
    params.write_text("parameters:\n  - {record_name: BB, FLG: false, N: 3, V: 2.5}\n"
                      "  - {model_name: ic120, record_name: LOAD_PATH, x: [1.0], y: 0.0}\n")
    r = tms_db(db, "param", "import", str(params))
    assert (
        r.returncode == 1
        and "p.yaml:3: record 'LOAD_PATH' (model 'ic120'): field 'y': waypoint records need arrays" in r.stderr
    )
    params.write_text("parameters:\n  - {record_name: BB, FLG: false, N: 3, V: 2.5}\n")
    assert tms_db(db, "param", "import", str(params)).returncode == 0
    r = tms_db(db, "param", "set", "BB", "FLG=true", "N=4", "S=hello")
    assert r.returncode == 0, r.stderr
    doc = json.loads(tms_db(db, "param", "get", "BB").stdout)
    assert (
        doc["FLG"] is True
        and doc["N"] == 4
        and doc["V"] == 2.5
        and doc["S"] == "hello"
        and "$date" in doc["timestamps"]
    )
    r = tms_db(db, "param", "get", "NOPE", "--model-name", "zx200")
    assert r.returncode == 1 and "record 'NOPE' of model 'zx200' not found" in r.stderr
    r = tms_db(db, "dump", str(tmp_path / "dump"))
    assert r.returncode == 0 and (tmp_path / "dump" / "rostmsdb" / "task.json").exists()
    r = tms_db(tmp_path / "db2", "restore", str(tmp_path / "dump"))
    assert r.returncode == 0 and "parameter: 1" in r.stdout
    assert tms_db(tmp_path / "db2", "check").stdout.strip() == "consistent"


def test_seed(tmp_path, capsys) -> None:
    (tmp_path / "trees").mkdir()
    (tmp_path / "trees" / "t.xml").write_text(TREE)
    seed = tmp_path / "seed.yaml"
    seed.write_text(
        "tasks:\n  - {task_id: 10, file: trees/t.xml, description: dump haul}\n"
        "parameters:\n  - {model_name: zx200, type: static, record_name: release_angle, target_angle: 1.2}\n"
    )
    db = str(tmp_path / "db")
    for _ in range(2):  # idempotent
        assert cli_main(["--path", db, "seed", "paper", "--file", str(seed)]) == 0
    assert "1 task(s), 1 parameter document(s)" in capsys.readouterr().out
    with open_store(path=db) as store:
        assert store.get_task(10)["description"] == "dump haul"
        assert store.get_parameter("zx200", "release_angle")["target_angle"] == 1.2
    seed.write_text("tasks:\n  - {task_id: 10, file: trees/missing.xml}\n")
    assert cli_main(["--path", db, "seed", "paper", "--file", str(seed)]) == 1
    assert "seed.yaml:2: task file trees/missing.xml: No such file" in capsys.readouterr().err
    assert cli_main(["--path", db, "seed", "paper", "--file", str(tmp_path / "none.yaml")]) == 1
    assert "none.yaml: seed file not found" in capsys.readouterr().err
