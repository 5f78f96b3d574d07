"""Terrain of the site as the original ROS2-TMS for Construction keeps it: a heightmap image in GridFS.

The original converts a survey point cloud (LAS) into a **16-bit grayscale PNG** with its ``las2heightmap``
(``tms_ss_terrain_static/las_to_heightmap``) and stores it in GridFS with ``save_image_to_mongodb.py``. Its
encoding, which this module reproduces:

* image column = x, growing east from the cloud's ``x_min``; image row 0 = the cloud's ``y_max`` (north up);
* pixel value = ``(z - z_min) * 4096`` (``HEIGHT_SCALE``: 1/4096 m per unit, so a relief of at most
  65535 / 4096 = 16.0 m); below ``z_min`` is clipped to 0. We round to the nearest unit (the original truncates),
  so a round trip is within half a unit (0.12 mm); a relief over 16 m is refused (the original's cast wraps);
* the file document's fields: ``time``, ``type``, ``id``, ``height`` (= x extent ``x_max - x_min`` [m], the
  original's naming), ``width`` (= y extent [m]), ``elevation`` (= ``z_max - z_min`` [m]), ``offset_x``,
  ``offset_y`` (the original writes 0; ours: the map position of the image's west / south edge), ``DataType``
  ``"heightmap"``; ours adds ``offset_z`` (= ``z_min``, the height pixel 0 stands for), which the original's
  heightmap client packs as 0.

Cells: ``cell`` [m] square (the original: the image size, 2048 x 2048, fixes the cell). A cell's height is the
median of its points; a cell no point hit is interpolated linearly between the measured cells around it (outside
their hull: the nearest measured cell), then a 3 x 3 median filter removes isolated spikes. las2heightmap instead
gives every pixel the median of the points in the 7 x 7 pixels around it, 0 when there is none: a smoothing whose
width is set by the pixel size. Interpolation keeps a slope a slope where a scan is sparser than the cells (the
plant scans one point per 0.2 m; sensing's nearest fill, :func:`tms_sp.heightgrid.rasterize`, makes 6 cm steps
on the mound's slopes at 0.1 m cells).

From a heightmap: the DEM as ``nav_msgs/OccupancyGrid`` data the original's ``DemSrv`` returns (cells linearly
scaled to -128..127 between the lowest and highest cell, its ``cv2.normalize(dem, -128, 127, NORM_MINMAX)``;
row 0 = south, origin = the grid's south-west corner) and the surface as a ``tms_msg_db/ColoredMesh`` (two
triangles per cell quad, vertex colours by height, normals from the height gradient: the original meshes its
point cloud with Poisson reconstruction in open3d, not installed here), and the points of ``TerrainStaticSrv``
(x, y, z, r, g, b FLOAT32 per cell centre, as the original's ``create_pointcloud2``). No rclpy here: the nodes
fill messages from these arrays.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import laspy
import numpy as np
from PIL import Image, UnidentifiedImageError
from scipy import ndimage
from scipy.interpolate import griddata
from scipy.stats import binned_statistic_2d

from tms_db import StoreError, find_heightmap, find_heightmap_doc
from tms_sp.errors import SensingError
from tms_sp.heightgrid import GridSpec

__all__ = [
    "HEIGHT_SCALE", "MAX_RELIEF", "STATIC_ID", "DYNAMIC_ID", "TerrainError", "Heightmap", "heightmap_from_points",
    "read_las", "encode_png", "decode_png", "heightmap_from_png", "heightmap_from_file", "file_fields",
    "heightmap_from_blob", "store_heightmap", "latest_heightmap", "latest_heightmap_doc", "dem", "colored_mesh",
    "cloud_xyzrgb", "image_8bit", "MeshArrays", "DynamicTerrain", "now_text", "region_box",
]

HEIGHT_SCALE = 4096.0  # pixel units per metre above z_min (las2heightmap: ``iz = z * 4096``)
MAX_RELIEF = 65535.0 / HEIGHT_SCALE  # [m] the largest height above z_min a 16-bit pixel holds
STATIC_ID = 3030  # the original's DATA_ID of static terrain (tms_ss_terrain_static)
DYNAMIC_ID = 3031  # the original's DATA_ID of dynamic terrain (tms_sd_terrain_dynamic)


class TerrainError(SensingError):
    """A terrain input or stored heightmap cannot be used; the message names the file, field or request."""


@dataclass(frozen=True)
class Heightmap:
    """Heights ``z[row, col]`` [m, map frame] in image order: row 0 is the north edge (``y_max``), col 0 the west
    edge (``x_min``); the cells cover ``[x_min, x_max] x [y_min, y_max]``. ``z_min`` is the height of pixel 0."""

    z: np.ndarray
    x_min: float
    y_min: float
    x_max: float
    y_max: float
    z_min: float

    @property
    def rows(self) -> int:
        return int(self.z.shape[0])

    @property
    def cols(self) -> int:
        return int(self.z.shape[1])

    @property
    def cell_x(self) -> float:
        return (self.x_max - self.x_min) / self.cols

    @property
    def cell_y(self) -> float:
        return (self.y_max - self.y_min) / self.rows

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre map coordinates ``(X, Y)``, each ``(rows, cols)``, in image order."""
        xs = self.x_min + (np.arange(self.cols) + 0.5) * self.cell_x
        ys = self.y_max - (np.arange(self.rows) + 0.5) * self.cell_y
        return np.meshgrid(xs, ys)

    def height_at(self, x: float, y: float) -> float:
        col = int(np.clip((x - self.x_min) / self.cell_x, 0, self.cols - 1))
        row = int(np.clip((self.y_max - y) / self.cell_y, 0, self.rows - 1))
        return float(self.z[row, col])


