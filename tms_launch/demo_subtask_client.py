"""``demo_subtask_client``: sends one demonstration ``tms_msg_ts/LeafNodeBase`` goal (a command-line tool, not a node
class)."""

from __future__ import annotations

import sys
import time

from tms_common.dds import use_platform_profiles


def main() -> int:
    """Send one goal to ``--action NAME`` (default demo_subtask); ``--cancel-after S`` cancels it.

    Prints each feedback state and the final status; exit code 0 when the goal ended as expected
    (SUCCEEDED, or CANCELED when a cancel was requested).
    """
    import argparse

    import rclpy
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_msg_ts.action import LeafNodeBase

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--action", default="demo_subtask")
    parser.add_argument("--record", default="demo_record")
    parser.add_argument("--cancel-after", type=float, default=None)
    parser.add_argument("--timeout", type=float, default=20.0)
    opts, ros_args = parser.parse_known_args()
    use_platform_profiles()
    rclpy.init(args=[sys.argv[0], *ros_args])
    node = rclpy.create_node("demo_subtask_client")
    try:
        client = ActionClient(node, LeafNodeBase, opts.action)
        if not client.wait_for_server(timeout_sec=opts.timeout):
            print(f"no action server {opts.action!r}", flush=True)
            return 2
        goal = LeafNodeBase.Goal(model_name="demo", record_name=opts.record)
        fut = client.send_goal_async(
            goal, feedback_callback=lambda fb: print(f"feedback {fb.feedback.status}", flush=True)
        )
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
        names = {
            GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED",
            GoalStatus.STATUS_CANCELED: "CANCELED",
            GoalStatus.STATUS_ABORTED: "ABORTED",
        }
        print(f"status {names.get(res.status, res.status)} result={res.result.result}", flush=True)
        expected = GoalStatus.STATUS_CANCELED if opts.cancel_after is not None else GoalStatus.STATUS_SUCCEEDED
        return 0 if res.status == expected else 5
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
