"""Judging a design run afterwards (tms_rp.excavation.evaluation): the plant's height field file read back in the
heightmaps' order (fine patch preferred where it covers the design), figures and the error plot."""

from __future__ import annotations

import numpy as np
import pytest

from tms_rp.excavation.design import Design, DesignError, Grid
from tms_rp.excavation.evaluation import excavated_volume, figures, plot_errors, truth_grid

TRENCH = {"name": "t", "kind": "trench", "start": [-5.0, -2.0], "end": [-5.0, 2.0], "width": 1.0, "depth": 0.5,
          "ground_z": 0.0, "side_slope": 0.0, "margin": 0.5}


def _dug(xs: np.ndarray, ys: np.ndarray, depth: float) -> np.ndarray:
    """Heights rows from the south (the plant's order): the trench dug to ``depth``."""
    gx, gy = np.meshgrid(xs, ys)
    return np.where((np.abs(gx + 5.0) < 0.5) & (np.abs(gy) < 2.0), -depth, 0.0)


def _npz(path, *, fine: bool, depth: float = 0.5):
    res, x0, y0 = 0.2, -10.0, -10.0
    xs = x0 + (np.arange(100) + 0.5) * res
    ys = y0 + (np.arange(100) + 0.5) * res
    arrays = {"h": _dug(xs, ys, depth) + 0.03, "x0": x0, "y0": y0, "res": res}  # coarse: 3 cm off, to tell them apart
    if fine:
        fr, fx0, fy0 = 0.05, -7.0, -4.0
        fxs = fx0 + (np.arange(80) + 0.5) * fr
        fys = fy0 + (np.arange(160) + 0.5) * fr
        arrays.update(fine_h=_dug(fxs, fys, depth), fine_x0=fx0, fine_y0=fy0, fine_res=fr)
    np.savez(path, **arrays)
    return path


def test_truth_grid_prefers_the_fine_patch_and_the_figures_of_an_exact_cut_are_zero(tmp_path):
    design = Design.from_dict(TRENCH)
    grid = truth_grid(_npz(tmp_path / "h.npz", fine=True), design)
    assert (grid.x_min, grid.y_min, grid.x_max, grid.y_max) == (-7.0, -4.0, -3.0, 4.0)
    f = figures(design, grid)
    assert f["mae_cm"] == pytest.approx(0.0, abs=1e-9) and f["max_cm"] == pytest.approx(0.0, abs=1e-9)
    assert f["cell_m"] == pytest.approx(0.05) and f["cells"] == round(2 * 5 / 0.05**2)
    assert excavated_volume(grid, design, 0.0) == pytest.approx(4 * 1 * 0.5, rel=1e-6)


def test_truth_grid_falls_back_to_the_coarse_grid_and_row_0_is_north(tmp_path):
    design = Design.from_dict(TRENCH)
    grid = truth_grid(_npz(tmp_path / "h.npz", fine=False, depth=0.3), design)
    assert grid.x_min == -10.0 and grid.z.shape == (100, 100)
    f = figures(design, grid)
    assert f["signed_mean_cm"] > 0  # 0.3 m dug of 0.5, the coarse grid 3 cm high: material above the design
    # an asymmetric field: the first row of the file (south) is the last row of the grid (north up)
    h = np.zeros((3, 2))
    h[0, 0] = 1.0
    np.savez(tmp_path / "a.npz", h=h, x0=0.0, y0=0.0, res=1.0)
    g = truth_grid(tmp_path / "a.npz")
    assert g.z[2, 0] == 1.0 and (g.x_max, g.y_max) == (2.0, 3.0)


def test_truth_grid_names_a_missing_or_malformed_file(tmp_path):
    with pytest.raises(DesignError, match="no such height field"):
        truth_grid(tmp_path / "none.npz")
    np.savez(tmp_path / "bad.npz", h=np.zeros((2, 2)), x0=0.0)
    with pytest.raises(DesignError, match="no number 'y0'"):
        truth_grid(tmp_path / "bad.npz")


def test_plot_errors_writes_a_png(tmp_path):
    design = Design.from_dict(TRENCH)
    xs = -7.0 + (np.arange(80) + 0.5) * 0.05
    ys = -4.0 + (np.arange(160) + 0.5) * 0.05
    grid = Grid(z=np.flipud(_dug(xs, ys, 0.45)), x_min=-7.0, y_min=-4.0, x_max=-3.0, y_max=4.0)
    out = plot_errors(design, {"a": grid, "b": grid}, tmp_path / "e.png", title="t")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
