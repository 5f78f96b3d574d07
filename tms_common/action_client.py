"""An rclpy ``ActionClient`` whose goal/cancel/result futures always complete (ros2/rclpy#1123).

Why: in the rclpy of these wheels (ros-jazzy-rclpy 7.1.6) ``send_goal_async``, ``_cancel_goal_async``
and ``_get_result_async`` first send the request and only then record its sequence number in the
client's pending table. With a MultiThreadedExecutor (the planner sends from an action-server execute
thread while other threads spin), a response that arrives in between is taken by an executor thread,
not found in the table, dropped with "Ignoring unexpected goal response", and the returned future
never completes. Under CPU load (13 processes on 2 cores in the paper launch) the sending thread can be
preempted right there: the planner then waited forever for a goal the arm controller had accepted and
executed - the ``pending_pose`` leaf stayed RUNNING with the controller idle. Upstream fixed it in
rclpy #1308 (backports #1517/#1519, newer than these wheels) with a lock; this subclass does the same:
a request is sent and recorded under one lock, and a response is looked up only after taking that lock.

``cancel_goal_by_id`` cancels a goal whose goal response was lost (the server may be running it).

Use it exactly like ``rclpy.action.ActionClient`` (every action client of the platform does). Imports rclpy.
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy.action import ActionClient

__all__ = ["RaceFreeActionClient"]


class RaceFreeActionClient(ActionClient):
    """``ActionClient`` with request sending and recording atomic with respect to response handling."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._request_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def send_goal_async(self, goal: Any, feedback_callback: Any = None, goal_uuid: Any = None) -> Any:
        with self._request_lock:
            return super().send_goal_async(goal, feedback_callback=feedback_callback, goal_uuid=goal_uuid)

    def _cancel_goal_async(self, goal_handle: Any) -> Any:
        with self._request_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle: Any) -> Any:
        with self._request_lock:
            return super()._get_result_async(goal_handle)

    def cancel_goal_by_id(self, goal_id: Any) -> Any:
        """Request the cancel of goal ``goal_id`` (a ``unique_identifier_msgs/UUID``) whose goal response never
        arrived: the server may have accepted it and be running it (a dropped reply, see
        config/dds/fastdds_profiles.xml). Returns the cancel future; a server that never got the goal answers
        ERROR_UNKNOWN_GOAL_ID."""
        from rclpy.action.client import ClientGoalHandle

        return self._cancel_goal_async(ClientGoalHandle(self, goal_id, None))

    async def execute(self, taken_data: Any) -> None:
        # A response can only exist once its request was sent; the sender records it before releasing
        # the lock, so after acquiring it here the pending tables hold every request we may answer.
        with self._request_lock:
            pass
        await super().execute(taken_data)
