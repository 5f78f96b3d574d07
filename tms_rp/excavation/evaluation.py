"""A design run judged afterwards: the plant's true height field and the sensed one against the design.

No rclpy, no store: :func:`truth_grid` reads the plant's ``heights_npz`` (``sim_bridge`` ``sim_plant``: the coarse
grid and, when there is one, its fine patch; rows from the south), :func:`figures` gives the
:func:`~tms_rp.excavation.design.surface_error` figures of one grid as plain numbers (cm) for a report, and
:func:`plot_errors` draws the per-cell error maps side by side into a PNG. The bench that runs the design scenario
(``tests/bench/bench_design_trench.py``) reads the sensed heightmap from the store and glues these together.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tms_rp.excavation.design import Design, DesignError, Grid, GridLike, surface_error

__all__ = ["truth_grid", "figures", "excavated_volume", "plot_errors"]


def _number(data: Any, key: str, source: str) -> float:
    try:
        return float(data[key])
    except (KeyError, TypeError, ValueError):
        raise DesignError(f"{source}: no number {key!r} (a sim_plant heights_npz has h, x0, y0, res)") from None


def truth_grid(path: str | Path, design: Design | None = None) -> Grid:
    """The plant's true heights from ``path`` as a :class:`Grid` (heightmaps' order: row 0 north). The fine patch
    when there is one and it covers ``design``'s area (or when no design is given), else the coarse grid.
    DesignError naming the file when it is missing or lacks a field."""
    p = Path(path)
    if not p.is_file():
        raise DesignError(f"{p}: no such height field (the plant writes it at its end with heights_npz set)")
    with np.load(p) as data:
        grids = []
        if "fine_h" in data:
            grids.append((np.asarray(data["fine_h"], float), _number(data, "fine_x0", str(p)),
                          _number(data, "fine_y0", str(p)), _number(data, "fine_res", str(p))))
        if "h" not in data:
            raise DesignError(f"{p}: no array 'h' (a sim_plant heights_npz)")
        grids.append((np.asarray(data["h"], float), _number(data, "x0", str(p)), _number(data, "y0", str(p)),
                      _number(data, "res", str(p))))
    for h, x0, y0, res in grids:
        grid = Grid(z=np.flipud(h).copy(), x_min=x0, y_min=y0, x_max=x0 + h.shape[1] * res, y_max=y0 + h.shape[0] * res)
        if design is None or _covers(grid, design):
            return grid
    return grid  # the coarse grid, which covers the site (surface_error names what is outside)


def _covers(grid: GridLike, design: Design) -> bool:
    xs = [q[0] for q in design.area]
    ys = [q[1] for q in design.area]
    return min(xs) >= grid.x_min and max(xs) <= grid.x_max and min(ys) >= grid.y_min and max(ys) <= grid.y_max


def figures(design: Design, grid: GridLike) -> dict[str, float | int]:
    """Surface-error figures of ``grid`` against ``design`` over its area: MAE, p95, max, signed mean [cm], the cut and
    fill volume still to do [m^3], the cells judged and the cell size [m]."""
    err = surface_error(design, grid)
    rows, cols = np.asarray(grid.z).shape
    return {"mae_cm": err.mae * 100, "p95_cm": err.p95 * 100, "max_cm": err.max_abs * 100,
            "signed_mean_cm": err.signed_mean * 100, "cut_remaining_m3": err.cut_volume,
            "fill_remaining_m3": err.fill_volume, "cells": err.cells, "cell_m": (grid.x_max - grid.x_min) / cols}


def excavated_volume(grid: GridLike, design: Design, ground_z: float) -> float:
    """[m^3] below ``ground_z`` over the design's area on ``grid``: what was dug out of it (the area was flat at
    ``ground_z`` before)."""
    s = design.sample(grid)
    z = np.asarray(grid.z, float)
    return float(np.clip(ground_z - z[s.inside], 0.0, None).sum() * s.cell_area)


def plot_errors(design: Design, grids: dict[str, GridLike], path: str | Path, *, title: str = "") -> Path:
    """One panel per grid (label -> grid): its error (grid - design, cm; + = material above) over the design's area,
    NaN outside; one diverging colour scale for all. Written as a PNG to ``path``."""
    import matplotlib  # plotting only when asked, with a headless backend chosen first

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = {label: (surface_error(design, g), g) for label, g in grids.items()}
    lim = max(5.0, max(float(np.nanmax(np.abs(e.error))) * 100 for e, _ in maps.values()))
    lim = min(lim, 30.0)
    xs = [q[0] for q in design.area]
    ys = [q[1] for q in design.area]
    fig, axes = plt.subplots(1, len(maps), figsize=(3.2 * len(maps) + 1.2, 7.5), squeeze=False)
    image = None
    for ax, (label, (err, g)) in zip(axes[0], maps.items(), strict=True):
        image = ax.imshow(err.error * 100, cmap="RdBu_r", vmin=-lim, vmax=lim,
                          extent=(g.x_min, g.x_max, g.y_min, g.y_max), origin="upper", interpolation="nearest")
        ax.set_xlim(min(xs), max(xs))
        ax.set_ylim(min(ys), max(ys))
        ax.set_aspect("equal")
        ax.set_xlabel("x [m, map]")
        ax.set_title(f"{label}\nMAE {err.mae * 100:.1f} cm, p95 {err.p95 * 100:.1f} cm\n"
                     f"max {err.max_abs * 100:.1f} cm, mean {err.signed_mean * 100:+.1f} cm", fontsize=9)
    axes[0][0].set_ylabel("y [m, map]")
    fig.colorbar(image, ax=axes[0].tolist(), label="surface - design [cm] (+ = soil left above)", shrink=0.8)
    if title:
        fig.suptitle(title, fontsize=10)
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
