"""``tms_db_reader`` / ``tms_db_writer`` as separate processes over DDS, sharing one on-disk store."""

from __future__ import annotations

import json
import time

import pytest

from tests.rosproc import executable
from tests.tms_db.test_store import BLACKBOARD, TREE, WAYPOINTS
from tms_db import open_store

pytestmark = pytest.mark.integration


def _call(node, client, request, timeout: float = 30.0):  # noqa: ANN001, ANN202
    assert client.wait_for_service(timeout_sec=timeout), f"service {client.srv_name} not available"
    future = client.call_async(request)
    deadline = time.monotonic() + timeout
    while not future.done():
        assert time.monotonic() < deadline, f"no reply from {client.srv_name}"
        node.executor_for_test.spin_once(timeout_sec=0.1)
    return future.result()


def test_reader_and_writer_nodes(procs, ros_node, tmp_path) -> None:
    from tms_msg.msg import ParameterUpdate
    from tms_msg.srv import GetParameter, GetTask, SetParameter

    db = tmp_path / "db"
    with open_store(path=db) as store:
        store.add_task(TREE, task_id=5)
        store.upsert_parameter(WAYPOINTS)
        store.upsert_parameter(BLACKBOARD)
    reader = procs([executable("tms_db", "tms_db_reader"), "--ros-args", "-p", f"db_path:={db}"])
    writer = procs([executable("tms_db", "tms_db_writer"), "--ros-args", "-p", f"db_path:={db}"])
    get_task = ros_node.create_client(GetTask, "/tms_db_reader/get_task")
    get_param = ros_node.create_client(GetParameter, "/tms_db_reader/get_parameter")
    set_param = ros_node.create_client(SetParameter, "/tms_db_writer/set_parameter")

    reply = _call(ros_node, get_task, GetTask.Request(task_id=5))
    assert reply.found and 'record_name="initial_pose"' in reply.task, reader.output
    reply = _call(ros_node, get_task, GetTask.Request(task_id=6))
    assert not reply.found and reply.task == "" and "task_id 6" in reply.message

    reply = _call(ros_node, get_param, GetParameter.Request(model_name="ic120", record_name="LOAD_PATH"))
    assert reply.found
    assert list(reply.keys).count("x") == 3 and reply.values[list(reply.keys).index("x")] == "1.0"
    assert json.loads(reply.document_json)["qw"] == [1.0, 1.0, 1.0]
    reply = _call(ros_node, get_param, GetParameter.Request(model_name="zx200", record_name="LOAD_PATH"))
    assert not reply.found and "record 'LOAD_PATH' of model 'zx200' not found" in reply.message

    # service write -> visible through the reader process, types kept
    fields = json.dumps({"sample_flg": True, "sample_val_int": 7, "sample_val_double": 2.0})
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=fields))
    assert reply.success, reply.message
    reply = _call(ros_node, get_param, GetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD"))
    doc = json.loads(reply.document_json)
    assert doc["sample_flg"] is True and doc["sample_val_int"] == 7 and "$date" in doc["timestamps"]
    assert reply.values[list(reply.keys).index("sample_flg")] == "true"
    assert reply.values[list(reply.keys).index("sample_val_double")] == "2.0"

    # bad writes are refused naming record and field; nothing changes
    reply = _call(ros_node, set_param, SetParameter.Request(model_name="ic120", record_name="LOAD_PATH",
                                                            fields_json='{"y": 3.0}'))
    assert not reply.success and "record 'LOAD_PATH'" in reply.message and "field 'y'" in reply.message
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="NEW_GROUP", fields_json='{"F": 1'))
    assert not reply.success and "not valid JSON" in reply.message
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="NEW_GROUP", fields_json='{"F": false}'))
    assert not reply.success and "record 'NEW_GROUP' not found" in reply.message
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="NEW_GROUP", fields_json='{"F": false}',
                                                            upsert=True))
    assert reply.success

    # topic path: fire-and-forget updates, applied in order
    pub = ros_node.create_publisher(ParameterUpdate, "/tms_db_writer/parameter_update", 100)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0:
        assert time.monotonic() < deadline, "tms_db_writer never subscribed"
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)
    for n in range(1, 21):
        pub.publish(ParameterUpdate(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=json.dumps({"sample_val_int": n})))
    pub.publish(ParameterUpdate(record_name="MISSING_GROUP", fields_json='{"F": true}'))
    deadline = time.monotonic() + 30
    while True:
        with open_store(path=db) as store:
            value = store.get_record("SAMPLE_GLOBAL_BLACKBOARD")["sample_val_int"]
        if value == 20:
            break
        assert time.monotonic() < deadline, f"topic updates not applied (value {value}):\n{writer.output}"
        time.sleep(0.2)
    assert writer.wait_for("parameter_update dropped: record 'MISSING_GROUP' not found", timeout=10), writer.output
