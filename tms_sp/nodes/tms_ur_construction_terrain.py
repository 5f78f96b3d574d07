"""Node ``tms_ur_construction_terrain``: the original's terrain services, served from the heightmaps in the DB.

The original serves each from its own ``tms_ur_construction`` node after reading a file through an action; here
one node answers every request from the newest stored heightmap (:mod:`tms_sp.terrain`), so a request sees the
terrain as it is now. Request ``type``: ``""`` or ``static`` = the static terrain, ``dynamic`` = the newest
dynamic one (``tms_sd_terrain_dynamic``), any other stored type by name.

===================================  ====================================  ======================================
service (relative)                   type                                  answer
===================================  ====================================  ======================================
``output/terrain/static_srv``        ``tms_msg_db/srv/TerrainStaticSrv``   cell centres as x, y, z, r, g, b FLOAT32
``output/terrain/dem_srv``           ``tms_msg_db/srv/DemSrv``             nav_msgs/OccupancyGrid, cells -128..127
``output/terrain/mesh_srv``          ``tms_msg_db/srv/ColoredMeshSrv``     tms_msg_db/ColoredMesh of the surface
``output/terrain/heightmap_srv``     ``tms_msg_db/srv/TmsdbTerrainImageSrv`` the heightmap image and its fields
===================================  ====================================  ======================================

Names: ``static_srv``, ``dem_srv``, ``mesh_srv`` as the original's launch files remap them;
``heightmap_srv`` is the name its ``tms_ur_construction_launch.py`` remaps for the heightmap node (whose code
serves ``TmsdbTerrainImageSrv`` under ``mesh_srv``, which here is the ``ColoredMeshSrv`` of its README).
Nothing stored for the type asked: an empty answer, logged naming the type (these services have no error field).

Parameters (read-only): ``db_uri``, ``db_path``, ``image_encoding`` (``bgr8``, the original's reader; or
``mono16``), ``max_vertices`` (40000: the mesh takes every n-th cell to stay below).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from geometry_msgs.msg import Point, Vector3
from rclpy.node import Node
from sensor_msgs.msg import Image, PointField
from shape_msgs.msg import MeshTriangle
from std_msgs.msg import ColorRGBA

from tms_common.errors import ConfigError, TmsError
from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db import StoreOwner, declare_and_open
from tms_msg_db.srv import ColoredMeshSrv, DemSrv, TerrainStaticSrv, TmsdbTerrainImageSrv
from tms_sp.terrain import (
    Heightmap,
    cloud_xyzrgb,
    colored_mesh,
    decode_png,
    dem,
    heightmap_from_blob,
    image_8bit,
    latest_heightmap,
)

__all__ = ["TmsUrConstructionTerrain", "main", "SERVICES"]

SERVICES = {"static": "output/terrain/static_srv", "dem": "output/terrain/dem_srv",
            "mesh": "output/terrain/mesh_srv", "heightmap": "output/terrain/heightmap_srv"}


class TmsUrConstructionTerrain(StoreOwner, Node):
    """Serves the terrain services; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_construction_terrain", **kwargs)
        self.encoding = str(declare_startup(self, "image_encoding", "bgr8").value)
        if self.encoding not in ("bgr8", "mono16"):
            raise ConfigError(f"tms_ur_construction_terrain: parameter image_encoding {self.encoding!r}: "
                              "bgr8 or mono16")
        self.max_vertices = int(declare_startup(self, "max_vertices", 40000).value)
        if self.max_vertices < 4:
            raise ConfigError(f"tms_ur_construction_terrain: parameter max_vertices must be >= 4, "
                              f"got {self.max_vertices}")
        self.store = declare_and_open(self)
        self.create_service(TerrainStaticSrv, SERVICES["static"], self._static)
        self.create_service(DemSrv, SERVICES["dem"], self._dem)
        self.create_service(ColoredMeshSrv, SERVICES["mesh"], self._mesh)
        self.create_service(TmsdbTerrainImageSrv, SERVICES["heightmap"], self._heightmap)
        self.get_logger().info(f"terrain services ready: {', '.join(SERVICES.values())}")

    def _load(self, kind: str, ident: int = 0, filename: str = "") -> tuple[dict, bytes, Heightmap] | None:
        kind = kind or "static"
        try:
            doc, data = latest_heightmap(self.store, kind, ident=ident, filename=filename)
            return doc, data, heightmap_from_blob(data, doc, source=f"{doc.get('filename')} ({doc['_id']})")
        except TmsError as exc:
            self.get_logger().error(f"terrain request for type {kind!r}: {exc}")
            return None

    def _static(self, request: Any, response: Any) -> Any:
        got = self._load(request.type)
        if got is not None:
            data, n = cloud_xyzrgb(got[2])
            cloud = response.pointcloud2
            cloud.header.frame_id = "map"
            cloud.header.stamp = self.get_clock().now().to_msg()
            cloud.fields = [PointField(name=name, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                            for i, name in enumerate(("x", "y", "z", "r", "g", "b"))]
            cloud.height, cloud.width, cloud.point_step, cloud.row_step = 1, n, 24, 24 * n
            cloud.is_bigendian, cloud.is_dense = False, False
            cloud.data = data
        return response

    def _dem(self, request: Any, response: Any) -> Any:
        got = self._load(request.type)
        if got is not None:
            cells, width, height, resolution, (x0, y0) = dem(got[2])
            grid = response.occupancy_grid
            grid.header.frame_id = "map"
            grid.header.stamp = self.get_clock().now().to_msg()
            grid.info.resolution = resolution
            grid.info.width, grid.info.height = width, height
            grid.info.origin.position.x, grid.info.origin.position.y = x0, y0
            grid.info.origin.orientation.w = 1.0
            grid.data = cells
        return response

    def _mesh(self, request: Any, response: Any) -> Any:
        got = self._load(request.type)
        if got is not None:
            m = colored_mesh(got[2], max_vertices=self.max_vertices)
            out = response.colored_mesh
            out.triangles = [MeshTriangle(vertex_indices=[int(i) for i in t]) for t in m.triangles]
            out.vertices = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in m.vertices]
            out.vertex_colors = [ColorRGBA(r=float(r), g=float(g), b=float(b), a=1.0) for r, g, b in m.colors]
            out.vertex_normals = [Vector3(x=float(x), y=float(y), z=float(z)) for x, y, z in m.normals]
        return response

    def _heightmap(self, request: Any, response: Any) -> Any:
        got = self._load(request.type, request.id, request.filename)
        if got is None:
            return response
        doc, data, _ = got
        try:
            units = decode_png(data, source=str(doc.get("filename")))
        except TmsError as exc:
            self.get_logger().error(f"terrain request for type {request.type!r}: {exc}")
            return response
        if self.encoding == "mono16":
            pixels = np.ascontiguousarray(units.astype("<u2"))
        else:
            pixels = np.ascontiguousarray(image_8bit(units))
        response.time = str(doc.get("time", ""))
        response.type = str(doc.get("type", ""))
        response.id = int(doc.get("id", 0))
        response.filename = str(doc.get("filename") or "")
        response.terrainheight = float(doc.get("height", 0.0))
        response.terrainwidth = float(doc.get("width", 0.0))
        response.terrainelevation = float(doc.get("elevation", 0.0))
        response.offset_x = float(doc.get("offset_x", 0.0))
        response.offset_y = float(doc.get("offset_y", 0.0))
        response.image = Image(height=int(pixels.shape[0]), width=int(pixels.shape[1]), encoding=self.encoding,
                               is_bigendian=0, step=int(pixels.strides[0]), data=pixels.tobytes())
        response.image.header.frame_id = "map"
        response.image.header.stamp = self.get_clock().now().to_msg()
        return response


def main() -> int:
    return run_node(TmsUrConstructionTerrain)


if __name__ == "__main__":
    sys.exit(main())