# ---- point clouds -> heightmap ------------------------------------------------------------------------------------
def read_las(path: str | Path) -> np.ndarray:
    """``(N, 3)`` x, y, z [m] (scaled and offset as the header says) of a LAS or LAZ file; TerrainError naming the
    file when it does not exist, is not LAS, or holds no point."""
    p = Path(path)
    if not p.is_file():
        raise TerrainError(f"{p}: no such LAS/LAZ file")
    try:
        las = laspy.read(str(p))
    except (laspy.errors.LaspyException, OSError, ValueError) as exc:
        raise TerrainError(f"{p}: not a readable LAS/LAZ file ({exc})") from None
    pts = np.column_stack([np.asarray(las.x, float), np.asarray(las.y, float), np.asarray(las.z, float)])
    if len(pts) == 0:
        raise TerrainError(f"{p}: the LAS file holds no point")
    return pts


def heightmap_from_points(points: np.ndarray, *, cell: float, box: GridSpec | None = None, z_min: float | None = None,
                          source: str = "points", min_coverage: float = 0.05) -> Heightmap:
    """Rasterise ``(N, 3)`` points into cells of ``cell`` [m] over ``box`` (default: the points' extent, grown to
    whole cells); ``z_min`` (default: the lowest point, as the original) is the height of pixel 0. TerrainError
    naming ``source`` for no point, a bad shape or too few cells hit."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise TerrainError(f"{source}: expected points of shape (N, 3), got {pts.shape}")
    pts = pts[np.all(np.isfinite(pts[:, :3]), axis=1)]
    if len(pts) == 0:
        raise TerrainError(f"{source}: empty point cloud (no finite point)")
    if not cell > 0:
        raise TerrainError(f"{source}: cell size must be > 0, got {cell}")
    if box is None:
        x0, y0 = float(pts[:, 0].min()), float(pts[:, 1].min())
        nx = max(1, math.floor((float(pts[:, 0].max()) - x0) / cell) + 1)
        ny = max(1, math.floor((float(pts[:, 1].max()) - y0) / cell) + 1)
        box = GridSpec(x0, y0, x0 + nx * cell, y0 + ny * cell, cell)
    else:
        box = GridSpec(box.x_min, box.y_min, box.x_max, box.y_max, cell)
    z = _rasterize(pts, box, source, min_coverage)
    base = float(pts[:, 2].min()) if z_min is None else float(z_min)
    return Heightmap(z=np.flipud(z).copy(), x_min=box.x_min, y_min=box.y_min,
                     x_max=box.x_min + box.nx * box.resolution, y_max=box.y_min + box.ny * box.resolution,
                     z_min=base)


def _rasterize(pts: np.ndarray, box: GridSpec, source: str, min_coverage: float) -> np.ndarray:
    """``z[row, col]`` (row 0 = south): cell medians, empty cells linearly interpolated between the measured cells'
    centres (nearest outside their hull), then a 3 x 3 median filter against isolated spikes."""
    inside = ((pts[:, 0] >= box.x_min) & (pts[:, 0] < box.x_max) & (pts[:, 1] >= box.y_min)
              & (pts[:, 1] < box.y_max))
    pts = pts[inside]
    if len(pts) == 0:
        raise TerrainError(f"{source}: no point inside x [{box.x_min:.2f}, {box.x_max:.2f}] "
                           f"y [{box.y_min:.2f}, {box.y_max:.2f}]")
    x_edges = box.x_min + np.arange(box.nx + 1) * box.resolution
    y_edges = box.y_min + np.arange(box.ny + 1) * box.resolution
    z = np.asarray(binned_statistic_2d(pts[:, 1], pts[:, 0], pts[:, 2], statistic="median",
                                       bins=[y_edges, x_edges]).statistic, dtype=float)
    measured = np.isfinite(z)
    coverage = float(measured.mean())
    if coverage < min_coverage:
        raise TerrainError(f"{source}: only {coverage:.0%} of {z.size} cells measured ({len(pts)} points), "
                           f"need {min_coverage:.0%}")
    if not measured.all():
        xc, yc = box.centres()
        known = np.column_stack([xc[measured], yc[measured]])
        holes = np.column_stack([xc[~measured], yc[~measured]])
        filled = (griddata(known, z[measured], holes, method="linear") if measured.sum() >= 3
                  else np.full(len(holes), np.nan))
        gaps = ~np.isfinite(filled)
        if gaps.any():  # outside the measured cells' hull (or too few for triangles): the nearest
            filled[gaps] = griddata(known, z[measured], holes[gaps], method="nearest")
        z[~measured] = filled
    return ndimage.median_filter(z, size=3, mode="nearest")


# ---- heightmap <-> 16-bit PNG -------------------------------------------------------------------------------------
def encode_png(hm: Heightmap, *, source: str = "heightmap") -> bytes:
    """The heightmap as the original's 16-bit grayscale PNG (``(z - z_min) * 4096``, rounded, below 0 -> 0).
    TerrainError naming ``source`` when the relief exceeds :data:`MAX_RELIEF`."""
    rel = np.asarray(hm.z, dtype=float) - hm.z_min
    top = float(np.nanmax(rel)) if rel.size else 0.0
    if top > MAX_RELIEF:
        raise TerrainError(f"{source}: relief {top:.3f} m above z_min {hm.z_min:.3f} exceeds the 16-bit heightmap's "
                           f"{MAX_RELIEF:.3f} m")
    units = np.clip(np.rint(np.nan_to_num(rel, nan=0.0) * HEIGHT_SCALE), 0, 65535).astype(np.uint16)
    buf = io.BytesIO()
    Image.fromarray(units).save(buf, format="PNG")
    return buf.getvalue()


def decode_png(data: bytes, *, source: str = "image") -> np.ndarray:
    """Pixel units ``(rows, cols)`` of a 16-bit grayscale PNG; TerrainError naming ``source`` for anything else
    (not an image, 8-bit, colour)."""
    try:
        img = Image.open(io.BytesIO(data))
        img.load()
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise TerrainError(f"{source}: not a PNG heightmap ({exc})") from None
    if img.mode not in ("I;16", "I;16B", "I"):
        raise TerrainError(f"{source}: heightmap must be a 16-bit grayscale PNG, got mode {img.mode}")
    units = np.asarray(img)
    if units.ndim != 2 or units.size == 0:
        raise TerrainError(f"{source}: empty or not 2-D image {units.shape}")
    return units.astype(np.int64)


def heightmap_from_png(data: bytes, *, x_min: float, y_min: float, size_x: float, size_y: float, z_min: float,
                       source: str = "image") -> Heightmap:
    """A 16-bit heightmap PNG placed on the map: west edge ``x_min``, south edge ``y_min``, extents ``size_x`` /
    ``size_y`` [m], pixel 0 at ``z_min``."""
    if not (size_x > 0 and size_y > 0):
        raise TerrainError(f"{source}: extents must be > 0, got {size_x} x {size_y}")
    units = decode_png(data, source=source)
    return Heightmap(z=units / HEIGHT_SCALE + z_min, x_min=x_min, y_min=y_min, x_max=x_min + size_x,
                     y_max=y_min + size_y, z_min=z_min)


def heightmap_from_file(path: str | Path, *, cell: float, x_min: float = 0.0, y_min: float = 0.0,
                        size_x: float = 0.0, size_y: float = 0.0, z_min: float | None = None) -> Heightmap:
    """A LAS/LAZ survey (by suffix ``.las`` / ``.laz``; rasterised at ``cell``; ``z_min`` None = its lowest point) or
    a 16-bit PNG heightmap (placed by the other arguments; ``size_x`` / ``size_y`` 0 = ``cell`` per pixel; ``z_min``
    None = 0)."""
    p = Path(path)
    if p.suffix.lower() in (".las", ".laz"):
        return heightmap_from_points(read_las(p), cell=cell, z_min=z_min, source=str(p))
    if not p.is_file():
        raise TerrainError(f"{p}: no such heightmap file")
    data = p.read_bytes()
    units = decode_png(data, source=str(p))
    rows, cols = units.shape
    return heightmap_from_png(data, x_min=x_min, y_min=y_min, size_x=size_x or cols * cell,
                              size_y=size_y or rows * cell, z_min=0.0 if z_min is None else z_min, source=str(p))


# ---- the GridFS file document -------------------------------------------------------------------------------------
def file_fields(hm: Heightmap, *, kind: str, ident: int, time: str) -> dict:
    """The fields the original's ``save_image_to_mongodb.py`` gives the file document (see the module docstring)."""
    return {"time": time, "type": kind, "id": int(ident), "height": float(hm.x_max - hm.x_min),
            "width": float(hm.y_max - hm.y_min), "elevation": float(np.max(hm.z) - hm.z_min),
            "offset_x": float(hm.x_min), "offset_y": float(hm.y_min), "offset_z": float(hm.z_min),
            "DataType": "heightmap"}


