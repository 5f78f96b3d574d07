"""The embedded store's background WAL checkpoint (``Store.checkpoint_in_background``): the writing connection no
longer checkpoints inside a commit, the store's thread keeps the WAL from growing, nothing written is lost, and a
bad period is refused naming the store."""

from __future__ import annotations

import os
import time

import pytest

from tms_db import StoreError, open_store
from tms_db.embedded import BACKSTOP_CHECKPOINT_PAGES, DB_FILE


def _write(store, n: int, pause_s: float) -> None:
    store.upsert_parameter({"record_name": "BB", "type": "dynamic", "N": 0})
    for i in range(n):
        store.set_fields("BB", {f"T{i % 10}": i, "N": i})
        time.sleep(pause_s)


def test_background_checkpoint_bounds_the_wal_and_keeps_every_write(tmp_path) -> None:
    store = open_store(path=tmp_path / "db")
    store.checkpoint_in_background(0.05)
    thread = store._checkpointer
    assert thread is not None and thread.is_alive()
    # the writer's own automatic checkpoint only as a backstop
    assert store._query("PRAGMA wal_autocheckpoint") == [(BACKSTOP_CHECKPOINT_PAGES,)]
    _write(store, 300, 0.01)
    wal = tmp_path / "db" / f"{DB_FILE}-wal"
    # 300 commits of >= 1 page (4 KiB + a 24-byte frame header) each: 1.24 MB and more had nothing checkpointed
    # and restarted the WAL (the backstop is 10,000 pages away). Alone it stays near 0.1 MB; on a loaded 2-core CI
    # machine the thread catches up less often (0.61 MB seen), so the bound is the WAL of 200 of the 300 commits:
    # the WAL restarted at least once, which only the thread can have done here
    assert os.path.getsize(wal) < 200 * (4096 + 24), os.path.getsize(wal)
    store.close()
    assert not thread.is_alive()
    with open_store(path=tmp_path / "db") as again:
        record = again.get_record("BB")
        assert record["N"] == 299 and [record[f"T{k}"] for k in range(10)] == list(range(290, 300))
        assert again.check() == []


def test_without_the_thread_the_writer_checkpoints_itself(tmp_path) -> None:
    with open_store(path=tmp_path / "db") as store:
        assert store._query("PRAGMA wal_autocheckpoint") == [(1000,)]  # SQLite's default
        _write(store, 1500, 0.0)
        # 1500 commits of >= 1 page (4 KiB + a 24-byte frame header) each: over 6.1 MB had nothing checkpointed;
        # SQLite's own checkpoint after 1000 pages restarts the WAL from its start, so it stays near 4.1 MB
        wal = os.path.getsize(tmp_path / "db" / f"{DB_FILE}-wal")
        assert wal < 4.5e6, wal
    with open_store(path=tmp_path / "db") as again:
        assert again.get_record("BB")["N"] == 1499


@pytest.mark.parametrize("period", [0.0, -1.0])
def test_a_bad_period_is_refused_naming_the_store(tmp_path, period: float) -> None:
    with open_store(path=tmp_path / "db") as store, pytest.raises(StoreError, match=r"rostmsdb\.sqlite3.*period"):
        store.checkpoint_in_background(period)
