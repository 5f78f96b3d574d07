"""Regression: the planner's action client never loses the controller's goal response (ros2/rclpy#1123).

The paper stack sometimes hung in a ZX200 ``change_pose``: zx200_planner sends the segment to
``arm_controller/move`` from an execute thread while MultiThreadedExecutor threads spin the client. In
rclpy 7.1.6 the request is sent before it is recorded, so a response handled in between is dropped and
the goal future never completes (the controller ran the goal and went idle; the leaf stayed RUNNING).
Here the window is forced deterministically: the client handle's send blocks until an executor thread
has *taken* the goal response. The stock ActionClient then loses the response (what the paper runs hit,
shown so this test fails if the mechanism is ever misdiagnosed); RaceFreeActionClient must not.
The server is the real ``excavator_arm_controller`` process, fed joint_states by this test.
"""

from __future__ import annotations

import threading
import time

import pytest

from tests.action_handle import ClientHandleProxy
from tests.arm_stack import joint_states_held_at
from tests.rosproc import executable

pytestmark = pytest.mark.integration

Q = [0.0, -0.8, 1.3, 1.2]


class _SlowSendHandle(ClientHandleProxy):
    """Wraps an rclpy action-client handle: ``send_goal_request`` returns only after the response was taken."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        self.taken = threading.Event()

    def send_goal_request(self, request):
        seq = self._inner.send_goal_request(request)
        self.taken.wait(30.0)  # the sending thread "preempted" until the response has been taken
        return seq

    def take_goal_response(self, response_type):
        data = self._inner.take_goal_response(response_type)
        if all(data):
            self.taken.set()
        return data


def _send_with_forced_race(node, client_cls, wait_s: float) -> tuple[bool, object]:
    from rclpy.executors import MultiThreadedExecutor

    from tms_msg.action import Zx200ArmMove
    from tms_msg.msg import Zx200ArmSegment

    client = client_cls(node, Zx200ArmMove, "/zx200/arm_controller/move")
    executor = MultiThreadedExecutor(num_threads=2, context=node.context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        assert client.wait_for_server(timeout_sec=60.0), "arm_controller/move not available"
        client._client_handle = _SlowSendHandle(client._client_handle)  # the forced window
        goal = Zx200ArmMove.Goal(segments=[Zx200ArmSegment(kind=Zx200ArmSegment.JOINT, label="race",
                                                           joint_positions=[float(v) for v in Q])])
        future = client.send_goal_async(goal)
        end = time.monotonic() + wait_s
        while not future.done() and time.monotonic() < end:
            time.sleep(0.05)
        handle = future.result() if future.done() else None
        if handle is not None and handle.accepted:
            result = handle.get_result_async()
            end = time.monotonic() + 60.0
            while not result.done() and time.monotonic() < end:
                time.sleep(0.05)
            return True, result.result() if result.done() else None
        return future.done(), None
    finally:
        executor.shutdown(timeout_sec=5.0)
        client.destroy()


def test_goal_response_is_not_lost_when_the_sender_is_preempted(procs, ros_node) -> None:
    import rclpy
    from rclpy.action import ActionClient

    from tms_common.action_client import RaceFreeActionClient

    ctl = procs([str(executable("tms_rc", "excavator_arm_controller")), "--ros-args", "-r", "__ns:=/zx200"],
                name="excavator_arm_controller")
    assert ctl.wait_for("excavator_arm_controller ready", 60), ctl.output
    # joint_states at the goal pose (the controller holds it: the goal ends SUCCESS after settling)
    with joint_states_held_at(rclpy.create_node("js_feed", context=ros_node.context), Q):
        # the response is taken before send returns: it is handled at once or never (10 s is plenty)
        stock_done, _ = _send_with_forced_race(rclpy.create_node("stock_client", context=ros_node.context),
                                               ActionClient, 10.0)
        assert not stock_done, "the stock ActionClient kept the response: rclpy#1123 fixed? re-check the workaround"
        done, result = _send_with_forced_race(rclpy.create_node("racefree_client", context=ros_node.context),
                                              RaceFreeActionClient, 60.0)
        assert done, "RaceFreeActionClient lost the goal response"
        assert result is not None, "RaceFreeActionClient: goal accepted but no result within 60 s"
        if result.status == 0:
            # STATUS_UNKNOWN: the server had already dropped the ended goal's result (ACTION_RESULT_TIMEOUT_S after
            # it ended) when the loaded machine delivered the request for it, as a rehearsal once saw; the goal
            # must still have ended reached on the controller (the stock client's goal before it too: two lines)
            end = time.monotonic() + 10.0
            while ctl.output.count("goal ended 1 (reached)") < 2 and time.monotonic() < end:
                time.sleep(0.1)
            assert ctl.output.count("goal ended 1 (reached)") >= 2, ctl.output
        else:
            assert result.status == 4 and result.result.error_code.val == 1, (result.status, result.result.message)
