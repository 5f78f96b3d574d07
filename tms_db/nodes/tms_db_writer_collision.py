"""``tms_db_writer_collision``: the original's ``tms_db_writer_collision``.

Topic ``/tms_db_collision`` (tms_msg_db/msg/TmsdbCollision): the mesh file ``filepath`` (read on this host) into
the parameter record ``collision_object_<file stem>`` of ``model_name``, its bytes in ``data``, ``type`` the
message's; a new record starts at the original's pose (x 8 m, identity), an existing one keeps its pose
(:func:`tms_db.boundary.write_collision`). The file stays. The original's node shuts down after one message; this one
keeps serving. A missing file or a record over the document limit is logged naming the topic and field, nothing
stored. Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_db.boundary import COLLISION_TOPIC, write_collision
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg_db.msg import TmsdbCollision

__all__ = ["main", "TmsDbWriterCollision"]


class TmsDbWriterCollision(StoreOwner, Node):
    """Stores collision-object meshes as records."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_writer_collision", **kwargs)
        self.store = declare_and_open(self)
        self.create_subscription(TmsdbCollision, COLLISION_TOPIC, self._on_mesh, 10)
        self.get_logger().info(f"tms_db_writer_collision ready: {COLLISION_TOPIC}")

    def _on_mesh(self, msg) -> None:
        try:
            doc = write_collision(self.store, msg.model_name, msg.type, msg.filepath)
        except StoreError as exc:
            self.get_logger().error(f"{COLLISION_TOPIC} dropped: {exc}")
            return
        self.get_logger().info(f"{COLLISION_TOPIC}: stored {msg.filepath!r} ({len(doc['data'])} bytes) as record "
                               f"{doc['record_name']!r}")


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbWriterCollision, args)


if __name__ == "__main__":
    sys.exit(main())
