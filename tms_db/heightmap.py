"""Terrain heightmaps in GridFS as the original's ``tms_db_reader_heightmap`` serves them (no rclpy).

Heightmaps are PNG blobs (:meth:`tms_db.store.Store.put_blob`) whose file document carries the original's fields
``time``, ``type``, ``id``, ``height``, ``width``, ``elevation``, ``offset_x``, ``offset_y``. :func:`find_heightmap`
picks the newest by ``time`` of a ``type`` (``static``, ``heightmap``, ``texture`` or ``dynamic``, the original's)
whose ``DataType`` is ``heightmap`` (``texture`` for that type), with ``id`` when not 0 and ``filename`` when not
empty; :func:`image_of` turns the PNG into the fields of a
``sensor_msgs/Image``: ``bgr8`` as the original's reader (``cv2.imdecode(..., IMREAD_COLOR)``: a 16-bit gray PNG
keeps its high byte, 1/16 m a step) or ``mono16`` (the stored 16-bit values, 1/4096 m).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError

from tms_db.errors import RecordNotFound, ValidationError

__all__ = ["TERRAIN_TYPES", "ENCODINGS", "find_heightmap", "image_of"]

TERRAIN_TYPES = ("static", "heightmap", "texture", "dynamic")
ENCODINGS = ("bgr8", "mono16")


def find_heightmap_doc(store: Any, kind: str, ident: int = 0, filename: str = "") -> dict:
    """The newest file document matching the request, without its bytes (to see whether a newer one came).
    ValidationError for a type not in :data:`TERRAIN_TYPES`; RecordNotFound naming type, id and filename when
    nothing is stored."""
    if kind not in TERRAIN_TYPES:
        raise ValidationError(f"terrain type {kind!r}: must be one of {', '.join(TERRAIN_TYPES)}")
    # DataType as the original's save_image_to_mongodb.py writes it: a type's other blobs (the original's dynamic
    # point clouds through tms_db_writer_gridfs, its static .pcd files) are not images
    flt: dict[str, Any] = {"type": kind, "DataType": "texture" if kind == "texture" else "heightmap"}
    if ident:
        flt["id"] = int(ident)
    if filename:
        flt["filename"] = filename
    found = store.find_blobs(flt, latest_only=True)
    if not found:
        raise RecordNotFound(f"no {kind!r} terrain stored" + (f" with id {ident}" if ident else "")
                             + (f" named {filename!r}" if filename else ""))
    return found[0]


def find_heightmap(store: Any, kind: str, ident: int = 0, filename: str = "") -> tuple[dict, bytes]:
    """The newest file document matching the request and its bytes (:func:`find_heightmap_doc`'s errors)."""
    doc = find_heightmap_doc(store, kind, ident, filename)
    return doc, store.get_blob(doc["_id"])


def image_of(data: bytes, encoding: str = "bgr8", *, source: str = "heightmap") -> dict:
    """``sensor_msgs/Image`` fields (height, width, encoding, is_bigendian, step, data) of PNG bytes."""
    if encoding not in ENCODINGS:
        raise ValidationError(f"image encoding {encoding!r}: must be one of {', '.join(ENCODINGS)}")
    try:
        img = Image.open(io.BytesIO(data))
        img.load()
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise ValidationError(f"{source}: the stored file is not a PNG image ({exc})") from None
    if img.mode in ("I;16", "I;16B", "I"):
        units = np.asarray(img).astype(np.uint16)
    elif img.mode in ("L", "RGB", "RGBA", "P"):
        rgb = np.asarray(img.convert("RGB"))
        if encoding == "mono16":
            raise ValidationError(f"{source}: an 8-bit {img.mode} image has no mono16 form")
        return _fields(rgb[:, :, ::-1], "bgr8")
    else:
        raise ValidationError(f"{source}: image mode {img.mode} is not a heightmap or texture")
    if encoding == "mono16":
        return _fields(units, "mono16")
    hi = (units >> 8).astype(np.uint8)
    return _fields(np.repeat(hi[:, :, None], 3, axis=2), "bgr8")


def _fields(pixels: np.ndarray, encoding: str) -> dict:
    rows, cols = pixels.shape[:2]
    pixels = np.ascontiguousarray(pixels.astype("<u2") if encoding == "mono16" else pixels)
    return {"height": int(rows), "width": int(cols), "encoding": encoding, "is_bigendian": 0,
            "step": int(pixels.strides[0]), "data": pixels.tobytes()}
