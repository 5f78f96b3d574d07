"""The original's start path across processes: its GUI's client (TmsdbGetTask at ``/tms_db_reader_task``,
then ``std_msgs/String`` on ``/task_sequence``) starts tasks in our manager, with the DB reader, the
subtask servers and a planning stub each in its own process.

The client side is built on the peer's types only (tms_msg_db, std_msgs), and does what the original's
``tms_ur_button`` does when its button is pressed with ``task_ids`` set: one TmsdbGetTask call per id,
then ``json.dumps({"tasks": [{"task_id", "task_sequence"}, ...]}, ensure_ascii=False)``.

The first test runs on both stores: the embedded one, and MongoDB (the session's server, a database of its own)
opened by every node through its ``db_uri``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from tests.mongo_server import unique_database, with_database
from tests.rosproc import executable
from tests.tms_ts.test_integration import _one_leaf, _seed, _state

pytestmark = pytest.mark.integration


@pytest.fixture(params=["embedded", "mongodb"])
def backend(request: pytest.FixtureRequest, ts_system) -> Iterator[str]:
    """The store ``ts_system`` seeds and its nodes open: its embedded one, or a fresh MongoDB database."""
    if request.param == "embedded":
        yield request.param
        return
    from tms_db import open_store

    ts_system.db_uri = with_database(request.getfixturevalue("mongodb_uri"), unique_database())
    embedded, ts_system.store = ts_system.store, open_store(uri=ts_system.db_uri)
    try:
        yield request.param
    finally:
        ts_system.store._client.drop_database(ts_system.store.database)  # test cleanup
        ts_system.store.close()
        ts_system.store = embedded  # the fixture closes its own


def _gui_button(system, task_ids: list[int]) -> str:
    """The original GUI's message for ``task_ids``, read through the DB reader as it reads them."""
    from tms_msg_db.srv import TmsdbGetTask

    client = system.node.create_client(TmsdbGetTask, "/tms_db_reader_task")
    assert client.wait_for_service(timeout_sec=30), "/tms_db_reader_task not available"
    tasks = []
    for task_id in task_ids:
        future = client.call_async(TmsdbGetTask.Request(task_id=task_id))
        system.wait(future.done, 30, f"TmsdbGetTask({task_id})")
        assert future.result().task, f"task {task_id} empty from /tms_db_reader_task"
        tasks.append({"task_id": task_id, "task_sequence": future.result().task})
    return json.dumps({"tasks": tasks}, ensure_ascii=False)


def _embedded_is_empty(db: str) -> bool:
    from tms_db import open_store

    with open_store(path=db) as store:
        return store.list_tasks() == [] and store.list_parameters() == []


def _publish_task_sequence(system, data: str) -> None:
    from std_msgs.msg import String

    pub = system.pubs.get("/task_sequence")
    if pub is None:
        pub = system.pubs["/task_sequence"] = system.node.create_publisher(String, "/task_sequence", 10)
    system.wait(lambda: pub.get_subscription_count() > 0, 20, "the manager on /task_sequence")
    pub.publish(String(data=data))


def _goals(system) -> list[str]:
    return [line.split()[1] for line in system.procs["stub"].lines if line.startswith("GOAL ")]


def _start_with_reader(ts_system, procs, manager_args: tuple[str, ...] = ()):
    _seed(ts_system.store)
    ts_system.store.add_task(_one_leaf("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere", "load_point"), task_id=1)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose"), task_id=2
    )
    db = ["-p", f"db_uri:={ts_system.db_uri}"] if ts_system.db_uri else ["-p", f"db_path:={ts_system.db}"]
    reader = procs([executable("tms_db", "tms_db_reader"), "--ros-args", *db], name="reader")
    system = ts_system.start(stub_duration_s=0.2, manager_args=manager_args)
    system.procs["reader"] = reader
    return system


def test_the_original_guis_json_starts_its_tasks_and_an_xml_starts_the_stored_task(backend, ts_system, procs):
    from tms_msg.msg import TaskState

    system = _start_with_reader(ts_system, procs)
    if backend == "mongodb":
        assert "document store: MongoStore(" in system.procs["reader"].output, system.procs["reader"].output
        manager_out = system.procs["manager"].output
        assert f"db MongoStore('{ts_system.db_uri}', database='{ts_system.store.database}')" in manager_out, manager_out
        # the directory the nodes were also given stays empty: tasks and records can only come from the server
        assert ts_system.store.database != "rostmsdb" and _embedded_is_empty(ts_system.db)
    _publish_task_sequence(system, _gui_button(system, [1, 2]))
    system.wait(lambda: _state(system, 1) == TaskState.SUCCESS and _state(system, 2) == TaskState.SUCCESS, 120,
                "tasks 1 and 2 started from /task_sequence to succeed")
    assert sorted(_goals(system)) == ["/ic120/navigate_to_pose", "/zx200/tms_rp_zx200_change_pose"]

    # a bare XML (the original GUI with one task_id sends the reader's answer as it is) runs as the stored task
    xml = json.loads(_gui_button(system, [1]))["tasks"][0]["task_sequence"]
    _publish_task_sequence(system, xml.replace("><", ">\n  <"))
    system.wait(lambda: len(_goals(system)) == 3, 60, "task 1's second planning goal")
    system.wait(lambda: _state(system, 1) == TaskState.SUCCESS, 60, "task 1 to succeed again")
    assert _goals(system)[-1] == "/ic120/navigate_to_pose"
    assert "ad-hoc" not in system.procs["manager"].output
    if backend == "mongodb":
        assert _embedded_is_empty(ts_system.db)

    # what cannot start is named, and the manager goes on
    _publish_task_sequence(system, '{"tasks": [{"task_id": "x"}]}')
    assert system.procs["manager"].wait_for("/task_sequence: tasks[0] must be", 20), system.procs["manager"].output


def test_the_manager_parameter_task_id_picks_its_entry_of_the_json(ts_system, procs):
    from tms_msg.msg import TaskState

    system = _start_with_reader(ts_system, procs, manager_args=("-p", "task_id:=2"))
    _publish_task_sequence(system, _gui_button(system, [1, 2]))
    system.wait(lambda: _state(system, 2) == TaskState.SUCCESS, 120, "task 2 to succeed")
    system.spin(2.0)
    assert _state(system, 1) is None  # never started: the JSON's other entry is another manager's
    assert _goals(system) == ["/zx200/tms_rp_zx200_change_pose"]
