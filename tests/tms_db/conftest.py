"""Fixtures of the tms_db tests: one ``store`` fixture, run against every backend.

The embedded store runs in a fresh directory per test. The MongoDB backend runs against the session's server
(``mongodb_uri`` of tests/conftest.py: ``$TMS_MONGODB_URI`` when set, else a SecantusDB server started for the run),
a fresh database per test, dropped afterwards.
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest

from tms_db import Store, open_store


def mongo_database() -> str:
    """A database name no other test uses."""
    return f"tms_test_{uuid.uuid4().hex[:12]}"


@pytest.fixture(params=["embedded", "mongodb"])
def store(request: pytest.FixtureRequest, tmp_path) -> Iterator[Store]:
    if request.param == "mongodb":
        uri = request.getfixturevalue("mongodb_uri")
        name = mongo_database()
        s = open_store(uri=uri, database=name)
        yield s
        s._client.drop_database(name)  # test cleanup
        s.close()
    else:
        s = open_store(path=tmp_path / "db")
        yield s
        s.close()