def heightmap_from_blob(data: bytes, doc: dict, *, source: str = "blob") -> Heightmap:
    """A stored heightmap back from its bytes and file document (``height``, ``width``, ``offset_x/y/z``)."""
    try:
        size_x, size_y = float(doc["height"]), float(doc["width"])
        x0, y0 = float(doc.get("offset_x", 0.0)), float(doc.get("offset_y", 0.0))
        z0 = float(doc.get("offset_z", 0.0))
    except (KeyError, TypeError, ValueError) as exc:
        raise TerrainError(f"{source}: file document lacks a heightmap field ({exc!r})") from None
    return heightmap_from_png(data, x_min=x0, y_min=y0, size_x=size_x, size_y=size_y, z_min=z0, source=source)


def store_heightmap(store: Any, hm: Heightmap, *, kind: str, ident: int, filename: str, time: str,
                    keep: int | None = None) -> str:
    """Put the heightmap's PNG into the store's GridFS with :func:`file_fields`; then, with ``keep``, delete the
    oldest heightmaps of the same ``type`` and ``id`` beyond the newest ``keep``. Returns the file id."""
    if not filename:
        raise TerrainError(f"{kind} terrain: empty filename")
    file_id = store.put_blob(encode_png(hm, source=filename), filename=filename,
                             **file_fields(hm, kind=kind, ident=ident, time=time))
    if keep is not None:
        if keep < 1:
            raise TerrainError(f"{kind} terrain: keep must be >= 1, got {keep}")
        # only heightmaps: the original's dynamic point clouds (tms_db_writer_gridfs) share type and id
        docs = store.find_blobs({"type": kind, "id": int(ident), "DataType": "heightmap"})
        for doc in docs[:-keep]:
            store.delete_blob(doc["_id"])
    return file_id


