"""``tms_db_writer_gridfs``: the original's ``tms_db_writer_gridfs``.

Topic ``/tms_db_gridfs_data`` (tms_msg_db/msg/TmsdbGridFS), by ``type`` (:func:`tms_db.boundary.put_gridfs`):

* ``static``, ``mesh``, ``dem``: the file named by ``filename`` (a path on this host) becomes a blob with
  ``filename``, ``time``, ``type``, ``id``; the file is then removed (``remove_file``, default true: the original's
  hand-off, the producer wrote it for the DB). A refused write leaves the file where it was.
* ``dynamic``: ``pointcloud2`` as the original stores it (its bytes as comma-separated decimal text, with
  ``height width is_bigendian point_step row_step fields is_dense``), no filename.

A file that cannot be read, a blob over the store's limit (``max_blob_bytes``, BlobTooLarge) or another type is
logged naming the topic and field; nothing is stored. Parameters: ``db_uri``, ``db_path``, ``remove_file`` (true),
``max_blob_bytes`` (0: the store's default, 64 MiB).
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db.boundary import CLOUD_TYPE, GRIDFS_TOPIC, put_gridfs
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_db.nodes.pointcloud import cloud_from_msg
from tms_msg_db.msg import TmsdbGridFS

__all__ = ["main", "TmsDbWriterGridFS"]


class TmsDbWriterGridFS(StoreOwner, Node):
    """Stores files and point clouds as blobs."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_writer_gridfs", **kwargs)
        self.remove_file = bool(declare_startup(self, "remove_file", True).value)
        max_blob = int(declare_startup(self, "max_blob_bytes", 0).value)
        self.store = declare_and_open(self, **({"max_blob_bytes": max_blob} if max_blob else {}))
        self.create_subscription(TmsdbGridFS, GRIDFS_TOPIC, self._on_data, 10)
        self.get_logger().info(f"tms_db_writer_gridfs ready: {GRIDFS_TOPIC} (blobs up to "
                               f"{self.store.max_blob_bytes:,} bytes, remove_file {self.remove_file})")

    def _on_data(self, msg) -> None:
        try:
            cloud = cloud_from_msg(msg.pointcloud2) if msg.type == CLOUD_TYPE else None
            file_id = put_gridfs(self.store, msg.type, msg.id, msg.time, msg.filename, cloud,
                                 remove_file=self.remove_file)
        except StoreError as exc:
            self.get_logger().error(f"{GRIDFS_TOPIC} dropped: {exc}")
            return
        self.get_logger().info(f"{GRIDFS_TOPIC}: stored {msg.type} {msg.filename or '(cloud)'} time {msg.time!r} "
                               f"as blob {file_id}")


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbWriterGridFS, args)


if __name__ == "__main__":
    sys.exit(main())
