"""Helpers for the IC120 integration tests: spinning, action calls, pose messages, truth recording."""

from __future__ import annotations

import math
import time


def spin_until(node, pred, timeout: float, step: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        node.executor_for_test.spin_once(timeout_sec=step)
        if pred():
            return True
    return False


def spin_for(node, seconds: float) -> None:
    spin_until(node, lambda: False, seconds)


def pose_stamped(x: float, y: float, yaw: float, frame: str = "map"):
    from geometry_msgs.msg import PoseStamped

    p = PoseStamped()
    p.header.frame_id = frame
    p.pose.position.x, p.pose.position.y = float(x), float(y)
    p.pose.orientation.z, p.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return p


def yaw_of(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


class ActionCall:
    """send a goal, collect feedback, wait for the result (all by spinning the test node)."""

    def __init__(self, node, action_type, name: str, goal, *, server_timeout: float = 30.0) -> None:
        from rclpy.action import ActionClient

        self.node = node
        self.client = ActionClient(node, action_type, name)
        assert spin_until(node, self.client.server_is_ready, server_timeout), f"action server {name} not available"
        self.feedback = []
        fut = self.client.send_goal_async(goal, feedback_callback=lambda m: self.feedback.append(m.feedback))
        assert spin_until(node, fut.done, 10.0), f"{name}: goal not answered"
        self.handle = fut.result()
        assert self.handle.accepted
        self._result = self.handle.get_result_async()

    def wait(self, timeout: float):
        assert spin_until(self.node, self._result.done, timeout), "no result in time"
        r = self._result.result()
        return r.status, r.result

    def cancel(self) -> None:
        fut = self.handle.cancel_goal_async()
        assert spin_until(self.node, fut.done, 10.0)


class Truth:
    """Records /sim/truth/ic120/pose (receive time, x, y, yaw) and the vessel truth angle."""

    def __init__(self, node) -> None:
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState

        self.poses: list[tuple[float, float, float, float]] = []
        self.stamped: list[tuple[float, float, float, float]] = []  # (sim stamp, x, y, yaw)
        self.recv_wall: list[float] = []
        self.joints: dict[str, float] = {}
        node.create_subscription(PoseStamped, "/sim/truth/ic120/pose", self._on_pose, 50)
        node.create_subscription(JointState, "/sim/truth/ic120/joint_states", self._on_joints, 50)

    def _on_pose(self, m) -> None:
        self.poses.append((time.monotonic(), m.pose.position.x, m.pose.position.y, yaw_of(m.pose.orientation)))
        st = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        self.stamped.append((st, m.pose.position.x, m.pose.position.y, yaw_of(m.pose.orientation)))
        self.recv_wall.append(time.time())

    def wall_series(self, window: float = 2.0) -> list[tuple[float, float, float, float]]:
        """Truth re-timed to wall clock: sim stamp + the least delay seen within +-``window`` s (robust to load)."""
        import numpy as np

        sim = np.array([p[0] for p in self.stamped])
        delay = np.array(self.recv_wall) - sim
        out = []
        for i, p in enumerate(self.stamped):
            near = np.abs(sim - sim[i]) <= window
            out.append((sim[i] + float(delay[near].min()), p[1], p[2], p[3]))
        return out

    def _on_joints(self, m) -> None:
        self.joints = dict(zip(m.name, m.position, strict=False))

    @property
    def last(self) -> tuple[float, float, float]:
        return self.poses[-1][1:]

    def at(self, t: float, *, series: list | None = None) -> tuple[float, float, float] | None:
        """Truth linearly interpolated at monotonic receive time ``t`` (or at time ``t`` of ``series``)."""
        import bisect

        series = self.poses if series is None else series
        ts = [p[0] for p in series]
        i = bisect.bisect_left(ts, t)
        if i == 0 or i >= len(ts):
            return None
        (t0, x0, y0, a0), (t1, x1, y1, a1) = series[i - 1], series[i]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 0.0
        da = (a1 - a0 + math.pi) % (2 * math.pi) - math.pi
        return x0 + f * (x1 - x0), y0 + f * (y1 - y0), a0 + f * da
