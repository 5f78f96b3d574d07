"""Binary objects (the original's GridFS files) on both backends: put / get intact, find by fields, latest, the size
limit, delete; the embedded store's all-or-nothing put under a failure mid-write."""

from __future__ import annotations

import hashlib
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from tests.rosproc import ROOT
from tms_db import BlobTooLarge, RecordNotFound, Store, ValidationError, open_store
from tms_db.data import BLOB_CHUNK_BYTES
from tms_db.embedded import EmbeddedStore


def test_ten_megabyte_heightmap_round_trip(store: Store) -> None:
    data = os.urandom(10 * 1000 * 1000 + 7)  # not a multiple of the chunk size
    fid = store.put_blob(data, filename="heightmap.png", time="2024-05-01T10:00:00.000000", type="static", id=3)
    assert isinstance(fid, str)
    assert hashlib.sha256(store.get_blob(fid)).hexdigest() == hashlib.sha256(data).hexdigest()
    (doc,) = store.find_blobs({"filename": "heightmap.png"})
    assert doc["_id"] == fid and doc["length"] == len(data)
    assert (doc["time"], doc["type"], doc["id"]) == ("2024-05-01T10:00:00.000000", "static", 3)
    assert doc["uploadDate"].tzinfo is not None and "data" not in doc


def test_empty_blob(store: Store) -> None:
    fid = store.put_blob(b"", filename="empty.bin")
    assert store.get_blob(fid) == b"" and store.find_blobs()[0]["length"] == 0


def test_find_blobs_filter_order_and_latest(store: Store) -> None:
    a = store.put_blob(b"dem-2", filename="dem.tif", time="2024-05-01T10:00:02.0", type="dem", id=1)
    b = store.put_blob(b"dem-1", filename="dem.tif", time="2024-05-01T10:00:01.0", type="dem", id=1)
    c = store.put_blob(b"mesh", filename="mesh.ply", time="2024-05-01T10:00:03.0", type="mesh", id=1)
    assert [d["_id"] for d in store.find_blobs({"type": "dem"})] == [b, a]
    assert [d["_id"] for d in store.find_blobs()] == [b, a, c]
    (latest,) = store.find_blobs({"type": "dem", "filename": "dem.tif"}, latest_only=True)
    assert store.get_blob(latest["_id"]) == b"dem-2"
    assert store.find_blobs({"type": "static"}) == [] and store.find_blobs({"type": "x"}, latest_only=True) == []
    assert [d["_id"] for d in store.find_blobs({"id": 1, "type": "mesh"})] == [c]


def test_dynamic_terrain_fields_as_the_original_writes_them(store: Store) -> None:
    # the original's dynamic terrain: no filename, the PointCloud2's fields beside the data
    fid = store.put_blob(b"1,2,3", filename=None, time="2024-05-01T10:00:00.0", type="dynamic", id=0, height=1,
                         width=3, is_bigendian=False, fields=["PointField(name='x')"], is_dense=True)
    (doc,) = store.find_blobs({"type": "dynamic"}, latest_only=True)
    assert doc["_id"] == fid and "filename" not in doc and doc["is_bigendian"] is False and doc["width"] == 3
    assert store.get_blob(fid).decode().split(",") == ["1", "2", "3"]


def test_over_the_limit_refused_and_nothing_stored(store: Store) -> None:
    store.max_blob_bytes = 1000
    with pytest.raises(BlobTooLarge) as err:
        store.put_blob(b"x" * 1001, filename="big.png", type="static")
    text = str(err.value)
    assert "big.png" in text and "1,001" in text and "1,000" in text
    assert isinstance(err.value, ValidationError) and (err.value.size, err.value.limit) == (1001, 1000)
    assert store.find_blobs() == []
    store.put_blob(b"x" * 1000, filename="fits.png")  # the limit itself fits
    assert [d["filename"] for d in store.find_blobs()] == ["fits.png"]


def test_open_store_option_and_default_limit(tmp_path) -> None:
    with open_store(path=tmp_path / "db", max_blob_bytes=10) as s:
        assert s.max_blob_bytes == 10
        with pytest.raises(BlobTooLarge, match="over the store's limit of 10"):
            s.put_blob(b"x" * 11, filename="a")
    with open_store(path=tmp_path / "db") as s:
        assert s.max_blob_bytes == 64 * 1024 * 1024


def test_get_and_delete_unknown_id_named(store: Store) -> None:
    fid = store.put_blob(b"abc", filename="a.bin")
    store.delete_blob(fid)
    for call in (store.get_blob, store.delete_blob):
        with pytest.raises(RecordNotFound, match=fid):
            call(fid)
        with pytest.raises(RecordNotFound, match="not-an-id"):
            call("not-an-id")
    assert store.find_blobs() == []