def latest_heightmap_doc(store: Any, kind: str, *, ident: int = 0, filename: str = "") -> dict:
    """:func:`latest_heightmap`'s document alone, without reading its bytes; TerrainError as there."""
    try:
        return find_heightmap_doc(store, kind, ident, filename)
    except StoreError as exc:
        raise TerrainError(str(exc)) from None


def latest_heightmap(store: Any, kind: str, *, ident: int = 0, filename: str = "") -> tuple[dict, bytes]:
    """The newest (by ``time``) stored heightmap of ``type`` ``kind`` (and ``id`` when not 0, ``filename`` when not
    empty) and its bytes, as tms_db's heightmap reader picks it; TerrainError naming the request when nothing
    matches."""
    try:
        return find_heightmap(store, kind, ident, filename)
    except StoreError as exc:
        raise TerrainError(str(exc)) from None


def image_8bit(units: np.ndarray) -> np.ndarray:
    """What the original's reader sends: its ``cv2.imdecode(..., IMREAD_COLOR)`` of the 16-bit PNG keeps the high
    byte (``unit >> 8``, 1/16 m) in each of B, G, R; ``(rows, cols, 3)`` uint8."""
    hi = (np.asarray(units, dtype=np.int64) >> 8).astype(np.uint8)
    return np.repeat(hi[:, :, None], 3, axis=2)


