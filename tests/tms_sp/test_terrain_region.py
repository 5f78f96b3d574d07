"""The dynamic terrain over a region of its own (a design's work area): the box parameter's checks, and a trench cut
below the ground kept in the 16-bit heightmap when pixel 0 lies under its bottom (at the ground it is clipped)."""

from __future__ import annotations

import numpy as np
import pytest

from tms_db import open_store
from tms_sp import terrain as tr
from tms_sp.heightgrid import GridSpec


def test_region_box_all_zero_is_none_else_a_grid_of_whole_cells():
    assert tr.region_box([0.0, 0.0, 0.0, 0.0], 0.05) is None
    box = tr.region_box([-8, -8, -2, 8], 0.05)
    assert box == GridSpec(-8.0, -8.0, -2.0, 8.0, 0.05) and (box.nx, box.ny) == (120, 320)


@pytest.mark.parametrize(("values", "cell", "problem"), [
    ([1.0, 2.0, 3.0], 0.05, r"box: expected \[x_min, y_min, x_max, y_max\], got 3 value"),
    (["a", 0, 1, 1], 0.05, r"box: expected \[x_min, y_min, x_max, y_max\] numbers"),
    ([0.0, 0.0, float("nan"), 1.0], 0.05, r"box: non-finite value"),
    ([0.0, 0.0, -1.0, 1.0], 0.05, r"box: empty box x \[0, -1\]"),
    ([0.0, 0.0, 1.02, 1.0], 0.05, r"box: the x side 1.02 m is not a whole number of 0.05 m cells"),
    ([0.0, 0.0, 1.0, 1.0], 0.0, r"box: cell must be > 0"),
])
def test_region_box_names_what_is_wrong(values, cell, problem):
    with pytest.raises(tr.TerrainError, match=problem):
        tr.region_box(values, cell, source="box")


def _trench_scan(spacing: float = 0.05) -> np.ndarray:
    xs = np.arange(-8 + spacing / 2, -2, spacing)
    ys = np.arange(-8 + spacing / 2, 8, spacing)
    gx, gy = np.meshgrid(xs, ys)
    z = np.where((np.abs(gx + 5.0) < 0.5) & (np.abs(gy) < 5.0), -0.5, 0.0)
    return np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])


def test_a_trench_below_the_ground_survives_only_with_pixel_0_under_it(tmp_path):
    store = open_store(path=tmp_path / "db")
    try:
        box = tr.region_box([-8, -8, -2, 8], 0.05)
        for z_min, bottom in ((-2.0, -0.5), (0.0, 0.0)):
            dyn = tr.DynamicTerrain(store, box, 0.05, z_min, filename=f"t{z_min}.png")
            dyn.on_points(_trench_scan(), source="scan")
            doc, blob = tr.latest_heightmap(store, "dynamic", filename=f"t{z_min}.png")
            hm = tr.heightmap_from_blob(blob, doc)
            assert (hm.cols, hm.rows) == (120, 320)
            assert hm.height_at(-5.0, 0.0) == pytest.approx(bottom, abs=1e-3)
            assert hm.height_at(-3.0, 0.0) == pytest.approx(max(0.0, z_min), abs=1e-3)
    finally:
        store.close()
