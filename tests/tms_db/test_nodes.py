"""``tms_db_reader`` / ``tms_db_writer`` as separate processes over DDS, sharing one on-disk store."""

from __future__ import annotations

import json
import time

import pytest

from tests.rosproc import executable
from tests.tms_db.test_store import BLACKBOARD, TREE, WAYPOINTS
from tms_db import open_store

pytestmark = pytest.mark.integration


def _call(node, client, request, timeout: float = 30.0):
    assert client.wait_for_service(timeout_sec=timeout), f"service {client.srv_name} not available"
    future = client.call_async(request)
    deadline = time.monotonic() + timeout
    while not future.done():
        assert time.monotonic() < deadline, f"no reply from {client.srv_name}"
        node.executor_for_test.spin_once(timeout_sec=0.1)
    return future.result()


def test_reader_and_writer_nodes(procs, ros_node, tmp_path) -> None:
    """The reader's clients are built on the original's types only (tms_msg_db), as its GUI and subtasks are."""
    from tms_msg.msg import ParameterUpdate
    from tms_msg.srv import SetParameter
    from tms_msg_db.srv import TmsdbGetParameter, TmsdbGetTask


    db = tmp_path / "db"
    with open_store(path=db) as store:
        store.add_task(TREE, task_id=5)
        store.upsert_parameter(WAYPOINTS)
        store.upsert_parameter(BLACKBOARD)
    reader = procs([executable("tms_db", "tms_db_reader"), "--ros-args", "-p", f"db_path:={db}"])
    writer = procs([executable("tms_db", "tms_db_writer"), "--ros-args", "-p", f"db_path:={db}"])
    get_task = ros_node.create_client(TmsdbGetTask, "/tms_db_reader_task")
    get_param = ros_node.create_client(TmsdbGetParameter, "/tms_db_reader_parameter")
    set_param = ros_node.create_client(SetParameter, "/tms_db_writer/set_parameter")


    reply = _call(ros_node, get_task, TmsdbGetTask.Request(task_id=5))
    assert 'record_name="initial_pose"' in reply.task and reply.task.startswith("<root"), reader.output
    reply = _call(ros_node, get_task, TmsdbGetTask.Request(task_id=6))
    assert reply.task == ""  # the original's answer for an unknown id
    assert reader.wait_for("task_id 6: no such task", timeout=10), reader.output

    reply = _call(ros_node, get_param, TmsdbGetParameter.Request(model_name="ic120", record_name="LOAD_PATH"))
    keys = list(reply.keys)
    assert keys.count("x") == 3 and reply.values[keys.index("x")] == "1.0"
    assert [v for k, v in zip(keys, reply.values, strict=True) if k == "qw"] == ["1.0", "1.0", "1.0"]
    assert not {"_id", "model_name", "type", "record_name"} & set(keys)
    reply = _call(ros_node, get_param, TmsdbGetParameter.Request(model_name="zx200", record_name="LOAD_PATH"))
    assert list(reply.keys) == [] and list(reply.values) == []
    assert reader.wait_for("record 'LOAD_PATH' of model 'zx200' not found", timeout=10), reader.output

    # service write -> visible through the reader process, types kept
    fields = json.dumps({"sample_flg": True, "sample_val_int": 7, "sample_val_double": 2.0})
    reply = _call(ros_node, set_param, SetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=fields))
    assert reply.success, reply.message
    reply = _call(ros_node, get_param, TmsdbGetParameter.Request(record_name="SAMPLE_GLOBAL_BLACKBOARD"))
    values = dict(zip(reply.keys, reply.values, strict=True))
    assert values["sample_flg"] == "True" and values["sample_val_int"] == "7" and values["sample_val_double"] == "2.0"
    assert values["timestamps"].startswith("20")  # str() of the write's UTC datetime
    with open_store(path=db) as store:
        doc = store.get_record("SAMPLE_GLOBAL_BLACKBOARD")
    assert doc["sample_flg"] is True and type(doc["sample_val_int"]) is int

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
        pub.publish(
            ParameterUpdate(record_name="SAMPLE_GLOBAL_BLACKBOARD", fields_json=json.dumps({"sample_val_int": n}))
        )
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
