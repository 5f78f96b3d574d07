"""Design surfaces in the store (tms_db.design): the collection ``design`` of ours, beside the original's, and the
``tms-db design`` commands (both backends where a store is used)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tms_db import (
    DESIGN_COLLECTION,
    RecordNotFound,
    Store,
    ValidationError,
    get_design,
    list_designs,
    open_store,
    put_design,
)
from tms_db.cli import main as cli_main
from tms_rp.excavation.design import Design

TRENCH = Design.from_dict({"name": "t1", "kind": "trench", "start": [-5.0, -5.0], "end": [-5.0, 5.0], "width": 1.0,
                           "depth": 0.5, "ground_z": 0.0, "margin": 0.5}).to_dict()


def test_put_and_get_round_trip(store: Store) -> None:
    put_design(store, TRENCH)
    got = get_design(store, "t1")
    assert got == TRENCH
    assert Design.from_dict(got).to_dict() == TRENCH
    assert list_designs(store) == ["t1"]
    # beside the original's collections: none of them holds it
    assert DESIGN_COLLECTION in store.data_types()
    assert store.list_parameters() == [] and store.list_tasks() == []


def test_newest_version_wins_and_the_same_document_adds_nothing(store: Store) -> None:
    first = put_design(store, TRENCH, time="2026-01-01T00:00:00.000000+00:00")
    assert put_design(store, TRENCH) == first  # the same document again: nothing added
    deeper = {**TRENCH, "depth": 0.8}
    put_design(store, deeper, time="2026-01-02T00:00:00.000000+00:00")
    assert get_design(store, "t1")["depth"] == 0.8
    assert len(store.find_data(DESIGN_COLLECTION, 3040, name="t1")) == 2  # the older version stays readable


def test_a_missing_design_is_named_with_the_stored_ones(store: Store) -> None:
    put_design(store, TRENCH)
    with pytest.raises(RecordNotFound, match=r"design 'nope': not in the store's collection 'design' \(stored: 't1'"):
        get_design(store, "nope")


@pytest.mark.parametrize("doc", [{"kind": "trench"}, {"name": ""}, {"name": 3}, ["name", "t"]])
def test_a_document_without_a_name_is_refused(store: Store, doc: object) -> None:
    with pytest.raises(ValidationError, match="design document"):
        put_design(store, doc)  # type: ignore[arg-type]
    assert list_designs(store) == []


def test_cli_put_list_show(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "db"
    f = tmp_path / "d.yaml"
    f.write_text("designs:\n  - name: e1\n    kind: embankment\n    start: [0, 0]\n    end: [4, 0]\n"
                 "    crest_width: 1.0\n    height: 0.4\n    base_z: 0.0\n    slope_left: 1.5\n    slope_right: 1.5\n")
    assert cli_main(["--path", str(db), "design", "put", str(f)]) == 0
    assert cli_main(["--path", str(db), "design", "list"]) == 0
    assert cli_main(["--path", str(db), "design", "show", "e1"]) == 0
    out = capsys.readouterr().out
    assert "design 'e1' (embankment)" in out and "\ne1\n" in out and '"crest_width": 1.0' in out
    assert cli_main(["--path", str(db), "design", "show", "e2"]) == 1
    assert "design 'e2': not in the store's collection 'design' (stored: 'e1'" in capsys.readouterr().err


def test_cli_refuses_a_bad_design_naming_file_line_and_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "db"
    f = tmp_path / "d.yaml"
    f.write_text("name: bad\nkind: trench\nstart: [0, 0]\nend: [4, 0]\nwidth: 1.0\nground_z: 0.0\ndepth: -1\n")
    assert cli_main(["--path", str(db), "design", "put", str(f)]) == 1
    err = capsys.readouterr().err
    assert f"{f}:1: design 'bad' (trench): depth = -1 is out of range" in err
    with open_store(path=db) as store:
        assert list_designs(store) == []
