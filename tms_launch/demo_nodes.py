"""Small demonstration nodes: a talker, a listener and a subtask action server and client.

They exercise the foundation end to end (DDS between processes, a ``tms_msg`` action with feedback,
result and cancel, the launcher) and are the baseline the benchmarks measure. Each ``*_main`` is a
console script.
"""

from __future__ import annotations

import sys
import time

from tms_common.node import run_node


def _make_talker():  # noqa: ANN202
    from rclpy.node import Node
    from std_msgs.msg import Header

    class Talker(Node):
        """Publishes a time-stamped ``std_msgs/Header`` on ``chatter`` at ``rate_hz``.

        ``shutdown_delay_s`` (0): when stopped, take this long to shut down (a node finishing its work on the
        way out), then print "talker: shut down"."""

        def __init__(self) -> None:
            super().__init__("talker")
            rate = self.declare_parameter("rate_hz", 100.0).value
            if not rate or rate <= 0:
                raise ValueError(f"talker: rate_hz must be > 0, got {rate}")
            self._shutdown_delay = float(self.declare_parameter("shutdown_delay_s", 0.0).value)
            self._pub = self.create_publisher(Header, "chatter", 10)
            self._seq = 0
            self.create_timer(1.0 / rate, self._tick)

        def _tick(self) -> None:
            msg = Header()
            msg.stamp = self.get_clock().now().to_msg()
            msg.frame_id = str(self._seq)
            self._seq += 1
            self._pub.publish(msg)

        def destroy_node(self) -> None:
            if self._shutdown_delay > 0:
                import time

                time.sleep(self._shutdown_delay)
                print("talker: shut down", flush=True)
            super().destroy_node()

    return Talker()


def _make_listener():  # noqa: ANN202
    from rclpy.node import Node
    from std_msgs.msg import Header

    class Listener(Node):
        """Subscribes to ``chatter`` and logs every ``log_every``-th sequence number it receives."""

        def __init__(self) -> None:
            super().__init__("listener")
            self._every = int(self.declare_parameter("log_every", 100).value)
            self.received = 0
            self.create_subscription(Header, "chatter", self._on_msg, 10)

        def _on_msg(self, msg: Header) -> None:
            self.received += 1
            if self.received % self._every == 1:
                print(f"heard seq={msg.frame_id} total={self.received}", flush=True)

    return Listener()


def _make_subtask_server():  # noqa: ANN202
    from rclpy.action import ActionServer, CancelResponse, GoalResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node

    from tms_msg.action import Subtask

    class DemoSubtaskServer(Node):
        """Serves ``tms_msg/Subtask`` on ``action_name``: runs ``duration_s``, publishing feedback.

        Goals whose ``record_name`` is empty are rejected. Cancel is accepted and acknowledged: the
        goal ends CANCELED with ``error_code`` CANCELED.
        """

        def __init__(self) -> None:
            super().__init__("demo_subtask_server")
            name = self.declare_parameter("action_name", "demo_subtask").value
            self._duration = float(self.declare_parameter("duration_s", 1.0).value)
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

    return DemoSubtaskServer()


def talker_main() -> int:
    return run_node(_make_talker, executor="single")


def listener_main() -> int:
    return run_node(_make_listener, executor="single")


def subtask_server_main() -> int:
    return run_node(_make_subtask_server, executor="multi")


def subtask_client_main() -> int:
    """Send one goal to ``--action NAME`` (default demo_subtask); ``--cancel-after S`` cancels it.

    Prints each feedback state and the final status; exit code 0 when the goal ended as expected
    (SUCCEEDED, or CANCELED when a cancel was requested).
    """
    import argparse

    import rclpy
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_msg.action import Subtask

    parser = argparse.ArgumentParser(description=subtask_client_main.__doc__)
    parser.add_argument("--action", default="demo_subtask")
    parser.add_argument("--record", default="demo_record")
    parser.add_argument("--cancel-after", type=float, default=None)
    parser.add_argument("--timeout", type=float, default=20.0)
    opts, ros_args = parser.parse_known_args()
    from tms_common.dds import use_platform_profiles

    use_platform_profiles()
    rclpy.init(args=[sys.argv[0], *ros_args])
    node = rclpy.create_node("demo_subtask_client")
    try:
        client = ActionClient(node, Subtask, opts.action)
        if not client.wait_for_server(timeout_sec=opts.timeout):
            print(f"no action server {opts.action!r}", flush=True)
            return 2
        goal = Subtask.Goal(model_name="demo", record_name=opts.record)
        fut = client.send_goal_async(goal, feedback_callback=lambda fb: print(f"feedback {fb.feedback.state}", flush=True))
        rclpy.spin_until_future_complete(node, fut, timeout_sec=opts.timeout)
        handle = fut.result()
        if handle is None or not handle.accepted:
            print("goal rejected", flush=True)
            return 3
        print("goal accepted", flush=True)
        result_fut = handle.get_result_async()
        if opts.cancel_after is not None:
            deadline = time.monotonic() + opts.cancel_after
            while time.monotonic() < deadline and not result_fut.done():
                rclpy.spin_once(node, timeout_sec=0.01)
            cancel_fut = handle.cancel_goal_async()
            rclpy.spin_until_future_complete(node, cancel_fut, timeout_sec=opts.timeout)
            accepted = bool(cancel_fut.result() and cancel_fut.result().goals_canceling)
            print(f"cancel acknowledged={accepted}", flush=True)
        rclpy.spin_until_future_complete(node, result_fut, timeout_sec=opts.timeout)
        res = result_fut.result()
        if res is None:
            print("no result", flush=True)
            return 4
        names = {GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED", GoalStatus.STATUS_CANCELED: "CANCELED", GoalStatus.STATUS_ABORTED: "ABORTED"}
        print(f"status {names.get(res.status, res.status)} error_code={res.result.error_code} error_msg={res.result.error_msg!r}", flush=True)
        expected = GoalStatus.STATUS_CANCELED if opts.cancel_after is not None else GoalStatus.STATUS_SUCCEEDED
        return 0 if res.status == expected else 5
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
