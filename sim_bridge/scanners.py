"""Simulated LiDAR-like scans of the soil for the sensing processors (tms_sp).

Pure functions returning ``(N, 3)`` point arrays; the plant node packs them into sensor_msgs/PointCloud2:

* :func:`mound_scan`: height samples of the ground around the mound, in ``map``, with Gaussian range
  noise, on a regular sub-grid of the height field (a stand-in for a site LiDAR scan);
* :func:`vessel_scan`: samples of the load surface inside a carrier's vessel in frame ``<carrier>/vessel``
  (origin at the vessel floor centre, x forward, y left, z up, vessel lowered; z = load height above
  the floor). The plant models the vessel load as a volume only, so the scan shows it as an even layer
  of that volume over the inner floor (documented limitation: no heap shape).
"""

from __future__ import annotations

import numpy as np

from sim_bridge.soil import HeightField

__all__ = ["mound_scan", "vessel_scan", "pack_xyz"]


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
