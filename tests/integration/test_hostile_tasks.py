"""One manager process, real rclpy over DDS: a task with an invalid machine name ends FAILURE naming it, while another
task on the same manager runs to SUCCESS, and the manager never exits (issue 38).

The original's task files hold a typo ``d37pxi_24＿`` (a full-width underscore); creating the action client for it
raised ``ValueError`` inside the manager's tick timer, which ended the site_server process and with it every machine.
The bad trees are stored through the store's API (as a restore of an older database, or the original's, holds them;
``tms-db task add`` now refuses them), one with the name as a literal, one as a task parameter ``{machine}``. Hostile
``/task_sequence`` messages (a 1000-deep tree, an id past int32, deep JSON) come on top. Only the manager and the DB
run: the good task has no machines (SetLocalBlackboard, Delay).
"""

from __future__ import annotations

import json
import time

from tests.rosproc import executable

BAD = "d37pxi_24＿"
LEAF = ('<Action ID="LeafNodeD37pxi" model_name="{model}" subtask_name="st_d37pxi_navigate_anywhere" '
        'record_name="D37_PATH"/>')


def tree(body: str) -> str:
    return f'<root main_tree_to_execute="Main">\n  <BehaviorTree ID="Main">\n    {body}\n  </BehaviorTree>\n</root>\n'


GOOD = tree('<Sequence><SetLocalBlackboard output_key="N" value="3"/><Delay delay_msec="1500"><AlwaysSuccess/></Delay>'
            '</Sequence>')


def test_an_invalid_model_name_fails_its_task_while_another_task_succeeds_and_no_process_exits(
    procs, ros_node, tmp_path
):
    from std_msgs.msg import String

    from tms_db import open_store
    from tms_msg.msg import TaskIds, TaskState, TaskStatus

    db = str(tmp_path / "db")
    with open_store(path=db) as store:
        store.add_task(tree(f"<Sequence>\n      {LEAF.format(model=BAD)}\n    </Sequence>"), task_id=1)  # a literal
        store.add_task(tree(LEAF.format(model="{machine}")), task_id=2, blackboard={"machine": BAD})  # a task parameter
        store.add_task(GOOD, task_id=3)
    manager = procs([executable("tms_ts", "tms_ts_manager"), "--ros-args", "-p", f"db_path:={db}",
                     "-p", "server_wait_s:=3.0", "-p", "status_rate_hz:=4.0"], name="manager")
    assert manager.wait_for("tms_ts_manager ready", 60), manager.output

    states: dict[int, TaskState] = {}

    def on_status(msg: TaskStatus) -> None:
        for t in msg.tasks:
            states[t.task_id] = t

    ros_node.create_subscription(TaskStatus, "/tms_ts/status", on_status, 50)
    start = ros_node.create_publisher(TaskIds, "/tms_ts/start", 50)
    sequence = ros_node.create_publisher(String, "/task_sequence", 50)

    def spin_until(predicate, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            ros_node.executor_for_test.spin_once(timeout_sec=0.05)
            if predicate():
                return
        raise AssertionError(f"timed out waiting for {what}; states {states}\n{manager.output[-3000:]}")

    spin_until(
        lambda: start.get_subscription_count() > 0 and sequence.get_subscription_count() > 0,
        30,
        "the manager's subscriptions",
    )
    # the good task first, so it is running while the bad ones come
    start.publish(TaskIds(task_ids=[3]))
    spin_until(lambda: 3 in states and states[3].state == TaskState.RUNNING, 20, "task 3 running")
    start.publish(TaskIds(task_ids=[1, 2]))
    hostile = [tree("<Sequence>" * 1000 + "<AlwaysSuccess/>" + "</Sequence>" * 1000),  # raised RecursionError
               json.dumps({"tasks": [{"task_id": 2**31, "task_sequence": GOOD}]}),       # an id past int32
               '{"tasks": ' + "[" * 100_000 + "]" * 100_000 + "}"]  # JSON deeper than json.loads goes
    for data in hostile:
        sequence.publish(String(data=data))
    spin_until(
        lambda: all(i in states and states[i].state != TaskState.RUNNING for i in (1, 2, 3)), 60, "tasks 1-3 ending"
    )

    # the bad tasks end FAILURE naming the leaf, its line and the bad name; the good one was not disturbed
    assert states[1].state == TaskState.FAILURE and BAD in states[1].message, states[1].message
    # the stored one-line form's position and "no valid ROS name" in states[1].message
    assert "LeafNodeD37pxi (line 1, column 69)" in states[1].message
    assert (
        states[2].state == TaskState.FAILURE
        and BAD in states[2].message
        and "task parameter 'machine'" in states[2].message
    )
    assert states[3].state == TaskState.SUCCESS, states[3].message
    # the hostile /task_sequence messages were refused, each named in one log line; nothing crashed
    for text in ("MAX_TREE_DEPTH", "task id 2147483648 is out of range", "MAX_JSON_DEPTH"):
        assert manager.wait_for(text, 10), f"no refusal naming {text}:\n{manager.output[-3000:]}"
    assert manager.popen.poll() is None, manager.output[-3000:]
    assert "Traceback" not in manager.output and "RecursionError" not in manager.output, manager.output[-3000:]
    # and it still runs tasks afterwards
    start.publish(TaskIds(task_ids=[3]))
    spin_until(lambda: states[3].state == TaskState.RUNNING, 20, "task 3 running again")
    spin_until(lambda: states[3].state == TaskState.SUCCESS, 30, "task 3 succeeding again")
    assert manager.popen.poll() is None
