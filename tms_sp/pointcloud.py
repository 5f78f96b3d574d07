"""sensor_msgs/PointCloud2 <-> numpy for xyz float32 clouds, without sensor_msgs_py (not in the wheels).

Pure functions over the message's fields (``fields``, ``point_step``, ``data``...), so they are tested
without rclpy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tms_sp.errors import SensingError

__all__ = ["xyz_from_cloud", "FLOAT32"]

FLOAT32 = 7  # sensor_msgs/PointField.FLOAT32


def xyz_from_cloud(msg: Any, *, topic: str = "points") -> np.ndarray:
    """``(N, 3)`` float array of the x, y, z fields of a PointCloud2 (any extra fields ignored)."""
    offsets = {}
    for f in msg.fields:
        if f.name in ("x", "y", "z"):
            if f.datatype != FLOAT32 or f.count not in (0, 1):
                raise SensingError(f"{topic}: field {f.name} must be one FLOAT32, got datatype {f.datatype} x{f.count}")
            offsets[f.name] = f.offset
    if set(offsets) != {"x", "y", "z"}:
        raise SensingError(f"{topic}: PointCloud2 needs fields x, y, z; has {[f.name for f in msg.fields]}")
    n = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = bytes(msg.data)
    if n == 0:
        return np.zeros((0, 3))
    if len(data) < n * step:
        raise SensingError(f"{topic}: {len(data)} bytes for {n} points of {step} bytes")
    endian = ">" if msg.is_bigendian else "<"
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": [endian + "f4"] * 3,
                      "offsets": [offsets["x"], offsets["y"], offsets["z"]], "itemsize": step})
    arr = np.frombuffer(data[: n * step], dtype=dtype, count=n)
    return np.column_stack([arr["x"], arr["y"], arr["z"]]).astype(float)