# ---- DEM, mesh and points ---------------------------------------------------------------------------------------
def dem(hm: Heightmap) -> tuple[list[int], int, int, float, tuple[float, float]]:
    """``(data, width, height, resolution, origin_xy)`` of the OccupancyGrid: int8 cells, row 0 = south."""
    z = np.flipud(np.asarray(hm.z, dtype=float))
    lo, hi = float(z.min()), float(z.max())
    scaled = np.zeros_like(z) if hi - lo <= 0 else (z - lo) / (hi - lo)
    cells = np.rint(scaled * 255.0 - 128.0).astype(np.int64)
    return cells.ravel().tolist(), hm.cols, hm.rows, float(hm.cell_x), (float(hm.x_min), float(hm.y_min))


@dataclass(frozen=True)
class MeshArrays:
    """``triangles (T, 3)`` vertex indices (counter-clockwise seen from above), ``vertices (V, 3)``,
    ``colors (V, 3)`` in [0, 1], ``normals (V, 3)`` unit."""

    triangles: np.ndarray
    vertices: np.ndarray
    colors: np.ndarray
    normals: np.ndarray


def _height_colors(z: np.ndarray) -> np.ndarray:
    # earth tones from dark (low) to light (high): only relative height is shown
    lo, hi = float(z.min()), float(z.max())
    t = np.zeros_like(z) if hi - lo <= 0 else (z - lo) / (hi - lo)
    low, high = np.array([0.35, 0.25, 0.15]), np.array([0.85, 0.75, 0.55])
    return low + t[..., None] * (high - low)


def colored_mesh(hm: Heightmap, *, max_vertices: int = 40000) -> MeshArrays:
    """The surface through the cell centres, every ``stride``-th cell so at most ``max_vertices`` vertices."""
    stride = max(1, math.ceil(math.sqrt(hm.rows * hm.cols / max(1, max_vertices))))
    xc, yc = hm.centres()
    xc, yc, zc = xc[::stride, ::stride], yc[::stride, ::stride], np.asarray(hm.z, float)[::stride, ::stride]
    r, c = zc.shape
    vertices = np.column_stack([xc.ravel(), yc.ravel(), zc.ravel()])
    idx = np.arange(r * c).reshape(r, c)
    if r > 1 and c > 1:
        a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()  # north row: west, east
        d, e = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()  # south row: west, east
        # rows run north -> south, so (south-west, south-east, north-east) is counter-clockwise seen from above
        triangles = np.concatenate([np.column_stack([d, e, b]), np.column_stack([d, b, a])]).astype(np.uint32)
    else:
        triangles = np.zeros((0, 3), dtype=np.uint32)
    dx = hm.cell_x * stride
    dy = hm.cell_y * stride
    gz_row, gz_col = np.gradient(zc, dy, dx) if r > 1 and c > 1 else (np.zeros_like(zc), np.zeros_like(zc))
    # row index grows southward: dz/dy = -dz/drow
    n = np.stack([-gz_col, gz_row, np.ones_like(zc)], axis=-1).reshape(-1, 3)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return MeshArrays(triangles=triangles, vertices=vertices, colors=_height_colors(zc).reshape(-1, 3), normals=n)


