"""The controller's internal action ``arm_controller/move`` (Zx200ArmMove): one goal of labelled segments.

The real ``excavator_arm_controller`` process, fed joint_states by this test (the arm "holds" pose Q):
a malformed segment rejects the whole goal before any motion, naming the segment; a goal of several
segments runs them in order as one motion and its feedback names the running segment.
"""

from __future__ import annotations

import time

import pytest

from tests.arm_stack import joint_states_held_at
from tests.rosproc import executable
from tms_model.excavator import codes

pytestmark = pytest.mark.integration

Q = [0.0, -0.8, 1.3, 1.2]


@pytest.fixture
def controller(procs, ros_node):
    """A running controller, a joint_states feed at Q, and the front_cmd velocities it publishes."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from com3_msgs.msg import JointCmd

    ctl = procs([str(executable("tms_rc", "excavator_arm_controller")), "--ros-args", "-r", "__ns:=/zx200"],
                name="excavator_arm_controller")
    assert ctl.wait_for("excavator_arm_controller ready", 60), ctl.output
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


def _run(node, executor, segments, timeout: float = 60.0):
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


def _joint(label: str, q, via: bool = False):
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


def test_a_goal_sent_before_the_first_joint_states_waits_for_them(procs, ros_node) -> None:
    """Start-up: the goal callback waits (without blocking the single-threaded node) for the first joint_states,
    then accepts; the goal runs and succeeds at the held pose."""
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.executors import SingleThreadedExecutor

    from tms_msg.action import Zx200ArmMove

    ctl = procs([str(executable("tms_rc", "excavator_arm_controller")), "--ros-args", "-r", "__ns:=/zx200"],
                name="excavator_arm_controller")
    assert ctl.wait_for("excavator_arm_controller ready", 60), ctl.output
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


def _send(node, executor, client, segments, timeout: float = 30.0):
    """Send a goal and wait for its acceptance; returns its result future."""
    from tms_msg.action import Zx200ArmMove

    send = client.send_goal_async(Zx200ArmMove.Goal(segments=segments))
    end = time.monotonic() + timeout
    while not send.done() and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
    assert send.done() and send.result().accepted, "goal not accepted"
    return send.result().get_result_async()


def _wait(executor, futures, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while not all(f.done() for f in futures) and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
    assert all(f.done() for f in futures), f"{sum(not f.done() for f in futures)} goal(s) without a result"


def test_re_sent_goals_to_the_held_pose_and_a_preempting_goal_each_end_with_a_result(controller) -> None:
    """Issue 39: the original's ZX200 tree re-sends change_pose to the pose the arm holds; one such goal ended
    before the controller's first tick and its end-of-goal log line raised, so rclpy aborted it with an empty
    result. Every goal here must end with a result of its own, and the controller must never raise."""
    from rclpy.action import ActionClient

    from tms_msg.action import Zx200ArmMove

    node, executor, _, ctl = controller
    client = ActionClient(node, Zx200ArmMove, "/zx200/arm_controller/move")
    assert client.wait_for_server(timeout_sec=30.0), "arm_controller/move not available"
    # 1. ten goals to the pose held, one after the other: each SUCCEEDED with SUCCESS
    for k in range(10):
        result = _send(node, executor, client, [_joint("hold", Q)])
        _wait(executor, [result])
        outcome = result.result()
        assert outcome.status == 4 and outcome.result.error_code.val == codes.SUCCESS, (k, outcome)
    # 2. a goal while one runs: the newer goal drives the arm (SUCCEEDED), the older ends with a failure result
    # of its own, not the newer one's result and not rclpy's empty one (error_code 0)
    q_far = [Q[0] + 0.3, Q[1], Q[2], Q[3]]  # never reached: the test's joint_states hold Q
    first = _send(node, executor, client, [_joint("far", q_far)])
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)
    second = _send(node, executor, client, [_joint("hold", Q)])
    _wait(executor, [first, second])
    assert first.result().status == 6, first.result()  # ABORTED
    assert first.result().result.error_code.val == codes.FAILURE, first.result().result
    assert first.result().result.message == "preempted by a newer goal before it ended", first.result().result
    assert second.result().status == 4 and second.result().result.error_code.val == codes.SUCCESS, second.result()
    # 3. two goals back to back, the second before the first has seen a tick: both end with a result
    a = client.send_goal_async(Zx200ArmMove.Goal(segments=[_joint("hold", Q)]))
    b = client.send_goal_async(Zx200ArmMove.Goal(segments=[_joint("hold", Q)]))
    _wait(executor, [a, b], 30.0)
    results = [a.result().get_result_async(), b.result().get_result_async()]
    _wait(executor, results)
    codes_seen = [(r.result().status, r.result().result.error_code.val) for r in results]
    assert (4, codes.SUCCESS) in codes_seen and all(c != 0 for _, c in codes_seen), codes_seen
    # the controller's log lines reach the test through its output pipe, the last one possibly after its result
    deadline = time.monotonic() + 10.0
    while sum("goal ended" in ln for ln in ctl.output.splitlines()) < 14 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.2)
    executor.spin_once(timeout_sec=0.2)
    ended = [ln for ln in ctl.output.splitlines() if "goal ended" in ln]
    assert len(ended) == 14, "\n".join(ended)  # one log line per goal: 10 + 2 + 2
    assert "Traceback" not in ctl.output and "Error raised in execute callback" not in ctl.output, ctl.output
    print(f"\n{len(ended)} goals ended; preempted before any tick ('at once'): "
          f"{sum('at once' in ln for ln in ended)}; back to back: {codes_seen}")