def test_bad_arguments_refused(store: Store) -> None:
    with pytest.raises(ValidationError, match="filename"):
        store.put_blob(b"x", filename=3)  # type: ignore[arg-type]
    with pytest.raises(ValidationError, match="bytes"):
        store.put_blob("text", filename="a")  # type: ignore[arg-type]
    with pytest.raises(ValidationError, match="'length'"):
        store.put_blob(b"x", filename="a", length=5)
    with pytest.raises(ValidationError, match="'bad'"):
        store.put_blob(b"x", filename="a", bad={1, 2})
    with pytest.raises(ValidationError, match="\\$gt"):
        store.find_blobs({"$gt": 1})
    assert store.find_blobs() == []


def test_embedded_put_is_all_or_nothing(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure after some chunks are written (a crash mid-put) leaves no file document and no chunk."""
    store = EmbeddedStore(tmp_path / "db")
    keep = store.put_blob(b"k" * 10, filename="kept.bin")
    written = []
    real = EmbeddedStore._write_chunk

    def failing(conn: sqlite3.Connection, file_oid: str, n: int, data: bytes) -> None:
        if n == 2:
            raise OSError("simulated crash mid-write")
        real(conn, file_oid, n, data)
        written.append(n)

    monkeypatch.setattr(EmbeddedStore, "_write_chunk", staticmethod(failing))
    with pytest.raises(OSError, match="simulated crash"):
        store.put_blob(os.urandom(5 * BLOB_CHUNK_BYTES), filename="half.bin")
    assert written == [0, 1], "the failure came after two chunks were written"
    monkeypatch.undo()
    assert [d["filename"] for d in store.find_blobs()] == ["kept.bin"]
    assert store._query("SELECT COUNT(*) FROM blob_chunks")[0][0] == 1  # only kept.bin's one chunk
    assert store.check() == [] and store.get_blob(keep) == b"k" * 10
    store.close()


def test_embedded_dump_names_blobs_as_gridfs(tmp_path) -> None:
    with EmbeddedStore(tmp_path / "a") as a, EmbeddedStore(tmp_path / "b") as b:
        data = os.urandom(BLOB_CHUNK_BYTES + 5)
        fid = a.put_blob(data, filename="x.png", type="static")
        assert {"fs.files", "fs.chunks"} <= set(a.collection_names())
        chunks = list(a.export_collection("fs.chunks"))
        assert [c["n"] for c in chunks] == [0, 1] and str(chunks[0]["files_id"]) == fid
        results = b.import_collections([(n, list(a.export_collection(n))) for n in ("fs.files", "fs.chunks")])
        assert all(r.loaded and not r.rejected for r in results)
        assert b.get_blob(fid) == data and b.check() == []


def test_cli_dump_restore_carries_data_and_blobs(tmp_path) -> None:
    """``tms-db dump`` writes blobs as GridFS's fs.files / fs.chunks (mongodump's layout) and data collections by
    name; ``restore`` into an empty store gives the same dump back, byte for byte, and the same reads."""
    data = os.urandom(2 * BLOB_CHUNK_BYTES + 11)
    with open_store(path=tmp_path / "a") as a:
        a.insert_data({"time": "2024-05-01T10:00:00.0", "type": "machine_pose", "id": 1, "name": "zx200",
                       "msg": {"x": 1.5}})
        fid = a.put_blob(data, filename="heightmap.png", time="2024-05-01T10:00:00.0", type="static", id=1)
    exe = Path(sys.prefix) / "bin" / "tms-db"

    def cli(db: str, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(exe), "--path", str(tmp_path / db), *args], capture_output=True, text=True,
                              timeout=60, cwd=ROOT)

    first = cli("a", "dump", str(tmp_path / "d1"))
    assert first.returncode == 0, first.stderr
    assert sorted(p.name for p in (tmp_path / "d1" / "rostmsdb").iterdir()) == [
        "fs.chunks.json", "fs.files.json", "machine_pose.json"]
    restored = cli("b", "restore", str(tmp_path / "d1"))
    assert restored.returncode == 0, restored.stderr
    assert cli("b", "dump", str(tmp_path / "d2")).returncode == 0
    for name in ("fs.chunks.json", "fs.files.json", "machine_pose.json"):
        assert (tmp_path / "d1" / "rostmsdb" / name).read_bytes() == (tmp_path / "d2" / "rostmsdb" / name).read_bytes()
    with open_store(path=tmp_path / "b") as b:
        assert b.get_blob(fid) == data and b.check() == []
        assert [d["msg"] for d in b.find_data("machine_pose", 1, latest_only=True)] == [{"x": 1.5}]
