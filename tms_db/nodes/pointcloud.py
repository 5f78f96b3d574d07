"""``sensor_msgs/PointCloud2`` <-> :class:`tms_db.boundary.Cloud`, for the GridFS writer and reader nodes."""

from __future__ import annotations

from typing import Any

from sensor_msgs.msg import PointCloud2, PointField

from tms_db.boundary import Cloud, PointFieldSpec

__all__ = ["cloud_from_msg", "cloud_to_msg"]


def cloud_from_msg(msg: Any) -> Cloud:
    return Cloud(height=msg.height, width=msg.width,
                 fields=tuple(PointFieldSpec(f.name, f.offset, f.datatype, f.count) for f in msg.fields),
                 is_bigendian=msg.is_bigendian, point_step=msg.point_step, row_step=msg.row_step,
                 data=bytes(msg.data), is_dense=msg.is_dense)


def cloud_to_msg(cloud: Cloud, frame_id: str = "map") -> PointCloud2:
    """The cloud as the original's reader fills it: frame ``map``, no stamp."""
    msg = PointCloud2(height=cloud.height, width=cloud.width, is_bigendian=cloud.is_bigendian,
                      point_step=cloud.point_step, row_step=cloud.row_step, is_dense=cloud.is_dense,
                      fields=[PointField(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
                              for f in cloud.fields])
    msg.header.frame_id = frame_id
    msg.data = cloud.data
    return msg
