"""Occupancy maps (Nav2 map_server PGM + YAML) and the inflated costmap of a tracked machine.

``load_map`` reads the same YAML keys as Nav2's map_server (``image, resolution, origin, negate,
occupied_thresh, free_thresh, mode``; trinary mode) and the PGM with Pillow; row 0 of the image is the
top of the map (largest y), so rows are flipped to make ``grid[row, col]`` grow with y and x.

:class:`Costmap` follows Nav2's cost scale: 254 = obstacle, 253 = centre within the inscribed radius of
the (padded) footprint, then ``252 * exp(-cost_scaling_factor * (d - inscribed))`` out to the
circumscribed radius + ``inflation_radius``. The planner treats >= 253 as blocked; :meth:`Costmap.footprint_hits`
checks the real oriented rectangle against the raw obstacles (the circle approximation alone cannot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from tms_common.errors import ConfigError
from tms_common.schema import load_schema, setting

__all__ = ["OccupancyMap", "Costmap", "CostmapParams", "Footprint", "NavMapYaml", "load_map", "save_map", "LETHAL",
           "INSCRIBED"]

LETHAL = 254
INSCRIBED = 253
FREE, OCCUPIED, UNKNOWN = 0, 100, -1


@dataclass(frozen=True)
class Footprint:
    """Rectangle centred on base_link: ``length`` along x, ``width`` along y [m]."""

    length: float
    width: float

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.width > 0):
            raise ValueError(f"footprint must have positive length and width, got {self.length} x {self.width}")

    @property
    def inscribed_radius(self) -> float:
        return 0.5 * min(self.length, self.width)

    @property
    def circumscribed_radius(self) -> float:
        return 0.5 * math.hypot(self.length, self.width)


@dataclass(frozen=True)
class CostmapParams:
    """``costmap`` section of the nav file (tms_rp.tracked.config)."""

    footprint_padding: float = 0.3
    inflation_radius: float = 2.5
    cost_scaling_factor: float = 1.5

    def __post_init__(self) -> None:
        for name in ("footprint_padding", "inflation_radius", "cost_scaling_factor"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"costmap.{name} must be >= 0, got {value!r}")


@dataclass
class OccupancyMap:
    """A trinary occupancy grid: ``grid[row, col]`` in {0 free, 100 occupied, -1 unknown}, row 0 at ``origin`` y."""

    grid: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape  # type: ignore[return-value]

    @property
    def size_m(self) -> tuple[float, float]:
        return self.grid.shape[1] * self.resolution, self.grid.shape[0] * self.resolution

    def world_to_cell(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) containing (x, y), or None outside the map."""
        col = math.floor((x - self.origin[0]) / self.resolution)
        row = math.floor((y - self.origin[1]) / self.resolution)
        if 0 <= row < self.grid.shape[0] and 0 <= col < self.grid.shape[1]:
            return row, col
        return None

    def cell_to_world(self, row: np.ndarray | int, col: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Centres of cells."""
        return (
            self.origin[0] + (np.asarray(col) + 0.5) * self.resolution,
            self.origin[1] + (np.asarray(row) + 0.5) * self.resolution,
        )


@dataclass(frozen=True, kw_only=True)
class NavMapYaml:
    """The keys of a Nav2 map_server map YAML (its defaults); read by :func:`tms_common.schema.load_schema`, so an
    unknown or missing key, a wrong type or a value out of range is a ``file:line: key: problem`` error."""

    image: str = setting(doc="the PGM/PNG beside the YAML")
    resolution: float = setting(lo=1e-6, doc="[m] per cell")
    origin: tuple[float, float, float] = setting(doc="[x, y, yaw] of the lower-left cell; yaw must be 0")
    negate: int = setting(0, lo=0, hi=1, doc="1: white is occupied")
    occupied_thresh: float = setting(0.65, lo=0.0, hi=1.0)
    free_thresh: float = setting(0.25, lo=0.0, hi=1.0)
    mode: str = setting("trinary", doc="only trinary is supported")

    def __post_init__(self) -> None:
        if self.origin[2] != 0:
            raise ValueError(f"origin: rotated maps are not supported (origin yaw {self.origin[2]!r})")
        if self.mode != "trinary":
            raise ValueError(f"mode: only mode 'trinary' is supported, got {self.mode!r}")
        if not self.free_thresh < self.occupied_thresh:
            raise ValueError(f"free_thresh: need free_thresh < occupied_thresh, got {self.free_thresh}, "
                             f"{self.occupied_thresh}")


def load_map(yaml_path: str | Path) -> OccupancyMap:
    """Load a Nav2 map_server map; errors name the file, line and key."""
    from PIL import Image

    m = load_schema(NavMapYaml, yaml_path)
    occ_t, free_t = m.occupied_thresh, m.free_thresh
    image_path = Path(yaml_path).parent / m.image
    try:
        with Image.open(image_path) as img:
            pixels = np.asarray(img.convert("L"), dtype=np.float64)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{yaml_path}: image: cannot read map image {image_path}: {exc}") from None
    negate = bool(m.negate)
    occ_prob = pixels / 255.0 if negate else (255.0 - pixels) / 255.0
    grid = np.full(pixels.shape, UNKNOWN, dtype=np.int8)
    grid[occ_prob > occ_t] = OCCUPIED
    grid[occ_prob < free_t] = FREE
    return OccupancyMap(np.ascontiguousarray(grid[::-1]), m.resolution, (m.origin[0], m.origin[1]))


def save_map(omap: OccupancyMap, yaml_path: str | Path) -> None:
    """Write ``omap`` as PGM + YAML (Nav2 map_saver conventions: free 254, occupied 0, unknown 205, free_thresh 0.196 as
    map_saver)."""
    from PIL import Image

    yaml_path = Path(yaml_path)
    pixels = np.full(omap.grid.shape, 205, dtype=np.uint8)
    pixels[omap.grid == FREE] = 254
    pixels[omap.grid == OCCUPIED] = 0
    image = yaml_path.with_suffix(".pgm")
    Image.fromarray(pixels[::-1]).save(image)
    yaml_path.write_text(
        f"image: {image.name}\nmode: trinary\nresolution: {omap.resolution}\n"
        f"origin: [{omap.origin[0]}, {omap.origin[1]}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )


class Costmap:
    """Inflated cost grid (uint8, Nav2 scale) plus the raw obstacles and free-space components.

    Unknown cells count as free (Nav2 ``allow_unknown: true`` in the nav config).
    """

    def __init__(self, omap: OccupancyMap, footprint: Footprint, params: CostmapParams | None = None) -> None:
        self.map = omap
        self.footprint = footprint
        self.params = params or CostmapParams()
        self.resolution = omap.resolution
        self.obstacles = omap.grid == OCCUPIED
        self.inscribed = footprint.inscribed_radius + self.params.footprint_padding
        self.circumscribed = footprint.circumscribed_radius + self.params.footprint_padding
        self.cost = self._inflate()
        self._labels: np.ndarray | None = None

    def _inflate(self) -> np.ndarray:
        if self.obstacles.any():
            dist = ndimage.distance_transform_edt(~self.obstacles) * self.resolution
        else:
            dist = np.full(self.obstacles.shape, np.inf)
        cost = np.zeros(dist.shape, dtype=np.uint8)
        reach = self.circumscribed + self.params.inflation_radius
        band = (dist > self.inscribed) & (dist <= reach)
        cost[band] = np.minimum(
            252.0, 252.0 * np.exp(-self.params.cost_scaling_factor * (dist[band] - self.inscribed))
        ).astype(np.uint8)
        cost[dist <= self.inscribed] = INSCRIBED
        cost[self.obstacles] = LETHAL
        return cost

    @property
    def blocked(self) -> np.ndarray:
        """Cells the footprint centre must not enter."""
        return self.cost >= INSCRIBED

    @property
    def labels(self) -> np.ndarray:
        """Connected components (8-connected) of the free cells; 0 = blocked. Cached."""
        if self._labels is None:
            self._labels, _ = ndimage.label(~self.blocked, structure=np.ones((3, 3), dtype=bool))
        return self._labels

    def cost_at(self, x: float, y: float) -> int | None:
        """Cost of the cell at (x, y), None outside the map."""
        cell = self.map.world_to_cell(x, y)
        return None if cell is None else int(self.cost[cell])

    def footprint_points(
        self, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, *, padding: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """World points sampling the (padded) rectangle's area at the map resolution for each pose."""
        half_l = 0.5 * self.footprint.length + padding
        half_w = 0.5 * self.footprint.width + padding
        step = self.resolution
        u = np.linspace(-half_l, half_l, int(math.ceil(2 * half_l / step)) + 1)
        v = np.linspace(-half_w, half_w, int(math.ceil(2 * half_w / step)) + 1)
        uu, vv = (a.ravel() for a in np.meshgrid(u, v))
        x, y, yaw = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (x, y, yaw))
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        return x[:, None] + c * uu - s * vv, y[:, None] + s * uu + c * vv

    def footprint_hits(self, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, *, padding: float = 0.0) -> np.ndarray:
        """Per pose: True if the oriented footprint overlaps an obstacle cell (outside the map counts as a hit)."""
        px, py = self.footprint_points(x, y, yaw, padding=padding)
        cols = np.floor((px - self.map.origin[0]) / self.resolution).astype(np.int64)
        rows = np.floor((py - self.map.origin[1]) / self.resolution).astype(np.int64)
        h, w = self.obstacles.shape
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        hit = np.ones(rows.shape, dtype=bool)
        hit[inside] = self.obstacles[rows[inside], cols[inside]]
        return hit.any(axis=1)

    def with_obstacles(self, omap: OccupancyMap) -> Costmap:
        """A new costmap for an updated map with the same footprint and parameters."""
        return Costmap(omap, self.footprint, self.params)
