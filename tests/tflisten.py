"""A tf listener built on tf2_msgs only (tf2_ros is not in the ROS wheels): /tf and /tf_static into a buffer.

As tf2's buffer: each child frame has one parent; static edges hold for all time; dynamic edges are kept per
stamp (the last ``history`` of each) and looked up at a stamp (the newest at or before it) or the newest.
"""

from __future__ import annotations

import bisect
from collections import defaultdict
from typing import Any

from tms_model.transform import Transform

__all__ = ["TfListener"]


def _stamp(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _transform(msg: Any) -> Transform:
    t, r = msg.transform.translation, msg.transform.rotation
    return Transform((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))


class TfListener:
    """Subscribes ``/tf`` and ``/tf_static`` on ``node`` with tf2's QoS profiles."""

    def __init__(self, node: Any, history: int = 2000) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        from tf2_msgs.msg import TFMessage

        self.history = history
        self.static: dict[str, tuple[str, Transform]] = {}
        self.dynamic: dict[str, list[tuple[float, str, Transform]]] = defaultdict(list)
        self.messages = 0
        dyn = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
        static = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(TFMessage, "/tf", self._on_tf, dyn)
        node.create_subscription(TFMessage, "/tf_static", self._on_static, static)

    def _on_tf(self, msg: Any) -> None:
        self.messages += 1
        for t in msg.transforms:
            edges = self.dynamic[t.child_frame_id]
            item = (_stamp(t.header), t.header.frame_id, _transform(t))
            bisect.insort(edges, item, key=lambda e: e[0])
            del edges[: max(0, len(edges) - self.history)]

    def _on_static(self, msg: Any) -> None:
        for t in msg.transforms:
            self.static[t.child_frame_id] = (t.header.frame_id, _transform(t))

    def stamps(self, child: str) -> list[float]:
        return [e[0] for e in self.dynamic.get(child, [])]

    def _edge(self, child: str, at: float | None) -> tuple[str, Transform] | None:
        if child in self.static:
            return self.static[child]
        edges = self.dynamic.get(child)
        if not edges:
            return None
        if at is None:
            return edges[-1][1], edges[-1][2]
        i = bisect.bisect_right([e[0] for e in edges], at + 1e-9)
        if i == 0:
            return None
        return edges[i - 1][1], edges[i - 1][2]

    def lookup(self, target: str, source: str, at: float | None = None) -> Transform | None:
        """``target_T_source`` (``source`` frame's points in ``target``), or None while a link is missing."""
        out = Transform()
        frame = source
        for _ in range(64):
            if frame == target:
                return out
            edge = self._edge(frame, at)
            if edge is None:
                return None
            parent, transform = edge
            out = transform * out
            frame = parent
        raise RuntimeError(f"tf loop or chain longer than 64 from {source!r} towards {target!r}")
