"""Two nodes on the ``events`` executor for tests/tms_common/test_rclpy_compat.py, each its own process
through run_node.

``python -m tests.tms_common.events_nodes talker``: publishes ``std_msgs/Header`` on ``events_chatter`` from a 20 Hz
timer (rclpy's default SIGINT handling). ``... listener``: counts them, prints ``heard N`` every 5th, stopped
in context (SIGINT reaches it through ``call_soon``, not a guard condition) with an ``on_stop_requested``
hook that asks twice; prints ``listener: destroyed with context ok`` when ``destroy_node`` runs.
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from std_msgs.msg import Header

from tms_common.node import run_node


class Talker(Node):
    def __init__(self) -> None:
        super().__init__("events_talker")
        self._pub = self.create_publisher(Header, "events_chatter", 10)
        self.create_timer(0.05, lambda: self._pub.publish(Header(frame_id="x")))
        print("talker up", flush=True)


class Listener(Node):
    def __init__(self) -> None:
        super().__init__("events_listener")
        self.heard = 0
        self._asked = 0
        self.create_subscription(Header, "events_chatter", self._on_msg, 10)
        print("listener up", flush=True)

    def _on_msg(self, _msg: Header) -> None:
        self.heard += 1
        if self.heard % 5 == 0:
            print(f"heard {self.heard}", flush=True)

    def on_stop_requested(self) -> bool:
        self._asked += 1
        print(f"stop requested ({self._asked})", flush=True)
        return self._asked < 2  # spin on once more, then let it stop

    def destroy_node(self) -> None:
        print(f"listener: destroyed with context {'ok' if self.context.ok() else 'shut down'}", flush=True)
        super().destroy_node()


if __name__ == "__main__":
    if sys.argv[1] == "talker":
        sys.exit(run_node(Talker, executor="events"))
    sys.exit(run_node(Listener, executor="events", stop_in_context=True))
