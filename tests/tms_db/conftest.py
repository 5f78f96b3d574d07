"""Fixtures of the tms_db tests: one ``store`` fixture, run against every backend.

The embedded store runs everywhere (a fresh directory per test). The MongoDB backend runs when
``TMS_MONGODB_URI`` names a server (a fresh database per test, dropped afterwards) and is skipped
naming that variable otherwise.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator

import pytest

from tms_db import Store, open_store

MONGO_URI = os.environ.get("TMS_MONGODB_URI", "")


@pytest.fixture(params=["embedded", "mongodb"])
def store(request: pytest.FixtureRequest, tmp_path) -> Iterator[Store]:
    if request.param == "mongodb":
        if not MONGO_URI:
            pytest.skip("MongoDB backend: set TMS_MONGODB_URI=mongodb://host:port to run it (no server here)")
        name = f"tms_test_{uuid.uuid4().hex[:12]}"
        s = open_store(uri=MONGO_URI, database=name)
        yield s
        s._client.drop_database(name)  # test cleanup
        s.close()
    else:
        s = open_store(path=tmp_path / "db")
        yield s
        s.close()
