"""The MongoDB server gone mid-run and back: the store and the DB nodes report it and recover.

Each test starts a SecantusDB server of its own (never the user's ``$TMS_MONGODB_URI``: it is killed here), SIGKILLs
it mid-run, calls, restarts it on the same port and storage, and calls again. While it is gone every call ends within
the store's bound (:data:`tms_db.mongo.SERVER_TIMEOUT_S` of server selection, pymongo's one retry of a read included)
with a :class:`tms_db.errors.StoreError` naming the server, the call and the cause, never a raw pymongo error; once it
is back the next call succeeds on the data written before the kill.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator

import pytest

from tests.mongo_server import MongoServer, with_database
from tests.rosproc import executable
from tests.tms_db.test_nodes import _call
from tests.tms_db.test_store import BLACKBOARD, TREE, WAYPOINTS
from tms_db import StoreError, open_store
from tms_db.mongo import SERVER_TIMEOUT_S

#: [s] the longest a call may take while the server is gone: one server selection, a read's retry, and slack for a
#: loaded 2-core machine
BOUND_S = 2 * SERVER_TIMEOUT_S + 5.0


@pytest.fixture
def server() -> Iterator[MongoServer]:
    with MongoServer() as srv:
        yield srv


def _seed(uri: str) -> None:
    # journaled: a write acknowledged less than ~0.2 s before a SIGKILL of the server was lost without it (measured
    # on SecantusDB, as mongod's default j:false loses up to its 100 ms journal interval)
    with open_store(uri=f"{uri}?journal=true") as store:
        store.add_task(TREE, task_id=5)
        store.upsert_parameter(WAYPOINTS)
        store.upsert_parameter(BLACKBOARD)


def _timed(call):
    """(the StoreError ``call()`` raised, seconds it took); fails when it raises anything else or nothing."""
    start = time.monotonic()
    with pytest.raises(StoreError) as caught:
        call()
    return caught.value, time.monotonic() - start


def test_the_store_names_the_server_and_the_call_and_recovers(server) -> None:
    uri = with_database(server.uri, "outage")
    _seed(uri)
    store = open_store(uri=uri)
    try:
        assert store.get_task(5)["task_sequence"].startswith("<root")
        server.kill()
        for call, what in ((lambda: store.get_task(5), "get_task(5)"),
                           (lambda: store.set_fields("SAMPLE_GLOBAL_BLACKBOARD", {"sample_val_int": 9}),
                            "set_fields('SAMPLE_GLOBAL_BLACKBOARD', {'sample_val_int': 9})"),
                           (lambda: list(store.export_collection("task")), "export_collection('task')")):
            exc, took = _timed(call)
            text = str(exc)
            assert took < BOUND_S, f"{what}: {took:.1f} s"
            assert text.startswith(f"MongoDB {uri} (database 'outage'): {what} failed: the server did not answer"), text
            assert type(exc) is StoreError and exc.__suppress_context__  # no pymongo traceback chained to it
        # opening a store on a server that is gone: the same bound and naming
        exc, took = _timed(lambda: open_store(uri=uri))
        assert took < BOUND_S and f"MongoDB {uri}: opening the store failed: the server did not answer" in str(exc)

        server.restart()
        assert store.get_task(5)["task_sequence"].startswith("<root")  # the same client, reconnected
        assert store.set_fields("SAMPLE_GLOBAL_BLACKBOARD", {"sample_val_int": 9})["sample_val_int"] == 9
        assert store.get_parameter("ic120", "LOAD_PATH")["x"] == WAYPOINTS["x"]  # written before the kill
        assert store.check() == []
    finally:
        store.close()


@pytest.mark.integration
def test_the_reader_node_answers_and_logs_while_the_server_is_gone_and_recovers(server, procs, ros_node) -> None:
    """``tms_db_reader`` (and ``tms_db_writer``) on MongoDB: the original's answers for a failed look-up ("" / empty
    lists; the writer's ``success`` false with the reason) and a log line naming the server and the call, within
    the bound; the same processes answer from the intact data once the server is back."""
    from tms_msg.srv import SetParameter
    from tms_msg_db.srv import TmsdbGetParameter, TmsdbGetTask

    uri = with_database(server.uri, "outage")
    _seed(uri)
    reader = procs([executable("tms_db", "tms_db_reader"), "--ros-args", "-p", f"db_uri:={uri}"], name="reader")
    writer = procs([executable("tms_db", "tms_db_writer"), "--ros-args", "-p", f"db_uri:={uri}"], name="writer")
    get_task = ros_node.create_client(TmsdbGetTask, "/tms_db_reader_task")
    get_param = ros_node.create_client(TmsdbGetParameter, "/tms_db_reader_parameter")
    set_param = ros_node.create_client(SetParameter, "/tms_db_writer/set_parameter")
    assert reader.wait_for("document store: MongoStore", 60), reader.output

    assert _call(ros_node, get_task, TmsdbGetTask.Request(task_id=5)).task.startswith("<root")
    server.kill()

    start = time.monotonic()
    reply = _call(ros_node, get_task, TmsdbGetTask.Request(task_id=5), timeout=BOUND_S + 10)
    took = time.monotonic() - start
    assert reply.task == "" and took < BOUND_S, f"{reply.task[:80]!r} after {took:.1f} s"
    assert reader.wait_for(f"MongoDB {uri} (database 'outage'): get_task(5) failed: the server did not answer", 10), \
        reader.output
    reply = _call(ros_node, get_param, TmsdbGetParameter.Request(model_name="ic120", record_name="LOAD_PATH"),
                  timeout=BOUND_S + 10)
    assert list(reply.keys) == [] and list(reply.values) == []
    assert reader.wait_for("get_parameter('ic120', 'LOAD_PATH') failed", 10), reader.output
    fields = json.dumps({"sample_val_int": 11})
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=fields),
                  timeout=BOUND_S + 10)
    assert not reply.success and f"MongoDB {uri}" in reply.message and "set_fields(" in reply.message, reply.message
    assert "Traceback" not in reader.output + writer.output

    server.restart()
    reply = _call(ros_node, get_task, TmsdbGetTask.Request(task_id=5))
    assert 'record_name="initial_pose"' in reply.task and reply.task.startswith("<root"), reader.output
    reply = _call(ros_node, get_param, TmsdbGetParameter.Request(model_name="ic120", record_name="LOAD_PATH"))
    assert [v for k, v in zip(reply.keys, reply.values, strict=True) if k == "x"] == [str(x) for x in WAYPOINTS["x"]]
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=fields))
    assert reply.success, reply.message
    with open_store(uri=uri) as store:
        assert store.get_record("SAMPLE_GLOBAL_BLACKBOARD")["sample_val_int"] == 11
    assert reader.popen.poll() is None and writer.popen.poll() is None  # the nodes lived through it


def test_open_store_names_an_option_the_backend_does_not_take(tmp_path) -> None:
    """A misspelt or other backend's option is refused naming it before any server is contacted (no 5 s wait)."""
    start = time.monotonic()
    with pytest.raises(StoreError, match=r"option\(s\) databse not taken by MongoStore \(it takes database, timeout_s"):
        open_store(uri="mongodb://127.0.0.1:1/x", databse="y")
    with pytest.raises(StoreError, match=r"option\(s\) synchronous not taken by MongoStore"):
        open_store(uri="mongodb://127.0.0.1:1/x", synchronous="FULL")
    assert time.monotonic() - start < 1.0
    with pytest.raises(StoreError, match=r"option\(s\) database not taken by EmbeddedStore"):
        open_store(path=tmp_path / "db", database="rostmsdb")
    assert not (tmp_path / "db").exists()  # nothing created
