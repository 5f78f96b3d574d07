"""``demo_subtask_server``: a demonstration ``tms_msg/Subtask`` action server (foundation tests)."""

from __future__ import annotations

import time
from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_msg.action import Subtask


class DemoSubtaskServer(Node):
    """Serves ``tms_msg/Subtask`` on ``action_name``: runs ``duration_s``, publishing feedback.

    Goals whose ``record_name`` is empty are rejected. Cancel is accepted and acknowledged: the
    goal ends CANCELED with ``error_code`` CANCELED.
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("demo_subtask_server", **kwargs)
        name = declare_startup(self, "action_name", "demo_subtask").value
        self._duration = float(declare_startup(self, "duration_s", 1.0).value)
        self._server = ActionServer(
            self,
            Subtask,
            name,
            execute_callback=self._execute,
            goal_callback=self._on_goal,
            cancel_callback=lambda _goal: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
        )

    def _on_goal(self, goal: Subtask.Goal) -> GoalResponse:
        return GoalResponse.ACCEPT if goal.record_name else GoalResponse.REJECT

    def _execute(self, handle):  # noqa: ANN001, ANN202
        result = Subtask.Result()
        end = time.monotonic() + self._duration
        step = 0
        while True:
            if handle.is_cancel_requested:
                handle.canceled()
                result.error_code = Subtask.Result.CANCELED
                result.error_msg = f"canceled at step {step}"
                return result
            if time.monotonic() >= end:
                break
            feedback = Subtask.Feedback()
            feedback.state = f"step {step}"
            handle.publish_feedback(feedback)
            step += 1
            time.sleep(min(0.05, max(0.0, end - time.monotonic())))
        handle.succeed()
        result.error_msg = f"{handle.request.model_name}/{handle.request.record_name} done after {step} steps"
        return result


def main() -> int:
    return run_node(DemoSubtaskServer, executor="multi")
