"""Node ``tms_sp_ingest``: an existing sensing PC drives the DB through the original's sensing topics.

Subscribes every topic of :data:`tms_sp.ingest.SENSING_TOPICS` with its ``sensing_msgs`` type (the
original's ``tms_sp_sensing`` updaters, one node each there, one subscription each here) and writes each
message into its dynamic record by the original's rule (:class:`tms_sp.ingest.SensingWriter`, the path
our own ``tms_sp_sensing`` writes through too):

=====================================  =========================  =====================================
topic                                  type                       record
=====================================  =========================  =====================================
``/tms_sp_change_pose``, ...           ``sensing_msgs/<Type>``    (model_name, record_name), dynamic
``/Flgs``                              ``sensing_msgs/Flgs202508`` record_name, dynamic; keep_val_flgs
=====================================  =========================  =====================================

QoS: reliable, depth 10 (the original's subscriptions). A message that cannot be written (record
missing or not dynamic, a value of the wrong shape) is logged naming the topic, record and field, and
dropped; the node goes on. Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import importlib
import sys
from typing import Any

from rclpy.node import Node

from tms_common.errors import TmsError
from tms_common.node import run_node
from tms_db import StoreOwner, declare_and_open
from tms_sp.ingest import SENSING_TOPICS, SensingTopic, SensingWriter

__all__ = ["SensingIngest", "main"]


class SensingIngest(StoreOwner, Node):
    """Writes the original's sensing messages into the DB; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sp_ingest", **kwargs)
        self.store = declare_and_open(self)
        self.writer = SensingWriter(self.store)
        self.written = 0
        msgs = importlib.import_module("sensing_msgs.msg")
        for topic in SENSING_TOPICS:
            msg_type = getattr(msgs, topic.type_name)
            self.create_subscription(msg_type, topic.topic, lambda m, t=topic: self._on_message(t, m), 10)
        self.get_logger().info(f"tms_sp_ingest ready: {len(SENSING_TOPICS)} sensing topics -> {self.store!r}")

    def _on_message(self, topic: SensingTopic, msg: Any) -> None:
        fields = {name: getattr(msg, name) for name in msg.get_fields_and_field_types()}
        try:
            written = self.writer.write_message(topic, fields)
        except TmsError as exc:  # SensingError (record), StoreError / ValidationError (shape)
            self.get_logger().error(f"{topic.topic}: dropped: {exc}")
            return
        self.written += 1
        if written:
            self.get_logger().debug(f"{topic.topic}: {fields.get('record_name')} <- {sorted(written)}")
        else:
            self.get_logger().warning(
                f"{topic.topic}: record {fields.get('record_name')!r} has none of the message's fields",
                throttle_duration_sec=5.0,
            )


def main() -> int:
    return run_node(SensingIngest)


if __name__ == "__main__":
    sys.exit(main())
