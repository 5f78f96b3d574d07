"""Fixtures of the tms_db tests: one ``store`` fixture, run against every backend.

The embedded store runs in a fresh directory per test. The MongoDB backend runs against the session's server
(``mongodb_uri`` of tests/conftest.py: ``$TMS_MONGODB_URI`` when set, else a SecantusDB server started for the run),
a fresh database per test, dropped afterwards.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.mongo_server import unique_database
from tms_db import Store, open_store


@pytest.fixture(params=["embedded", "mongodb"])
def store(request: pytest.FixtureRequest, tmp_path) -> Iterator[Store]:
    if request.param == "mongodb":
        uri = request.getfixturevalue("mongodb_uri")
        name = unique_database()
        s = open_store(uri=uri, database=name)
        yield s
        s._client.drop_database(name)  # test cleanup
        s.close()
    else:
        s = open_store(path=tmp_path / "db")
        yield s
        s.close()
