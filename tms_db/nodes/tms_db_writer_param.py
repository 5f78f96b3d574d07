"""``tms_db_writer_param``: the original's ``tms_db_writer_param`` (node ``tms_db_writer_query``).

Topic ``/tms_db_param_data`` (tms_msg_db/msg/TmsdbQuery): by ``type``, ``pose`` and ``joint`` write a record of
``vehicle_name`` / ``record_name`` from ``add_path`` / ``add_joints``, ``pose_query`` sets (``writemode``
``over_write``) or appends the waypoint arrays of an existing record (:func:`tms_db.boundary.apply_query`). A query
for a record that does not exist, an unknown ``type``, too few joint positions or a record the store refuses is
logged naming the topic, record and field; nothing is stored then. Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_db.boundary import PARAM_TOPIC, POSE_FIELDS, apply_query
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg_db.msg import TmsdbQuery

__all__ = ["main", "TmsDbWriterParam", "query_pose"]


def query_pose(msg: Any) -> dict[str, float]:
    """``add_path.pose`` of a TmsdbQuery as ``x y z qx qy qz qw``."""
    p, q = msg.add_path.pose.position, msg.add_path.pose.orientation
    return dict(zip(POSE_FIELDS, (p.x, p.y, p.z, q.x, q.y, q.z, q.w), strict=True))


class TmsDbWriterParam(StoreOwner, Node):
    """Applies TmsdbQuery writes to the parameter records."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_writer_query", **kwargs)
        self.store = declare_and_open(self)
        self.create_subscription(TmsdbQuery, PARAM_TOPIC, self._on_query, 10)
        self.get_logger().info(f"tms_db_writer_param ready: {PARAM_TOPIC}")

    def _on_query(self, msg) -> None:
        try:
            doc = apply_query(self.store, msg.type, msg.writemode, msg.record_name, msg.vehicle_name,
                              query_pose(msg), list(msg.add_joints.position))
        except StoreError as exc:
            self.get_logger().error(f"{PARAM_TOPIC} dropped: {exc}")
            return
        self.get_logger().info(f"{PARAM_TOPIC}: {msg.type} {msg.writemode or '-'} stored record "
                               f"{doc.get('record_name')!r} of {doc.get('model_name') or 'no model'!r}")


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbWriterParam, args)


if __name__ == "__main__":
    sys.exit(main())