def cloud_xyzrgb(hm: Heightmap) -> tuple[bytes, int]:
    """``(data, n)``: the cell centres as x, y, z, r, g, b little-endian FLOAT32 (24 bytes a point), the layout of
    the original's ``create_pointcloud2`` (colours 0..1)."""
    xc, yc = hm.centres()
    zc = np.asarray(hm.z, float)
    rgb = _height_colors(zc).reshape(-1, 3)
    arr = np.column_stack([xc.ravel(), yc.ravel(), zc.ravel(), rgb]).astype("<f4")
    return arr.tobytes(), int(arr.shape[0])


# ---- the dynamic terrain from sensing scans ----------------------------------------------------------------------
def now_text() -> str:
    """The original's ``time`` field: local wall time, ISO 8601 with microseconds (sorts as it reads)."""
    return datetime.now().isoformat(timespec="microseconds")


def region_box(values: Any, cell: float, *, source: str = "box") -> GridSpec | None:
    """``[x_min, y_min, x_max, y_max]`` [m, map] as the box a dynamic terrain rasterises at ``cell``; all zero: None
    (the caller's default region). TerrainError naming ``source`` for a wrong length, a non-finite value, an empty
    box or sides that are not whole cells (a box that does not tile would shift its cells off the scan's)."""
    try:
        box = [float(v) for v in values]
    except (TypeError, ValueError):
        raise TerrainError(f"{source}: expected [x_min, y_min, x_max, y_max] numbers, got {values!r}") from None
    if len(box) != 4:
        raise TerrainError(f"{source}: expected [x_min, y_min, x_max, y_max], got {len(box)} value(s) {box}")
    if not any(box):
        return None
    if not all(math.isfinite(v) for v in box):
        raise TerrainError(f"{source}: non-finite value in {box}")
    x0, y0, x1, y1 = box
    if not (x1 > x0 and y1 > y0):
        raise TerrainError(f"{source}: empty box x [{x0:g}, {x1:g}] y [{y0:g}, {y1:g}]")
    if not cell > 0:
        raise TerrainError(f"{source}: cell must be > 0, got {cell}")
    for axis, size in (("x", x1 - x0), ("y", y1 - y0)):
        n = size / cell
        if abs(n - round(n)) > 1e-6:
            raise TerrainError(f"{source}: the {axis} side {size:g} m is not a whole number of {cell:g} m cells")
    return GridSpec(x0, y0, x1, y1, cell)


@dataclass
class DynamicTerrain:
    """Scans of the site (map-frame points) -> ``type: dynamic`` heightmaps in the store, the newest ``keep`` kept.

    ``box`` is the region rasterised at ``cell``; ``z_min`` is pixel 0 (the site's ground, so that static and
    dynamic heightmaps of one site compare pixel for pixel when the static one was made with the same ``z_min``)."""

    store: Any
    box: GridSpec
    cell: float
    z_min: float
    keep: int = 20
    filename: str = "dynamic_terrain.png"
    ident: int = DYNAMIC_ID
    written: int = 0

    def __post_init__(self) -> None:
        if self.keep < 1:
            raise TerrainError(f"dynamic terrain: keep must be >= 1, got {self.keep}")
        if not self.cell > 0:
            raise TerrainError(f"dynamic terrain: cell must be > 0, got {self.cell}")

    def on_points(self, points: np.ndarray, *, time: str | None = None, source: str = "scan") -> str:
        """Rasterise one scan and store it; the new file id. TerrainError naming ``source`` for an unusable scan
        (nothing stored then)."""
        hm = heightmap_from_points(points, cell=self.cell, box=self.box, z_min=self.z_min, source=source,
                                   min_coverage=0.2)
        file_id = store_heightmap(self.store, hm, kind="dynamic", ident=self.ident, filename=self.filename,
                                  time=time or now_text(), keep=self.keep)
        self.written += 1
        return file_id
