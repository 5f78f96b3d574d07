"""Node ``tms_sd_terrain_dynamic``: the site's scans -> the dynamic terrain heightmap in the DB.

The original's ``tms_sd_terrain_dynamic`` (``DATA_ID`` 3031, ``type: dynamic``) relays each dynamic-terrain
PointCloud2 it receives to GridFS; ours rasterises the scan into the same 16-bit heightmap the static terrain is
(:class:`tms_sp.terrain.DynamicTerrain`) and stores it through the store's GridFS API, so that
``tms_db_reader_heightmap`` answers ``dynamic`` like ``static``. The newest ``keep`` dynamic heightmaps are kept.

Input: ``points_topic`` (default ``/sim/sensors/mound/points``, the plant's mound scan that ``tms_sp_sensing``
reads; sensor_msgs/PointCloud2, x/y/z FLOAT32, frame ``map``). The region is the sensing configuration's mound
grid (``config/tms_sp/sensing.yaml``: the mound's base disk + ``roi_margin``), pixel 0 the site's ground
(``config/site.yaml`` ``mound.ground_z``), unless ``box`` names another region ``[x_min, y_min, x_max, y_max]``
(a design's work area: ``config/launch/design_trench.yaml``, with the plant's ``/sim/sensors/region/points``) and
``z_min`` another pixel 0: the 16-bit heightmap clips below its pixel 0, so a design cut below the ground needs
``z_min`` under its bottom.

Parameters (read-only): ``db_uri``, ``db_path``, ``config``, ``site`` ("" = the defaults), ``points_topic``,
``period_s`` (0.0: every scan received, as the original writes each cloud; > 0: the latest scan every period),
``resolution`` (0.0 = the sensing grid's, 0.1 m), ``keep`` (20), ``filename`` (``dynamic_terrain.png``),
``id`` (3031), ``box`` (``[0, 0, 0, 0]``: the mound grid), ``z_min`` (NaN: the site's ground). A scan that cannot
be rasterised is logged naming the topic and dropped.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from tms_common.errors import ConfigError, TmsError
from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db import StoreOwner, declare_and_open
from tms_sp.config import load_sensing_config
from tms_sp.pointcloud import xyz_from_cloud
from tms_sp.terrain import DYNAMIC_ID, DynamicTerrain, region_box

__all__ = ["TmsSdTerrainDynamic", "main"]


class TmsSdTerrainDynamic(StoreOwner, Node):
    """Writes dynamic heightmaps from scans; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sd_terrain_dynamic", **kwargs)
        config = str(declare_startup(self, "config", "").value)
        site = str(declare_startup(self, "site", "").value)
        cfg = load_sensing_config(config or None, site or None)
        self.topic = str(declare_startup(self, "points_topic", "/sim/sensors/mound/points").value)
        period = float(declare_startup(self, "period_s", 0.0).value)
        if period < 0:
            raise ConfigError(f"tms_sd_terrain_dynamic: parameter period_s must be >= 0, got {period}")
        resolution = float(declare_startup(self, "resolution", 0.0).value) or cfg.mound_grid.resolution
        keep = int(declare_startup(self, "keep", 20).value)
        filename = str(declare_startup(self, "filename", "dynamic_terrain.png").value)
        ident = int(declare_startup(self, "id", DYNAMIC_ID).value)
        box_values = declare_startup(self, "box", [0.0, 0.0, 0.0, 0.0]).value
        z_min = float(declare_startup(self, "z_min", float("nan")).value)
        if z_min != z_min:  # NaN: the site's ground, as the static terrain
            z_min = cfg.mound.ground_z
        self.store = declare_and_open(self)
        try:
            box = region_box(box_values, resolution, source="tms_sd_terrain_dynamic: parameter box") or cfg.mound_grid
            self.terrain = DynamicTerrain(self.store, box, resolution, z_min, keep=keep,
                                          filename=filename, ident=ident)
        except TmsError as exc:
            raise ConfigError(f"tms_sd_terrain_dynamic: {exc}") from None
        self._latest: Any = None
        self.create_subscription(PointCloud2, self.topic, self._on_cloud, 2)
        if period > 0:
            self.create_timer(period, self._store_latest)
        b = box
        self.get_logger().info(f"dynamic terrain: {self.topic} -> type dynamic id {ident} {filename!r}, x "
                               f"{b.x_min:g}..{b.x_max:g} y {b.y_min:g}..{b.y_max:g} at {resolution:g} m, "
                               f"pixel 0 at z {z_min:g} m, "
                               f"{'every scan' if period == 0 else f'every {period:g} s'}, keep {keep}")
        self._period = period

    def _on_cloud(self, msg: Any) -> None:
        self._latest = msg
        if self._period == 0:
            self._store_latest()

    def _store_latest(self) -> None:
        msg, self._latest = self._latest, None
        if msg is None:
            return
        try:
            self.terrain.on_points(xyz_from_cloud(msg, topic=self.topic), source=self.topic)
        except TmsError as exc:
            self.get_logger().warning(f"dynamic terrain not stored: {exc}", throttle_duration_sec=5.0)


def main() -> int:
    return run_node(TmsSdTerrainDynamic)


if __name__ == "__main__":
    sys.exit(main())
