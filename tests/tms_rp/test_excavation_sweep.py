"""The pass planner's level sweep (PlannerSettings.level_sweep): passes planned as the arm's excavate drags them,
the edge level over the whole bucket width, checked by executing the goal itself (not the planned cells) on a grid:
no cell is cut below the design and each pass moves what it planned."""

from __future__ import annotations

import numpy as np
import pytest

from tms_model.excavator.kinematics import site_excavator_kind
from tms_model.machines import load_machine
from tms_rp.excavation.design import Design, Grid, cell_centres, surface_error
from tms_rp.excavation.planner import BasePose, PassPlanner, PlannerSettings

MACHINE = load_machine(site_excavator_kind())
TRENCH = {"name": "tr", "kind": "trench", "start": [-5.0, -5.0], "end": [-5.0, 5.0], "width": 1.0, "depth": 0.5,
          "ground_z": 0.0, "side_slope": 0.0, "margin": 0.5}


def _drag(grid: Grid, cut, width: float) -> float:
    """The excavate goal on an ideal machine: everything above the start's edge height in the bucket-wide band from
    the start over the pass length, down to it; the volume removed."""
    xc, yc = cell_centres(grid)
    u = np.array(cut.direction)
    n = np.array([-u[1], u[0]])
    along = (xc - cut.start[0]) * u[0] + (yc - cut.start[1]) * u[1]
    across = (xc - cut.start[0]) * n[0] + (yc - cut.start[1]) * n[1]
    band = (along >= 0) & (along <= cut.length) & (np.abs(across) <= width / 2)
    before = grid.z[band].copy()
    grid.z[band] = np.minimum(before, cut.start[2])
    cell = (grid.x_max - grid.x_min) / grid.z.shape[1] * (grid.y_max - grid.y_min) / grid.z.shape[0]
    return float(np.sum(before - grid.z[band])) * cell


def test_level_sweeps_executed_as_goals_never_cut_below_the_design_and_move_what_they_plan():
    design = Design.from_dict(TRENCH)
    grid = Grid(z=np.zeros((160, 60)), x_min=-8.0, y_min=-8.0, x_max=-2.0, y_max=8.0)
    planner = PassPlanner(MACHINE, PlannerSettings(level_sweep=True))
    base = BasePose(0.0, 0.0, 0.0, 0.0)
    target = design.sample(grid).target
    inside = design.sample(grid).inside
    planned = moved = 0.0
    for _ in range(60):
        d = planner.next_pass(grid, design, base)
        if d.cut is None:
            break
        assert np.ptp(d.cut.path[:, 2]) == 0.0  # one edge height
        planned += d.cut.volume
        moved += _drag(grid, d.cut, planner.bucket_width)
        assert np.all(grid.z[inside] >= target[inside] - 1e-9)  # the walls and the apron stay
    assert d.cut is None and d.reason.startswith("nothing reachable worth a pass")
    assert moved == pytest.approx(planned, rel=0.1)
    e = surface_error(design, grid)
    # what a level, bucket-wide radial drag from one base pose leaves: the trench's corners toward its ends, where
    # the slanted bucket would cut the walls (measured: MAE 5.5 cm, 3.9 of 5 m3)
    assert e.fill_volume == 0.0 and 0.5 < e.cut_volume < 2.0


def test_without_fill_a_small_dip_in_the_design_does_not_cap_the_pass():
    design = Design.from_dict(TRENCH)
    grid = Grid(z=np.zeros((160, 60)), x_min=-8.0, y_min=-8.0, x_max=-2.0, y_max=8.0)
    xc, yc = cell_centres(grid)
    grid.z[(np.abs(xc + 4.3) < 0.1) & (np.abs(yc) < 0.3)] = -0.05  # a 5 cm dip in the apron: room for 0.006 m3
    base = BasePose(0.0, 0.0, 0.0, 0.0)
    capped = PassPlanner(MACHINE, PlannerSettings(level_sweep=True, min_fill_volume=0.001)).next_pass(
        grid, design, base)
    free = PassPlanner(MACHINE, PlannerSettings(level_sweep=True, min_fill_volume=0.001, fill=False)).next_pass(
        grid, design, base)
    assert capped.cut.dump_kind == "fill" and capped.cut.volume <= 0.01
    assert free.cut.dump_kind == "spoil" and free.cut.volume > 0.1
