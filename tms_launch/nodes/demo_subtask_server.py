"""``demo_subtask_server``: a demonstration subtask action server (``tms_msg_ts/LeafNodeBase``; foundation tests)."""

from __future__ import annotations

import time
from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_msg_ts.action import LeafNodeBase


class DemoSubtaskServer(Node):
    """Serves ``tms_msg_ts/LeafNodeBase`` on ``action_name``: runs ``duration_s``, publishing feedback ``status``.

    Goals whose ``record_name`` is empty are rejected. Cancel is accepted and acknowledged: the
    goal ends CANCELED with ``result`` false (true only for SUCCEEDED, as the original's subtasks answer).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("demo_subtask_server", **kwargs)
        name = declare_startup(self, "action_name", "demo_subtask").value
        self._duration = float(declare_startup(self, "duration_s", 1.0).value)
        self._server = ActionServer(
            self,
            LeafNodeBase,
            name,
            execute_callback=self._execute,
            goal_callback=self._on_goal,
            cancel_callback=lambda _goal: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
            result_timeout=ACTION_RESULT_TIMEOUT_S,
        )

    def _on_goal(self, goal: LeafNodeBase.Goal) -> GoalResponse:
        return GoalResponse.ACCEPT if goal.record_name else GoalResponse.REJECT

    def _execute(self, handle):
        end = time.monotonic() + self._duration
        step = 0
        while True:
            if handle.is_cancel_requested:
                handle.publish_feedback(LeafNodeBase.Feedback(status=f"canceled at step {step}"))
                handle.canceled()
                return LeafNodeBase.Result(result=False)
            if time.monotonic() >= end:
                break
            handle.publish_feedback(LeafNodeBase.Feedback(status=f"step {step}"))
            step += 1
            time.sleep(min(0.05, max(0.0, end - time.monotonic())))
        handle.publish_feedback(LeafNodeBase.Feedback(
            status=f"{handle.request.model_name}/{handle.request.record_name} done after {step} steps"))
        handle.succeed()
        return LeafNodeBase.Result(result=True)


def main() -> int:
    return run_node(DemoSubtaskServer, executor="multi")
