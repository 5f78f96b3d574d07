"""``demo_listener``: a demonstration listener (foundation tests and benchmarks)."""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from std_msgs.msg import Header

from tms_common.node import run_node
from tms_common.params import declare_startup


class Listener(Node):
    """Subscribes to ``chatter`` and logs every ``log_every``-th sequence number it receives."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("listener", **kwargs)
        self._every = int(declare_startup(self, "log_every", 100).value)
        self.received = 0
        self.create_subscription(Header, "chatter", self._on_msg, 10)

    def _on_msg(self, msg: Header) -> None:
        self.received += 1
        if self.received % self._every == 1:
            print(f"heard seq={msg.frame_id} total={self.received}", flush=True)


def main() -> int:
    return run_node(Listener, executor="single")
