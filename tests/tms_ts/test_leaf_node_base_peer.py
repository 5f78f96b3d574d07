"""A peer of the original: a client built only on ``tms_msg_ts/action/LeafNodeBase`` (the original's leaf
type) runs our subtasks at ``/<model_name>/<subtask_name>`` and cancels one, across processes.

Real processes: ``tms_ts_subtasks`` (zx200) reading the DB, and the planning stub serving the original's
``tms_msg_rp`` actions. The client imports nothing of ours: goal ``{model_name, record_name}``, result
``result`` (true only when SUCCEEDED), feedback ``status``.
"""

from __future__ import annotations

import sys
import time

import pytest

from tests.rosproc import ROOT, executable

pytestmark = pytest.mark.integration

ACTION = "/zx200/subtask_zx200_change_pose"


@pytest.fixture
def peer_stack(tmp_path, procs):
    """The zx200 subtask servers over a planning stub whose goals run 30 s (a cancel ends them at once)."""
    from tms_db import open_store

    db = str(tmp_path / "db")
    store = open_store(path=db)
    joints = {"swing_joint": 0.0, "boom_joint": -0.3, "arm_joint": 1.2, "bucket_joint": 0.5}
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "initial_pose", "trajectory": 1,
                            **joints})
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "carry", "position_with_angle": 1,
                            "x": 5.0, "y": 2.0, "z": 2.5, "theta_w": 1.4, "pass_through": 1})
    store.close()
    stub = procs([sys.executable, "-m", "tests.tms_ts.planning_stub", "--ros-args", "-p", "model_names:=zx200",
                  "-p", "duration_s:=30.0"], name="stub", PYTHONPATH=str(ROOT))
    subtasks = procs([executable("tms_ts", "tms_ts_subtasks"), "--ros-args", "-p", "machine:=zx200",
                      "-p", f"db_path:={db}"], name="zx200")
    assert stub.wait_for("planning stub ready", 60), stub.output
    assert subtasks.wait_for("subtask servers", 60), subtasks.output
    return stub, subtasks


def _spin_until(node, predicate, timeout: float, what: str, procs=()):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        node.executor_for_test.spin_once(timeout_sec=0.05)
        if predicate():
            return
    out = "\n".join(f"--- {p.name}\n{p.output[-2000:]}" for p in procs)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}\n{out}")


def test_a_leaf_node_base_client_runs_a_subtask_and_its_cancel_is_confirmed(peer_stack, ros_node):
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_msg_ts.action import LeafNodeBase  # the peer's type, nothing else of ours

    stub, subtasks = peer_stack
    client = ActionClient(ros_node, LeafNodeBase, ACTION)
    _spin_until(ros_node, client.server_is_ready, 30, f"the subtask server {ACTION}", peer_stack)
    feedback: list[str] = []
    goal = LeafNodeBase.Goal(model_name="zx200", record_name="initial_pose")
    sent = client.send_goal_async(goal, feedback_callback=lambda msg: feedback.append(msg.feedback.status))
    _spin_until(ros_node, sent.done, 10, "the goal response", peer_stack)
    handle = sent.result()
    assert handle.accepted
    result = handle.get_result_async()
    # the subtask read the record and its planning goal is running (the original's TmsRpZx200ChangePose)
    _spin_until(ros_node, lambda: "GOAL /zx200/tms_rp_zx200_change_pose" in stub.output, 20, "the planning goal",
                peer_stack)
    asked = time.monotonic()
    cancel = handle.cancel_goal_async()
    _spin_until(ros_node, cancel.done, 10, "the cancel response", peer_stack)
    assert len(cancel.result().goals_canceling) == 1, cancel.result()  # the cancel was accepted
    _spin_until(ros_node, result.done, 20, "the CANCELED result", peer_stack)
    took = time.monotonic() - asked
    assert result.result().status == GoalStatus.STATUS_CANCELED, result.result()
    assert result.result().result.result is False  # the original's bool: true only for SUCCEEDED
    # confirmed: planning reported the stop before the subtask ended CANCELED
    assert "CANCELED /zx200/tms_rp_zx200_change_pose" in stub.output, stub.output[-2000:]
    # the reason for a client that reads only the original's type: the last feedback status
    _spin_until(ros_node, lambda: any(f.startswith("CANCELED: canceled; planning") for f in feedback), 5,
                "the reason in the last feedback", peer_stack)
    print(f"\nLeafNodeBase cancel confirmed {took:.2f} s wall after the request; last status {feedback[-1]!r}")
    assert took < 5.0, f"cancel confirmed only {took:.2f} s after the request"


def test_a_leaf_node_base_client_gets_a_failure_as_false_and_its_reason_as_status(peer_stack, ros_node):
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_msg_ts.action import LeafNodeBase

    stub, _ = peer_stack
    client = ActionClient(ros_node, LeafNodeBase, ACTION)
    _spin_until(ros_node, client.server_is_ready, 30, f"the subtask server {ACTION}", peer_stack)
    feedback: list[str] = []
    # a record asking for pass_through: its options go to the planner by goal id, then the original's goal
    sent = client.send_goal_async(LeafNodeBase.Goal(model_name="zx200", record_name="carry"),
                                  feedback_callback=lambda msg: feedback.append(msg.feedback.status))
    _spin_until(ros_node, sent.done, 10, "the goal response", peer_stack)
    _spin_until(ros_node, lambda: "OPTIONS pass_through=True theta_w_tolerance=0" in stub.output, 20,
                "the change_pose options at the planner", peer_stack)
    _spin_until(ros_node, lambda: stub.output.count("GOAL /zx200/tms_rp_zx200_change_pose") == 1, 20,
                "the planning goal", peer_stack)
    cancel = sent.result().cancel_goal_async()
    result = sent.result().get_result_async()
    _spin_until(ros_node, lambda: cancel.done() and result.done(), 20, "the canceled carry", peer_stack)
    # a record that does not exist: ABORTED, result false, the reason as the last feedback status (sent after
    # a goal that ran, so this client's feedback subscription is matched: feedback is not kept for late joiners)
    sent = client.send_goal_async(LeafNodeBase.Goal(model_name="zx200", record_name="no_such_record"),
                                  feedback_callback=lambda msg: feedback.append(msg.feedback.status))
    _spin_until(ros_node, sent.done, 10, "the goal response", peer_stack)
    result = sent.result().get_result_async()
    _spin_until(ros_node, result.done, 10, "the result", peer_stack)
    assert result.result().status == GoalStatus.STATUS_ABORTED and result.result().result.result is False
    _spin_until(ros_node, lambda: any(f.startswith("RECORD_INVALID: ") and "no_such_record" in f for f in feedback),
                5, "the reason in the last feedback", peer_stack)
