"""Concurrency and durability of the store across real processes (issue 7 "What must be shown"), on both backends:
the embedded store in a directory, MongoDB on the session's server (a database of the test's own).

The 30 s, 4 + 4 process campaign is ``python -m tests.bench tms_db``; this is its shorter version.
"""

from __future__ import annotations

import random
import signal
import time
from collections.abc import Iterator

import pytest

from tests.mongo_server import unique_database, with_database
from tests.tms_db.hammer import open_at
from tests.tms_db.workers import run_hammer, spawn, verify_store
from tms_db import open_store

pytestmark = pytest.mark.slow


@pytest.fixture(params=["embedded", "mongodb"])
def backend(request: pytest.FixtureRequest, tmp_path) -> Iterator[str]:
    """Where the workers' store is: a directory, or a MongoDB URI naming a fresh database (dropped afterwards)."""
    if request.param == "embedded":
        yield str(tmp_path / "db")
        return
    uri = with_database(request.getfixturevalue("mongodb_uri"), unique_database())
    yield uri
    with open_store(uri=uri) as store:
        store._client.drop_database(store.database)  # test cleanup


def test_four_writers_four_readers_lose_nothing(backend, tmp_path) -> None:
    db = backend
    wsum, rsum, acks, _ = run_hammer(db, tmp_path, writers=4, readers=4, seconds=6.0)
    assert all(w["inc"] > 20 and w["flag"] > 20 for w in wsum), wsum  # every writer made progress
    assert all(r["reads"] > 100 for r in rsum), rsum
    assert [r["first_problems"] for r in rsum] == [[]] * 4  # no torn document, nothing went backwards
    assert verify_store(db, acks, exact=True) == []  # no lost update, every acknowledged write present


def test_sigkilled_writer_loses_no_acknowledged_write(backend, tmp_path) -> None:
    db = backend
    from tests.tms_db import hammer

    hammer.prepare(str(db), 2)
    acks = [tmp_path / "ack0.log", tmp_path / "ack1.log"]
    steady = spawn("writer", db, "--wid", "1", "--seconds", "12", "--ack", str(acks[1]))
    rng = random.Random(7)
    kills = 0
    for _round in range(4):  # kill writer 0 at random moments, restart it, kill again
        victim = spawn("writer", db, "--wid", "0", "--seconds", "60", "--ack", str(acks[0]))
        deadline = time.monotonic() + 20
        while not acks[0].exists() or acks[0].stat().st_size < 200 * (_round + 1):  # it is writing now
            assert time.monotonic() < deadline, "writer 0 never started writing"
            time.sleep(0.05)
        time.sleep(rng.uniform(0.0, 0.3))
        victim.send_signal(signal.SIGKILL)
        victim.wait(10)
        assert victim.returncode == -signal.SIGKILL
        kills += 1
        # the store reopens and is consistent while the other writer keeps going
        with open_at(db) as store:
            assert store.check() == []
    steady.wait(60)
    assert steady.returncode == 0
    assert kills == 4
    # A killed writer's last write may be committed but not yet acknowledged (one ahead), never lost:
    # restarts continue its numbering, so its last acknowledged seq/flag must be there (or one more),
    # and the shared counters hold every acknowledged increment (plus at most one per kill).
    assert verify_store(db, acks, exact=False, slack=kills) == []
    with open_at(db) as store:
        doc = store.get_record("W0")
        assert doc["neg"] == -doc["seq"] and doc["arr"] == [doc["seq"]] * 7  # whole, never torn
