"""Height grids from LiDAR-like point clouds.

A :class:`HeightGrid` is a regular 2.5-D surface (one height per cell) over an axis-aligned box.
:func:`rasterize` bins points into cells with the per-cell median (robust to noise and sparse
outliers), fills cells no point hit from their nearest measured neighbour, and removes isolated
spikes with a 3x3 median filter. Everything downstream (mound volume, excavation target, vessel
load) works on the grid, never on raw points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.stats import binned_statistic_2d

from tms_sp.errors import SensingError

__all__ = ["GridSpec", "HeightGrid", "rasterize"]


@dataclass(frozen=True)
class GridSpec:
    """An axis-aligned box ``[x_min, x_max] x [y_min, y_max]`` cut into square cells of ``resolution``."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    resolution: float

    def __post_init__(self) -> None:
        if not self.resolution > 0:
            raise ValueError(f"GridSpec: resolution must be > 0, got {self.resolution}")
        if not (self.x_max > self.x_min and self.y_max > self.y_min):
            raise ValueError(
                f"GridSpec: empty box x [{self.x_min}, {self.x_max}] y [{self.y_min}, {self.y_max}]"
            )

    @property
    def nx(self) -> int:
        return max(1, int(round((self.x_max - self.x_min) / self.resolution)))

    @property
    def ny(self) -> int:
        return max(1, int(round((self.y_max - self.y_min) / self.resolution)))

    @property
    def cell_area(self) -> float:
        return self.resolution * self.resolution

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates as two ``(ny, nx)`` arrays ``(X, Y)``."""
        xs = self.x_min + (np.arange(self.nx) + 0.5) * self.resolution
        ys = self.y_min + (np.arange(self.ny) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)

    def index_of(self, x: float, y: float) -> tuple[int, int]:
        """``(row, col)`` of the cell holding ``(x, y)``, clipped to the grid."""
        col = int(np.clip((x - self.x_min) / self.resolution, 0, self.nx - 1))
        row = int(np.clip((y - self.y_min) / self.resolution, 0, self.ny - 1))
        return row, col


@dataclass(frozen=True)
class HeightGrid:
    """Surface heights ``z[row, col]`` (row = y index, col = x index) over ``spec``; no NaN after rasterize."""

    spec: GridSpec
    z: np.ndarray
    coverage: float  # fraction of cells that held at least one point (the rest were filled)

    def height_at(self, x: float, y: float) -> float:
        row, col = self.spec.index_of(x, y)
        return float(self.z[row, col])


def rasterize(points: np.ndarray, spec: GridSpec, *, sensor: str = "points", min_coverage: float = 0.2) -> HeightGrid:
    """Build a :class:`HeightGrid` from points ``(N, 3)`` in the grid's frame.

    Points outside the box are ignored. Raises :class:`SensingError` naming ``sensor`` when fewer than
    ``min_coverage`` of the cells are hit (the sensor does not see the region).
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise SensingError(f"{sensor}: expected points of shape (N, 3), got {pts.shape}")
    finite = np.all(np.isfinite(pts[:, :3]), axis=1)
    pts = pts[finite]
    inside = (
        (pts[:, 0] >= spec.x_min) & (pts[:, 0] < spec.x_max) & (pts[:, 1] >= spec.y_min) & (pts[:, 1] < spec.y_max)
    )
    pts = pts[inside]
    if len(pts) == 0:
        raise SensingError(
            f"{sensor}: no point inside x [{spec.x_min:.2f}, {spec.x_max:.2f}] y [{spec.y_min:.2f}, {spec.y_max:.2f}]"
        )
    x_edges = spec.x_min + np.arange(spec.nx + 1) * spec.resolution
    y_edges = spec.y_min + np.arange(spec.ny + 1) * spec.resolution
    stat = binned_statistic_2d(pts[:, 1], pts[:, 0], pts[:, 2], statistic="median", bins=[y_edges, x_edges])
    z = np.asarray(stat.statistic, dtype=float)
    measured = np.isfinite(z)
    coverage = float(measured.mean())
    if coverage < min_coverage:
        raise SensingError(
            f"{sensor}: only {coverage:.0%} of {z.size} cells measured ({len(pts)} points), need {min_coverage:.0%}"
        )
    if not measured.all():
        # Nearest measured neighbour for every empty cell.
        _, (ri, ci) = ndimage.distance_transform_edt(~measured, return_indices=True)
        z = z[ri, ci]
    z = ndimage.median_filter(z, size=3, mode="nearest")
    return HeightGrid(spec=spec, z=z, coverage=coverage)
