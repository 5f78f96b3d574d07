"""Node ``tms_db_reader_heightmap``: the original's heightmap reader action over the store's GridFS.

Action ``tms_db_reader_heightmap`` (``tms_msg_db/action/TmsdbTerrainImage``, the original's name and type). Goal
``type`` (``static``, ``heightmap``, ``texture``, ``dynamic``), ``id`` (0 = any), ``filename`` ("" = any; the
original filters static ones by filename always); the result is the newest matching heightmap
(:func:`tms_db.heightmap.find_heightmap`): ``result`` true, ``time``, ``type``, ``filename``, ``terrainheight`` /
``terrainwidth`` / ``terrainelevation`` / ``offset_x`` / ``offset_y`` from the file document's ``height``,
``width``, ``elevation``, ``offset_x``, ``offset_y``, and ``image`` (encoding per parameter ``image_encoding``:
``bgr8``, the original's, or ``mono16``, the stored 16-bit values), frame ``map``.

Where the original waits (it loops until a matching file appears) or answers an unknown type with an empty
result, ours ends the goal ABORTED at once with ``result`` false and ``msg`` naming the type, id and filename asked
for. The original's ``dynamic`` branch streams stored point clouds as feedback, which its ``TmsdbTerrainImage``
feedback (empty) cannot carry; here dynamic terrain is a heightmap like the static one
(``tms_sd_terrain_dynamic`` stores it) and is answered the same way.

Parameters: ``db_uri``, ``db_path``, ``image_encoding`` (``bgr8``).
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.action import ActionServer
from rclpy.node import Node
from sensor_msgs.msg import Image

from tms_common.errors import ConfigError
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_db.errors import StoreError
from tms_db.heightmap import ENCODINGS, find_heightmap, image_of
from tms_db.nodes.common import StoreOwner, declare_and_open
from tms_msg_db.action import TmsdbTerrainImage

__all__ = ["ACTION", "TmsDbReaderHeightmap", "main"]

ACTION = "tms_db_reader_heightmap"


class TmsDbReaderHeightmap(StoreOwner, Node):
    """Serves stored heightmaps; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_db_reader_heightmap", **kwargs)
        self.encoding = str(declare_startup(self, "image_encoding", "bgr8").value)
        if self.encoding not in ENCODINGS:
            raise ConfigError(f"tms_db_reader_heightmap: parameter image_encoding {self.encoding!r}: "
                              f"one of {', '.join(ENCODINGS)}")
        self.store = declare_and_open(self)
        self._server = ActionServer(self, TmsdbTerrainImage, ACTION, execute_callback=self._execute,
                                    result_timeout=ACTION_RESULT_TIMEOUT_S)
        self.get_logger().info(f"{ACTION} ready ({self.encoding})")

    def _execute(self, goal_handle: Any) -> Any:
        req = goal_handle.request
        result = TmsdbTerrainImage.Result()
        result.type = req.type
        result.filename = req.filename
        try:
            doc, data = find_heightmap(self.store, req.type, req.id, req.filename)
            fields = image_of(data, self.encoding, source=f"{doc.get('filename')} ({doc['_id']})")
            result.time = str(doc.get("time", ""))
            result.filename = str(doc.get("filename") or "")
            result.terrainheight = float(doc.get("height", 0.0))
            result.terrainwidth = float(doc.get("width", 0.0))
            result.terrainelevation = float(doc.get("elevation", 0.0))
            result.offset_x = float(doc.get("offset_x", 0.0))
            result.offset_y = float(doc.get("offset_y", 0.0))
        except (StoreError, TypeError, ValueError) as exc:
            result.result = False
            result.msg = f"{ACTION}: {exc}"
            self.get_logger().warning(result.msg)
            goal_handle.abort()
            return result
        image = Image(**fields)
        image.header.frame_id = "map"
        image.header.stamp = self.get_clock().now().to_msg()
        result.image = image
        result.result = True
        result.msg = f"{result.type} heightmap {result.filename} of {result.time}"
        goal_handle.succeed()
        return result


def main() -> int:
    return run_node(TmsDbReaderHeightmap)


if __name__ == "__main__":
    sys.exit(main())
