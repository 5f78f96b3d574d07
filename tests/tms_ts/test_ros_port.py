"""ManagerRosPort with a real rclpy node (no other process needed)."""

from __future__ import annotations


def test_lock_engage_then_release_logs_both(ros_node) -> None:  # noqa: ANN001
    """rclpy refuses a log call whose severity differs from the last call at the same line: engaging the lock
    (warning) and then releasing it (info) raised ValueError inside the manager's tick."""
    from tms_ts.nodes.ros_port import ManagerRosPort

    port = ManagerRosPort(ros_node)
    for _ in range(2):
        port.lock("zx200", True, "task cancelled")
        assert port.locked["zx200"] is True
        port.lock("zx200", False, "new goal")
        assert port.locked["zx200"] is False
