"""ManagerRosPort with a real rclpy node (no other process needed)."""

from __future__ import annotations


def test_lock_engage_then_release_logs_both(ros_node) -> None:
    """rclpy refuses a log call whose severity differs from the last call at the same line: engaging the lock
    (warning) and then releasing it (info) raised ValueError inside the manager's tick."""
    from tms_ts.nodes.ros_port import ManagerRosPort

    port = ManagerRosPort(ros_node)
    for _ in range(2):
        port.lock("zx200", True, "task cancelled")
        assert port.locked["zx200"] is True
        port.lock("zx200", False, "new goal")
        assert port.locked["zx200"] is False


def test_planning_server_ready_sees_the_subtasks_planning_server_on_the_graph(ros_node) -> None:
    import time

    from rclpy.action import ActionServer

    from nav2_msgs.action import NavigateToPose
    from tms_ts.nodes.ros_port import ManagerRosPort

    port = ManagerRosPort(ros_node)
    assert port.planning_server_ready("ic120", "st_ic120_no_such_subtask") is None
    assert port.planning_server_ready("ic120", "st_ic120_navigate_anywhere") is False
    server = ActionServer(ros_node, NavigateToPose, "/ic120/navigate_to_pose", execute_callback=lambda gh: None)
    end = time.monotonic() + 10.0
    while not port.planning_server_ready("ic120", "st_ic120_navigate_anywhere") and time.monotonic() < end:
        ros_node.executor_for_test.spin_once(timeout_sec=0.05)
    assert port.planning_server_ready("ic120", "st_ic120_navigate_anywhere") is True
    assert port.planning_server_ready("ic120", "st_ic120_navigate_anywhere_deg") is True  # same planning action
    server.destroy()
