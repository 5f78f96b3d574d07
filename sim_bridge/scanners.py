"""Simulated LiDAR-like scans of the soil for the sensing processors (tms_sp).

Pure functions returning ``(N, 3)`` point arrays; the plant node packs them into sensor_msgs/PointCloud2:

* :func:`mound_scan`: height samples of the ground around the mound, in ``map``, with Gaussian range
  noise, on a regular sub-grid of the height field (a stand-in for a site LiDAR scan);
* :func:`region_scan`: height samples over an axis-aligned rectangle (a design's work area) at any spacing, read
  from the fine patch where there is one (``soil.grid.fine``) and from the coarse cells elsewhere, so a scan finer
  than the coarse grid resolves what the tool cut in the patch;
* :func:`vessel_scan`: samples of the load surface inside a carrier's vessel in frame ``<carrier>/vessel``
  (origin at the vessel floor centre, x forward, y left, z up, vessel lowered; z = load height above
  the floor). The plant models the vessel load as a volume only, so the scan shows it as an even layer
  of that volume over the inner floor (documented limitation: no heap shape).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from sim_bridge.soil import HeightField

__all__ = ["mound_scan", "region_scan", "ScanRegion", "vessel_scan", "pack_xyz"]


def mound_scan(
    field: HeightField, center: tuple[float, float], radius: float, *, noise: float, rng: np.random.Generator,
    spacing: float = 0.2,
) -> np.ndarray:
    """Ground points within ``radius`` of ``center`` on a ``spacing`` grid, heights with ``noise`` (1 sigma).

    The points are the coarse cells' (``field.h``): under a fine patch (``soil.grid.fine``) each is the mean of the
    patch's cells over it, so the scan carries the patch's volume.
    """
    step = max(1, int(round(spacing / field.res)))
    rows, cols = field.window(center[0], center[1], radius)
    xs = field.xs[cols][::step]
    ys = field.ys[rows][::step]
    h = field.h[rows, cols][::step, ::step]
    gx, gy = np.meshgrid(xs, ys)
    inside = np.hypot(gx - center[0], gy - center[1]) <= radius
    z = h[inside] + rng.normal(0.0, noise, size=int(inside.sum()))
    return np.column_stack([gx[inside], gy[inside], z])


class ScanRegion(NamedTuple):
    """An axis-aligned rectangle of the map scanned on a ``spacing`` grid (points at the cell centres)."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    spacing: float

    def problem(self) -> str | None:
        """What is wrong with it (an empty rectangle, a spacing that is not > 0), or None."""
        if not all(np.isfinite(v) for v in self):
            return f"non-finite value in {tuple(self)}"
        if not (self.x_max > self.x_min and self.y_max > self.y_min):
            return f"empty rectangle x [{self.x_min:g}, {self.x_max:g}] y [{self.y_min:g}, {self.y_max:g}]"
        if not self.spacing > 0:
            return f"spacing must be > 0, got {self.spacing:g}"
        return None


def region_scan(field: HeightField, region: ScanRegion, *, noise: float, rng: np.random.Generator) -> np.ndarray:
    """Ground points on the ``region.spacing`` grid over the rectangle (clipped to the height field), heights with
    ``noise`` (1 sigma): the fine patch's cell under each point inside the patch, the coarse cell elsewhere.

    Unlike :func:`mound_scan` (coarse cells, block means under the patch) this samples the patch itself, so the
    scan resolves centimetre steps the patch holds when ``spacing`` is about the patch's resolution."""
    problem = region.problem()
    if problem is not None:
        raise ValueError(f"region_scan: {problem}")
    gx0, gy0 = field.x0, field.y0
    gx1, gy1 = gx0 + field.nx * field.res, gy0 + field.ny * field.res
    s = region.spacing
    xs = np.arange(region.x_min + s / 2, region.x_max, s)
    ys = np.arange(region.y_min + s / 2, region.y_max, s)
    xs = xs[(xs >= gx0) & (xs < gx1)]
    ys = ys[(ys >= gy0) & (ys < gy1)]
    gx, gy = np.meshgrid(xs, ys)
    cols = np.clip(((gx - gx0) / field.res).astype(int), 0, field.nx - 1)
    rows = np.clip(((gy - gy0) / field.res).astype(int), 0, field.ny - 1)
    h = field.h[rows, cols]
    f = field.fine
    if f is not None:
        inside = (gx >= f.x0) & (gx < f.x1) & (gy >= f.y0) & (gy < f.y1)
        fc = np.clip(((gx[inside] - f.x0) / f.res).astype(int), 0, f.nx - 1)
        fr = np.clip(((gy[inside] - f.y0) / f.res).astype(int), 0, f.ny - 1)
        h[inside] = f.h[fr, fc]
    z = h + rng.normal(0.0, noise, size=h.shape)
    return np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])


def vessel_scan(
    volume: float, length: float, width: float, *, noise: float, rng: np.random.Generator, spacing: float = 0.1
) -> np.ndarray:
    """Load-surface points over the inner ``length`` x ``width`` floor for ``volume`` m^3 spread evenly."""
    xs = np.arange(-length / 2 + spacing / 2, length / 2, spacing)
    ys = np.arange(-width / 2 + spacing / 2, width / 2, spacing)
    gx, gy = np.meshgrid(xs, ys)
    level = max(0.0, volume) / (length * width)
    z = level + rng.normal(0.0, noise, size=gx.shape)
    return np.column_stack([gx.ravel(), gy.ravel(), np.maximum(z, 0.0).ravel()])


def pack_xyz(points: np.ndarray) -> tuple[bytes, int]:
    """Little-endian float32 x, y, z records (12 bytes each) and the point count."""
    return np.ascontiguousarray(points, dtype="<f4").tobytes(), int(points.shape[0])
