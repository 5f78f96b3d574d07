"""Synthetic LiDAR-like samples of the mound and the vessel load, for tests, benchmarks and demos.

A real sensor (or the plant's simulated one) gives surface points with noise and a few outliers;
these generators do the same from analytic surfaces so the processors can be checked against a
known truth. The random generator is passed in, so every sample is reproducible.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["truncated_cone", "scan", "vessel_heap", "dig_pit"]

Surface = Callable[[np.ndarray, np.ndarray], np.ndarray]


def truncated_cone(
    cx: float, cy: float, base_radius: float, top_radius: float, height: float, ground_z: float = 0.0
) -> Surface:
    """Height function of a truncated-cone mound on flat ground."""

    def z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        r = np.hypot(x - cx, y - cy)
        frac = np.clip((base_radius - r) / (base_radius - top_radius), 0.0, 1.0)
        return ground_z + height * frac

    return z


def dig_pit(surface: Surface, px: float, py: float, radius: float, depth: float, floor: float = 0.0) -> Surface:
    """``surface`` with a round pit of ``radius`` lowered by ``depth`` (not below ``floor``)."""

    def z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        base = surface(x, y)
        inside = np.hypot(x - px, y - py) <= radius
        return np.where(inside, np.maximum(base - depth, floor), base)

    return z


def vessel_heap(
    volume: float, length: float, width: float, cx: float = 0.0, cy: float = 0.0, spread: float = 0.8
) -> Surface:
    """A Gaussian heap of ``volume`` m^3 centred at ``(cx, cy)`` in the vessel frame (0 = floor)."""
    sigma = spread

    def z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        g = np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * sigma * sigma))
        inside = (np.abs(x) <= length / 2) & (np.abs(y) <= width / 2)
        # Normalise over the vessel area on a fine grid so the heap holds `volume` exactly.
        xs = np.linspace(-length / 2, length / 2, 181)
        ys = np.linspace(-width / 2, width / 2, 91)
        gx, gy = np.meshgrid(xs, ys)
        total = np.exp(-((gx - cx) ** 2 + (gy - cy) ** 2) / (2 * sigma * sigma)).mean() * length * width
        return np.where(inside, volume * g / total if total > 0 else 0.0, 0.0)

    return z


def scan(
    surface: Surface,
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    n: int,
    rng: np.random.Generator,
    *,
    noise: float = 0.03,
    outliers: float = 0.01,
    outlier_height: float = 2.0,
) -> np.ndarray:
    """``n`` points ``(N, 3)`` uniformly over the box with Gaussian z noise and a fraction of outliers."""
    x = rng.uniform(*x_range, n)
    y = rng.uniform(*y_range, n)
    z = surface(x, y) + rng.normal(0.0, noise, n)
    k = int(round(outliers * n))
    if k:
        idx = rng.choice(n, k, replace=False)
        z[idx] += rng.uniform(-outlier_height, outlier_height, k)
    return np.column_stack([x, y, z])
