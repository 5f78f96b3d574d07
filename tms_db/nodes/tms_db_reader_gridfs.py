"""``tms_db_reader_gridfs``: the original's ``tms_db_reader_gridfs`` action server.

Action ``/tms_db_reader_gridfs`` (tms_msg_db/action/TmsdbGridFS), by the goal's ``type``:

* ``static``, ``mesh``, ``dem``: the newest blob of that type and ``filename`` is written to the file ``filename``
  on this host (as the original; through a temporary file and a rename, so a reader never sees half of it);
  result ``true``, ``msg`` naming the file and size.
* ``dynamic``: the stored point clouds decoded from the original's text (frame ``map``): with ``latest_only`` the
  newest, otherwise each in ascending time; each is published as feedback and the last is the result's
  ``pointcloud2``.

The original polls until a static blob appears and streams dynamic clouds forever; this server answers once: a
blob not found, a blob that does not decode or an unknown type ends the goal aborted with ``result`` false and
``msg`` naming it (logged too). Parameters: ``db_uri``, ``db_path``.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from rclpy.action import ActionServer
from rclpy.node import Node

from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_db.boundary import CLOUD_TYPE, FILE_TYPES, GRIDFS_ACTION, read_clouds, read_file_blob
from tms_db.errors import StoreError
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_db.nodes.pointcloud import cloud_to_msg
from tms_msg_db.action import TmsdbGridFS

__all__ = ["main", "TmsDbReaderGridFS", "write_file"]


def write_file(path: str, data: bytes) -> None:
    """``data`` into ``path`` through a temporary file in its directory and a rename."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent or ".")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class TmsDbReaderGridFS(StoreOwner, Node):
    """Reads blobs back: files to disk, point clouds into the result."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_reader_gridfs", **kwargs)
        self.store = declare_and_open(self)
        self._server = ActionServer(self, TmsdbGridFS, GRIDFS_ACTION, self._execute,
                                    result_timeout=ACTION_RESULT_TIMEOUT_S)
        self.get_logger().info(f"tms_db_reader_gridfs ready: {GRIDFS_ACTION}")

    def _execute(self, goal_handle):
        goal = goal_handle.request
        result = TmsdbGridFS.Result()
        try:
            if goal.type in FILE_TYPES:
                meta, data = read_file_blob(self.store, goal.type, goal.filename)
                try:
                    write_file(goal.filename, data)
                except OSError as exc:
                    raise StoreError(f"field 'filename': cannot write {goal.filename!r}: "
                                     f"{exc.strerror or exc}") from None
                result.msg = f"wrote {len(data)} bytes of blob {meta['_id']} (time {meta.get('time')!r}) to " \
                             f"{goal.filename}"
            elif goal.type == CLOUD_TYPE:
                clouds = read_clouds(self.store, goal.type, goal.latest_only)
                if not clouds:
                    raise StoreError(f"no {goal.type!r} point cloud stored")
                for cloud in clouds:
                    goal_handle.publish_feedback(TmsdbGridFS.Feedback(result=True, msg=cloud.time,
                                                                      pointcloud2=cloud_to_msg(cloud)))
                result.pointcloud2 = cloud_to_msg(clouds[-1])
                result.msg = f"{len(clouds)} point cloud(s), the last of time {clouds[-1].time!r}"
            else:
                raise StoreError(f"field 'type': {goal.type!r} is not a GridFS type "
                                 f"({', '.join(FILE_TYPES)}, {CLOUD_TYPE})")
        except StoreError as exc:
            self.get_logger().error(f"{GRIDFS_ACTION}: {exc}")
            result.result, result.msg = False, str(exc)
            goal_handle.abort()
            return result
        result.result = True
        goal_handle.succeed()
        return result

    def destroy_node(self) -> None:
        self._server.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(TmsDbReaderGridFS, args)


if __name__ == "__main__":
    sys.exit(main())
