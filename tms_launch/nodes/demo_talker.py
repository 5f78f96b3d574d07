"""``demo_talker``: a demonstration talker (foundation tests and benchmarks)."""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from std_msgs.msg import Header

from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import declare_startup


class Talker(Node):
    """Publishes a time-stamped ``std_msgs/Header`` on ``chatter`` at ``rate_hz``.

    ``shutdown_delay_s`` (0): when stopped, take this long to shut down (a node finishing its work on the
    way out), then print "talker: shut down"."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("talker", **kwargs)
        rate = declare_startup(self, "rate_hz", 100.0).value
        if not rate or rate <= 0:
            raise ConfigError(f"talker: parameter rate_hz must be > 0, got {rate}")
        self._shutdown_delay = float(declare_startup(self, "shutdown_delay_s", 0.0).value)
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


def main() -> int:
    return run_node(Talker, executor="single")
