"""The controller's internal action ``arm_controller/move`` (Zx200ArmMove): one goal of labelled segments.

The real ``zx200_arm_controller`` process, fed joint_states by this test (the arm "holds" pose Q):
a malformed segment rejects the whole goal before any motion, naming the segment; a goal of several
segments runs them in order as one motion and its feedback names the running segment.
"""

from __future__ import annotations

import time

import pytest

from tests.rosproc import executable
from tests.zx200.conftest import joint_states_held_at
from tms_model.excavator import codes

pytestmark = pytest.mark.integration

Q = [0.0, -0.8, 1.3, 1.2]


@pytest.fixture
def controller(procs, ros_node):  # noqa: ANN001, ANN201
    """A running controller, a joint_states feed at Q, and the front_cmd velocities it publishes."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from com3_msgs.msg import JointCmd

    ctl = procs([str(executable("tms_rc", "zx200_arm_controller")), "--ros-args", "-r", "__ns:=/zx200"],
                name="zx200_arm_controller")
    assert ctl.wait_for("zx200_arm_controller ready", 60), ctl.output
    node = rclpy.create_node("arm_move_probe", context=ros_node.context)
    cmds: list[list[float]] = []
    node.create_subscription(JointCmd, "/zx200/front_cmd", lambda m: cmds.append(list(m.velocity)), 100)
    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(node)
    try:
        with joint_states_held_at(node, Q):
            yield node, executor, cmds, ctl
    finally:
        executor.shutdown(timeout_sec=5.0)


def _run(node, executor, segments, timeout: float = 60.0):  # noqa: ANN001, ANN202
    from rclpy.action import ActionClient

    from tms_msg.action import Zx200ArmMove

    client = ActionClient(node, Zx200ArmMove, "/zx200/arm_controller/move")
    assert client.wait_for_server(timeout_sec=30.0), "arm_controller/move not available"
    feedback: list[tuple[int, str]] = []
    send = client.send_goal_async(Zx200ArmMove.Goal(segments=segments),
                                  feedback_callback=lambda m: feedback.append((m.feedback.segment, m.feedback.label)))
    end = time.monotonic() + timeout
    while not send.done() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    assert send.done(), "no goal response"
    handle = send.result()
    assert handle.accepted, "goal not accepted"
    result = handle.get_result_async()
    while not result.done() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    assert result.done(), f"goal did not end within {timeout} s (feedback {feedback[-3:]})"
    drain = time.monotonic() + 0.5  # feedback is a topic: the last messages may arrive after the result
    while time.monotonic() < drain:
        executor.spin_once(timeout_sec=0.05)
    return result.result().status, result.result().result, feedback


def _joint(label: str, q, via: bool = False):  # noqa: ANN001, ANN202
    from tms_msg.msg import Zx200ArmSegment

    return Zx200ArmSegment(kind=Zx200ArmSegment.JOINT, label=label, joint_positions=[float(v) for v in q], via=via)


def test_malformed_segment_rejects_the_goal_before_motion(controller) -> None:
    from tms_msg.msg import Zx200ArmSegment

    node, executor, cmds, _ = controller
    bad = [
        ([_joint("fine", Q, via=True), _joint("three_angles", Q[:3])], "segment 2 (three_angles): joint_positions"),
        ([_joint("nan", [float("nan"), *Q[1:]])], "segment 1 (nan): joint_positions"),
        ([Zx200ArmSegment(kind=7, label="odd")], "segment 1 (odd): unknown kind 7"),
        ([Zx200ArmSegment(kind=Zx200ArmSegment.CARTESIAN, label="fast", theta_w=1.0, speed_scale=50.0)],
         "segment 1 (fast): speed_scale 50.0"),
        ([], "empty goal"),
    ]
    for segments, reason in bad:
        cmds.clear()
        status, res, _ = _run(node, executor, segments)
        assert status == 6, (reason, status, res.message)  # ABORTED
        assert res.error_code.val == codes.INVALID_GOAL, (reason, res.error_code.val)
        assert reason in res.message, (reason, res.message)
        executor.spin_once(timeout_sec=0.2)
        moving = [c for c in cmds if max(abs(v) for v in c) > 0.0]
        assert not moving, f"{reason}: the arm was commanded to move: {moving[:3]}"


def test_segments_run_in_order_as_one_goal(controller) -> None:
    node, executor, _, _ = controller
    q_via = [Q[0], Q[1], Q[2], Q[3] + 0.004]  # within the via tolerance of the held pose
    status, res, feedback = _run(node, executor, [_joint("pass", q_via, via=True), _joint("hold", Q)])
    assert status == 4 and res.error_code.val == codes.SUCCESS, (status, res.message)
    # feedback is sampled every 50 ms, so a short segment may go unreported: check what was reported
    named = [(seg, label) for seg, label in feedback if seg]
    assert named, "no feedback named a segment"
    assert all({1: "pass", 2: "hold"}.get(seg) == label for seg, label in named), named
    assert [seg for seg, _ in named] == sorted(seg for seg, _ in named), f"segments out of order: {named}"


def test_a_goal_sent_before_the_first_joint_states_waits_for_them(procs, ros_node) -> None:  # noqa: ANN001
    """Start-up: the goal callback waits (without blocking the single-threaded node) for the first joint_states,
    then accepts; the goal runs and succeeds at the held pose."""
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.executors import SingleThreadedExecutor

    from tms_msg.action import Zx200ArmMove

    ctl = procs([str(executable("tms_rc", "zx200_arm_controller")), "--ros-args", "-r", "__ns:=/zx200"],
                name="zx200_arm_controller")
    assert ctl.wait_for("zx200_arm_controller ready", 60), ctl.output
    node = rclpy.create_node("arm_move_early_probe", context=ros_node.context)
    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(node)
    try:
        client = ActionClient(node, Zx200ArmMove, "/zx200/arm_controller/move")
        assert client.wait_for_server(timeout_sec=30.0), "arm_controller/move not available"
        send = client.send_goal_async(Zx200ArmMove.Goal(segments=[_joint("hold", Q)]))
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert not send.done(), "answered before any joint_states (it must wait for them)"
        with joint_states_held_at(node, Q):
            end = time.monotonic() + 20.0
            while not send.done() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            assert send.done() and send.result().accepted, f"goal not accepted once joint_states came\n{ctl.output}"
            result = send.result().get_result_async()
            end = time.monotonic() + 30.0
            while not result.done() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            assert result.done() and result.result().status == 4, ctl.output  # SUCCEEDED
    finally:
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
