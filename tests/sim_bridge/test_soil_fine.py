"""The fine soil patch (``soil.grid.fine``): volume kept exactly across its border, centimetre cuts inside it, and
the coarse view (render, mound scan) as the block means of the patch."""

import dataclasses

import numpy as np
import pytest

from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.scanners import mound_scan
from sim_bridge.soil import HeightField
from sim_bridge.spec import FineGrid
from tms_common.config import config_path

#: a patch on flat ground west of the mound (the paper grid: x, y from -20 m at 0.2 m), and one over the mound
PATCH = FineGrid(x_min=-10.0, y_min=-10.0, size_x=6.0, size_y=2.0, resolution=0.04)
MOUND_PATCH = FineGrid(x_min=4.0, y_min=-2.0, size_x=5.0, size_y=4.0, resolution=0.04)


def _field(fine: FineGrid | None) -> HeightField:
    return HeightField(dataclasses.replace(load_plant(None).soil, fine=fine))


def test_volume_is_conserved_over_random_cuts_and_deposits_across_the_patch_border():
    field = _field(PATCH)
    f = field.fine
    assert (f.nx, f.ny, f.k) == (150, 50, 5) and not field.active[f.r0:f.r1, f.c0:f.c1].any()
    v0, g0 = field.volume(), field.ground_soil_volume()
    rng = np.random.default_rng(11)
    held = moved = 0.0
    crossed = 0
    for _ in range(1500):
        # near a patch edge: the west or the north one, so cuts and piles straddle it
        if rng.random() < 0.5:
            x, y = -10.0 + rng.uniform(-1.0, 1.0), rng.uniform(-10.5, -7.5)
        else:
            x, y = rng.uniform(-10.5, -3.5), -8.0 + rng.uniform(-1.0, 1.0)
        if rng.random() < 0.55:
            ang = rng.uniform(0.0, 2 * np.pi)
            d = rng.uniform(0.0, 0.4)
            end = (x + d * np.cos(ang), y + d * np.sin(ang))
            got = field.cut((x, y), end, rng.uniform(-0.6, 0.2), width=rng.uniform(0.3, 1.6),
                            lateral=(-np.sin(ang), np.cos(ang)), max_volume=rng.uniform(0.0, 0.6))
            assert got >= 0.0
            held += got
            moved += got
        elif held > 0.0:
            v = min(held, rng.uniform(0.0, 0.4))
            field.deposit(x, y, v, float(rng.choice([0.01, 0.3, 0.6, 1.2])))
            held -= v
        crossed += not (f.contains(x - 0.6, y) == f.contains(x + 0.6, y) == f.contains(x, y + 0.6))
    assert crossed > 500
    assert moved > 20.0  # soil was really moved
    assert abs(field.volume() + held - v0) <= 1e-9 * v0
    assert field.ground_soil_volume() + held == pytest.approx(g0, abs=1e-9 * v0)
    # the coarse view h carries the same volume: its cells under the patch are the patch's block means
    view = float((field.h - field.datum).sum() * field.cell_area)
    assert view == pytest.approx(field.volume(), rel=1e-12)
    means = f.h.reshape(f.ny // f.k, f.k, f.nx // f.k, f.k).mean(axis=(1, 3))
    assert np.allclose(field.h[f.r0:f.r1, f.c0:f.c1], means, rtol=0.0, atol=1e-12)


def test_a_pile_smaller_than_a_cell_lands_in_the_fine_cell_under_it():
    field = _field(PATCH)
    v0 = field.volume()
    field.deposit(-7.01, -9.01, 0.002, 0.001)  # no cell centre within 1 mm: the cell holding the point
    assert field.height(-7.01, -9.01) == pytest.approx(0.002 / 0.04**2)
    assert field.height(-7.05, -9.01) == 0.0  # the next fine cell, inside the same coarse cell
    assert field.volume() == pytest.approx(v0 + 0.002, rel=1e-12)


def _trench_errors(field: HeightField, x0: float, x1: float, yc: float, width: float, z: float,
                   border: float) -> tuple[float, float]:
    """Cut a trench ``x0`` .. ``x1`` (edge ``width`` across y at ``yc``, 1 cm steps, edge at ``z``) and return the
    mean abs error of the surface against ``z`` over the trench, for x above ``border`` (in the patch) and below."""
    steps = int(round((x1 - x0) / 0.01))
    for i in range(steps):
        a, b = x0 + i * 0.01, x0 + (i + 1) * 0.01
        field.cut((a, yc), (b, yc), z, width=width, lateral=(0.0, 1.0), max_volume=10.0)
    xs = np.arange(x0 + 0.005, x1, 0.01)
    ys = np.arange(yc - width / 2 + 0.005, yc + width / 2, 0.01)
    err = np.array([[abs(field.height(x, y) - z) for x in xs] for y in ys])
    return float(err[:, xs > border].mean()), float(err[:, xs < border].mean())


def test_a_straight_cut_leaves_centimetre_steps_in_the_patch_and_coarse_steps_outside():
    """A 10 m x 1 m x 0.5 m trench, half in the patch: the edge height is met to < 1 cm (mean) inside it."""
    z = -0.5
    field = _field(PATCH)
    inside, outside = _trench_errors(field, -14.03, -4.03, -8.97, 1.0, z, -10.0)
    coarse_in, coarse_out = _trench_errors(_field(None), -14.03, -4.03, -8.97, 1.0, z, -10.0)
    print(f"\ntrench 10 m x 1 m x 0.5 m, mean |surface - design|: fine patch (0.04 m) {inside * 100:.2f} cm, "
          f"coarse grid (0.2 m) {outside * 100:.2f} cm; the same trench without the patch: {coarse_in * 100:.2f} cm "
          f"/ {coarse_out * 100:.2f} cm")
    assert inside < 0.01
    assert outside > 2 * inside and coarse_in > 2 * inside
    assert outside == pytest.approx(coarse_out, abs=1e-12)  # the coarse side cut as without a patch


def test_height_and_the_mound_scan_read_the_patch():
    field = _field(MOUND_PATCH)
    f = field.fine
    cx, cy = field.spec.mound_center
    # the mound in the patch from the same formula: the same volume as the coarse cells, to the discretisation
    assert field.mound_volume() == pytest.approx(_field(None).mound_volume(), rel=0.01)
    field.cut((cx - 2.0, cy + 0.13), (cx - 1.0, cy + 0.13), 0.7, width=1.0, lateral=(0.0, 1.0), max_volume=5.0)
    field.deposit(cx + 0.5, cy - 0.5, 0.3, 0.6)
    for r, c in ((3, 7), (f.ny // 2, f.nx // 3), (f.ny - 1, f.nx - 1)):
        assert field.height(f.xs[c], f.ys[r]) == f.h[r, c]
    assert field.height(cx - 1.5, cy + 0.13) == pytest.approx(0.7)
    pts = mound_scan(field, (cx, cy), 4.0, noise=0.0, rng=np.random.default_rng(0), spacing=0.2)
    in_patch = [(x, y, zz) for x, y, zz in pts if f.contains(x, y)]
    assert len(in_patch) > 300
    half = field.res / 2
    for x, y, zz in in_patch[::7]:  # a scan point under the patch: the mean of its fine cells' heights
        fine = [field.height(fx, fy) for fx in f.xs[(f.xs > x - half) & (f.xs < x + half)]
                for fy in f.ys[(f.ys > y - half) & (f.ys < y + half)]]
        assert len(fine) == f.k**2 and zz == pytest.approx(np.mean(fine), abs=1e-12)
    assert float((pts[:, 2] - field.spec.ground_z).sum()) * 0.2**2 == pytest.approx(field.mound_volume(), rel=0.05)


def _plant_yaml(tmp_path, fine: str) -> str:
    text = config_path("sim", "plant.yaml").read_text()
    line = "grid: {x_min: -20.0, y_min: -20.0, size_x: 72.0, size_y: 50.0, resolution: 0.2}"
    assert line in text
    path = tmp_path / "plant.yaml"
    path.write_text(text.replace(line, line[:-1] + f", fine: {fine}}}"))
    return str(path)


@pytest.mark.parametrize(("fine", "problem"), [
    ("{x_min: 0.0, y_min: 0.0, size_x: 4.0, size_y: 2.0, resolution: 0.03}", "fine.resolution: "),
    ("{x_min: -21.0, y_min: 0.0, size_x: 4.0, size_y: 2.0, resolution: 0.04}", "fine.x_min: "),
    ("{x_min: 50.0, y_min: 0.0, size_x: 4.0, size_y: 2.0, resolution: 0.04}", "fine.size_x: "),
    ("{x_min: 0.0, y_min: 0.1, size_x: 4.0, size_y: 2.0, resolution: 0.04}", "fine.y_min: "),
    ("{x_min: 0.0, y_min: 0.0, size_x: 4.0, size_y: 2.05, resolution: 0.04}", "fine.size_y: "),
    ("{x_min: 0.0, y_min: 0.0, size_x: 4.0, size_y: 2.0, resolution: 0.04, res: 1}", "fine.res: unknown key"),
])
def test_a_patch_off_the_grid_is_refused_naming_its_field(tmp_path, fine, problem):
    with pytest.raises(SimConfigError) as err:
        load_plant(_plant_yaml(tmp_path, fine))
    assert problem in str(err.value) and "\n" not in str(err.value)


def test_the_patch_is_read_from_the_plant_yaml(tmp_path):
    spec = load_plant(_plant_yaml(tmp_path, "{x_min: 2.0, y_min: -4.0, size_x: 10.0, size_y: 8.0, resolution: 0.05}"))
    assert spec.soil.fine == FineGrid(2.0, -4.0, 10.0, 8.0, 0.05)
    assert load_plant(None).soil.fine is None
