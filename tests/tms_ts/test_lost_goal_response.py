"""A goal whose acceptance never reaches the manager is cancelled by its id, so it cannot run on unseen.

A clean-clone CI run failed this way: at start-up on 2 cores, Fast DDS dropped the goal
response of ``/ic120/st_ic120_navigate_anywhere`` ("failed to send response (timeout): client will not
receive response") while the subtask server accepted the goal and ran it. The leaf then failed on its
accept timeout and could not cancel a goal it had no handle for. Here the dropped reply is emulated in
the client handle (the response is taken and discarded); the subtask server and planning server are the
real processes. ``RosGoal.cancel`` must reach the server by goal id and the planning goal must end
CANCELED long before it would have finished.
"""

from __future__ import annotations

import time

import pytest

from tests.action_handle import ClientHandleProxy

pytestmark = pytest.mark.integration


class _DropGoalResponses(ClientHandleProxy):
    """Wraps an rclpy action-client handle: every goal response is taken and discarded (a dropped reply)."""

    def __init__(self, inner) -> None:
        super().__init__(inner)
        self.dropped = 0

    def take_goal_response(self, response_type):
        data = self._inner.take_goal_response(response_type)
        if all(data):
            self.dropped += 1
        return (None, None)


def test_a_goal_whose_response_was_lost_is_cancelled_by_its_id(ts_system):
    from tms_ts.leaf import PENDING
    from tms_ts.nodes.ros_port import ManagerRosPort

    ts_system.store.upsert_parameter({"model_name": "ic120", "type": "static", "record_name": "load_point",
                                      "x": 10.0, "y": 2.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0})
    system = ts_system.start(stub_duration_s=60.0)
    port = ManagerRosPort(system.node)
    client = port._client("ic120", "st_ic120_navigate_anywhere")  # the handle to wrap
    system.wait(client.server_is_ready, 30, "st_ic120_navigate_anywhere")
    dropper = _DropGoalResponses(client._client_handle)
    client._client_handle = dropper

    goal = port.send_subtask_goal("ic120", "st_ic120_navigate_anywhere", "load_point")
    stub = system.procs["stub"]
    system.wait(lambda: stub.wait_for("GOAL /ic120/navigate_to_pose", 0.01), 30, "the planning goal to start")
    system.wait(lambda: dropper.dropped >= 1, 10, "the goal response (to drop it)")
    assert goal.state == PENDING, goal.state  # the manager never learns that the goal runs

    cancelled_at = time.monotonic()
    goal.cancel()
    assert goal.cancelled_unanswered
    system.wait(lambda: stub.wait_for("CANCELED /ic120/navigate_to_pose", 0.01), 20,
                "the running planning goal to be cancelled by goal id")
    assert time.monotonic() - cancelled_at < 20.0
    assert "DONE /ic120/navigate_to_pose" not in stub.output
