"""Design surfaces, their error metrics and the pass planner (tms_rp.excavation), without ROS.

Heights at known points are worked out by hand from each kind's parameters; the planner is run against a small
height-grid "digger" in this file (it lowers the planned cells to the edge path, with noise, and puts the volume it
removed at the planned dump place), on a 10 m x 1 m x 0.5 m trench and on a small two-faced embankment.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from tms_model.excavator.kinematics import site_excavator_kind
from tms_model.machines import load_machine
from tms_rp.excavation.design import (
    Design,
    DesignError,
    Grid,
    cell_centres,
    embankment,
    s_curve,
    surface_error,
    trench,
)
from tms_rp.excavation.planner import BasePose, Decision, PassPlanner, PlannerSettings
from tms_sp.terrain import Heightmap

MACHINE = load_machine(site_excavator_kind())


# ---- heights by hand -----------------------------------------------------------------------------------------------
def test_trench_heights_at_known_points() -> None:
    d = trench("t1", start=[0, 0], end=[10, 0], width=1.0, ground_z=0.0, depth=0.5, side_slope=1.0)
    pts = {  # (x, y): height worked out from the parameters
        (5.0, 0.0): -0.5, (5.0, 0.5): -0.5,  # bottom, bottom edge
        (5.0, 0.75): -0.5 + 0.25 / 1.0,  # 0.25 m up the wall at 1:1
        (5.0, -0.9): -0.5 + 0.4,
        (5.0, 1.2): 0.0, (12.0, 0.0): 0.0,  # beyond the wall's top: the original ground
        (-0.25, 0.0): -0.25,  # the end wall
    }
    for (x, y), z in pts.items():
        assert float(d.height(x, y)) == pytest.approx(z, abs=1e-9), (x, y)
    vertical = trench("t2", start=[0, 0], end=[10, 0], width=1.0, ground_z=2.0, bottom_z=1.2)
    assert float(vertical.height(5.0, 0.4)) == pytest.approx(1.2)
    assert float(vertical.height(5.0, 0.6)) == pytest.approx(2.0)
    sloped = trench("t3", start=[0, 0], end=[0, 10], width=2.0, ground_z=0.0, bottom_z=-0.8, side_slope=2.0)
    assert float(sloped.height(1.0 + 0.4, 5.0)) == pytest.approx(-0.8 + 0.4 / 2.0)  # axis along +y this time
    # default area: the footprint (bottom grown by the walls' run 0.8 m * 2 = 1.6 m)
    assert sloped.contains(1.0 + 1.55, 5.0) and not sloped.contains(1.0 + 1.65, 5.0)


def test_two_faced_embankment_heights_at_known_points() -> None:
    d = embankment("e1", start=[0, 0], end=[4, 0], crest_width=1.0, height=0.6, base_z=1.0, slope_left=1.5,
                   slope_right=2.0)
    assert float(d.height(2.0, 0.0)) == pytest.approx(1.6)  # crest centre
    assert float(d.height(2.0, 0.5)) == pytest.approx(1.6)  # crest edge
    assert float(d.height(2.0, 0.5 + 0.45)) == pytest.approx(1.6 - 0.45 / 1.5)  # left face (+y is left of +x)
    assert float(d.height(2.0, -0.5 - 0.6)) == pytest.approx(1.6 - 0.6 / 2.0)  # right face, its own slope
    assert float(d.height(2.0, -0.5 - 1.2)) == pytest.approx(1.0)  # right toe: 0.6 m * 2.0
    assert float(d.height(2.0, 5.0)) == pytest.approx(1.0)  # the ground beyond
    assert float(d.height(4.3, 0.4)) == pytest.approx(1.6)  # 0.5 m from the end point: still on the crest
    assert float(d.height(4.6, 0.8)) == pytest.approx(1.6 - (1.0 - 0.5) / 1.5)  # round the end, left slope


def test_s_curve_heights_at_known_points() -> None:
    # axis along +y from (1, 2): the left normal is -x; the crest swings 1.5 m left at t = 2 and right at t = 6
    d = s_curve("s1", start=[1, 2], heading=math.pi / 2, length=8.0, amplitude=1.5, crest_width=0.4, height=0.5,
                base_z=0.0, slope_left=1.0, slope_right=2.0)
    assert float(d.height(1.0, 2.0)) == pytest.approx(0.5)  # start
    assert float(d.height(1.0, 6.0)) == pytest.approx(0.5)  # the S's middle crosses the axis
    assert float(d.height(1.0 - 1.5, 4.0)) == pytest.approx(0.5)  # left crest of the S
    assert float(d.height(1.0 + 1.5, 8.0)) == pytest.approx(0.5)  # right crest
    assert float(d.height(1.0 - 1.5 - 0.2 - 0.25, 4.0)) == pytest.approx(0.5 - 0.25 / 1.0, abs=1e-6)
    assert float(d.height(1.0 + 1.5 + 0.2 + 0.5, 8.0)) == pytest.approx(0.5 - 0.5 / 2.0, abs=1e-6)
    assert float(d.height(10.0, 0.0)) == pytest.approx(0.0)
    # inside the left bend (its radius 1 / (1.5 (2 pi / 8)^2) = 1.08 m > 0.3 m): the right face, 0.1 m below the
    # crest edge at slope 2 (the polyline's chords there are within 1e-4 m of the curve)
    assert float(d.height(1.0 - 1.5 + 0.2 + 0.1, 4.0)) == pytest.approx(0.5 - 0.1 / 2.0, abs=1e-3)


# ---- the document --------------------------------------------------------------------------------------------------
def _designs() -> list[Design]:
    return [
        trench("t", start=[0, 0], end=[10, 0], width=1.0, ground_z=0.0, depth=0.5, side_slope=0.5, margin=0.3),
        trench("tb", start=[1, 1], end=[1, 6], width=0.8, ground_z=3.0, bottom_z=2.0),
        embankment("e", start=[0, 0], end=[3, 1], crest_width=0.5, height=0.4, base_z=0.2, slope_left=1.5,
                   slope_right=2.5, margin=1.0),
        s_curve("s", start=[0, 0], heading=0.3, length=20.0, amplitude=2.0, crest_width=1.0, height=1.0, base_z=0.0,
                slope_left=2.0, slope_right=2.0,
                area=[[-5, -8], [25, -8], [25, 15], [-5, 15]]),
    ]


def test_dict_round_trip_keeps_every_design() -> None:
    xs, ys = np.meshgrid(np.linspace(-3, 12, 31), np.linspace(-4, 6, 21))
    for d in _designs():
        doc = d.to_dict()
        back = Design.from_dict(json.loads(json.dumps(doc)))  # through the DB's JSON-like form
        assert back == d and back.to_dict() == doc, d.name
        assert np.array_equal(back.height(xs, ys), d.height(xs, ys))
        assert set(doc) >= {"name", "kind", "frame", "area"} and doc["frame"] == "map"


@pytest.mark.parametrize(("change", "words"), [
    ({"widht": 1.0}, ["'widht'", "'t'"]),  # unknown key: named, with the design
    ({"depth": -0.5}, ["depth", "out of range", "'t'"]),
    ({"depth": 50.0}, ["depth", "out of range"]),
    ({"side_slope": 11}, ["side_slope", "out of range"]),
    ({"width": True}, ["width", "number"]),
    ({"width": float("nan")}, ["width", "finite"]),
    ({"bottom_z": -0.4}, ["exactly one of 'depth' and 'bottom_z'"]),
    ({"frame": "odom"}, ["frame", "'map'"]),
    ({"kind": "pond"}, ["kind", "'pond'"]),
    ({"start": [0, 0, 0]}, ["start", "point"]),
    ({"end": [0.05, 0]}, ["start and end"]),
    ({"area": [[0, 0], [1, 1]]}, ["area", "polygon"]),
    ({"area": [[0, 0], [1, 1], [2, 2]]}, ["area", "no area"]),
    ({"name": ""}, ["name"]),
])
def test_bad_trench_documents_are_refused_with_the_key(change: dict, words: list[str]) -> None:
    doc = _designs()[0].to_dict()
    doc.update(change)
    with pytest.raises(DesignError) as err:
        Design.from_dict(doc)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_bad_embankment_documents_are_refused() -> None:
    doc = _designs()[3].to_dict()
    for key, value, words in (("amplitude", 11.0, "amplitude"), ("slope_left", 0.0, "slope_left"),
                              ("height", 0.0, "height"), ("end", [1, 1], "'end'")):
        bad = dict(doc, **{key: value})
        with pytest.raises(DesignError, match=words):
            Design.from_dict(bad)
    missing = {k: v for k, v in doc.items() if k != "crest_width"}
    with pytest.raises(DesignError, match="missing key 'crest_width'"):
        Design.from_dict(missing)


# ---- grids and metrics ---------------------------------------------------------------------------------------------
def test_sampling_follows_the_heightmap_convention() -> None:
    # a sloped trench wall running east-west: heights differ between north and south rows
    d = trench("g", start=[-10, 0], end=[10, 0], width=0.4, ground_z=1.0, depth=1.0, side_slope=2.0,
               area=[[-2, -2], [2, -2], [2, 2], [-2, 2]])
    hm = Heightmap(z=np.zeros((40, 20)), x_min=-2.0, y_min=-2.0, x_max=2.0, y_max=2.0, z_min=0.0)
    s = d.sample(hm)
    xc, yc = hm.centres()
    assert np.array_equal(cell_centres(hm)[0], xc) and np.array_equal(cell_centres(hm)[1], yc)
    assert np.allclose(s.target, d.height(xc, yc))
    # row 0 is the north edge: y = 1.95, 1.75 m off the bottom's edge -> 1.75 / 2 up the wall
    assert s.target[0, 5] == pytest.approx(0.0 + 1.75 / 2.0)
    assert s.target[20, 5] == pytest.approx(0.0)  # y = -0.05: on the bottom
    assert s.inside.all() and s.cell_area == pytest.approx(0.2 * 0.1)
    with pytest.raises(DesignError, match="holds no cell"):
        d.sample(Grid(z=np.zeros((4, 4)), x_min=10.0, y_min=10.0, x_max=14.0, y_max=14.0))


def test_metrics_against_a_hand_built_grid() -> None:
    # design: flat at 0 over the west half of a 4 x 4 grid of 1 m cells (a trench bottom covering everything)
    d = trench("m", start=[-10, 2], end=[10, 2], width=10.0, ground_z=5.0, depth=5.0,
               area=[[0, 0], [2, 0], [2, 4], [0, 4]])
    z = np.full((4, 4), 9.0)  # the east half is outside the area and must not count
    z[:, :2] = [[0.1, -0.2], [0.0, 0.3], [0.0, 0.0], [-0.1, 0.05]]
    e = surface_error(d, Grid(z=z, x_min=0.0, y_min=0.0, x_max=4.0, y_max=4.0))
    absolute = [0.1, 0.2, 0.0, 0.3, 0.0, 0.0, 0.1, 0.05]
    assert e.cells == 8
    assert e.mae == pytest.approx(sum(absolute) / 8)
    assert e.max_abs == pytest.approx(0.3)
    assert e.signed_mean == pytest.approx((0.1 - 0.2 + 0.3 - 0.1 + 0.05) / 8)
    assert e.cut_volume == pytest.approx(0.1 + 0.3 + 0.05)  # 1 m^2 cells
    assert e.fill_volume == pytest.approx(0.2 + 0.1)
    ranked = sorted(absolute)  # the 95th percentile, linear between ranks 6 and 7 of 0..7
    assert e.p95 == pytest.approx(ranked[6] + 0.65 * (ranked[7] - ranked[6]))
    assert np.isnan(e.error[:, 2:]).all() and e.error[1, 1] == pytest.approx(0.3)


# ---- the planner against a digger ------------------------------------------------------------------------------------
def _dig(grid: Grid, d: Decision, rng: np.random.Generator, noise: float) -> float:
    """Carry out ``d.cut`` on ``grid``: its cells down to the edge path at their place along it (never up), with
    noise; the removed volume at the dump place in the planned shape. Returns the volume removed."""
    p = d.cut
    assert p is not None
    z = grid.z
    xc, yc = cell_centres(grid)
    rows, cols = p.cells[:, 0], p.cells[:, 1]
    u = np.array(p.direction)
    along = (xc[rows, cols] - p.start[0]) * u[0] + (yc[rows, cols] - p.start[1]) * u[1]
    path_along = (p.path[:, 0] - p.start[0]) * u[0] + (p.path[:, 1] - p.start[1]) * u[1]
    edge = np.interp(along, path_along, p.path[:, 2])
    before = z[rows, cols].copy()
    z[rows, cols] = np.minimum(before, edge + rng.normal(0.0, noise, len(rows)))
    area = (grid.x_max - grid.x_min) / z.shape[1] * (grid.y_max - grid.y_min) / z.shape[0]
    removed = float(np.sum(before - z[rows, cols])) * area
    dr, dc = p.dump_cells[:, 0], p.dump_cells[:, 1]
    rise = p.dump_to - z[dr, dc]
    z[dr, dc] += rise * removed / (float(np.sum(rise)) * area) + rng.normal(0.0, noise, len(dr))
    return removed


def _run(planner: PassPlanner, grid: Grid, design: Design, base: BasePose, *, passes: int = 400,
         noise: float = 0.01) -> tuple[Decision, int, float]:
    rng = np.random.default_rng(3)
    axis = planner.swing_axis(base)
    moved = 0.0
    for k in range(passes):
        d = planner.next_pass(grid, design, base)
        if d.cut is None:
            return d, k, moved
        p = d.cut
        assert 0 < p.volume <= MACHINE.bucket.capacity + 1e-9 and p.width == MACHINE.bucket.width
        assert 0 < p.depth <= planner.settings.max_pass_depth + 1e-12
        assert p.length <= planner.settings.max_pass_length + 0.2
        # the drag goes toward the machine: the end is nearer the swing axis than the start
        assert math.dist(p.end[:2], axis) < math.dist(p.start[:2], axis)
        assert np.dot(p.direction, axis - np.array(p.start[:2])) > 0
        moved += _dig(grid, d, rng, noise)
    raise AssertionError(f"no stop after {passes} passes: {d.reason}, {d.error.summary()}")


def _flat(x0: float, y0: float, x1: float, y1: float, cell: float = 0.1) -> Grid:
    return Grid(z=np.zeros((round((y1 - y0) / cell), round((x1 - x0) / cell))), x_min=x0, y_min=y0, x_max=x1,
                y_max=y1)


def test_planner_cuts_a_10m_trench_to_within_3cm() -> None:
    design = trench("trench10", start=[0, 0], end=[10, 0], width=1.0, ground_z=0.0, depth=0.5)
    grid = _flat(-2.0, -6.0, 12.0, 4.0)
    planner = PassPlanner(MACHINE)
    start = surface_error(design, grid)
    assert start.cut_volume == pytest.approx(5.0, rel=1e-6)  # 10 m x 1 m x 0.5 m
    done, passes, moved = _run(planner, grid, design, BasePose(5.0, -3.5, math.pi / 2, 0.0))
    e = done.error
    print(f"\ntrench 10 x 1 x 0.5 m: {passes} passes, {moved:.2f} m3 moved; {e.summary()}")
    assert done.reason.startswith("within tolerance"), done.reason
    assert e.mae <= 0.03 and e.cut_volume < 0.05 * start.cut_volume
    assert moved == pytest.approx(start.cut_volume, rel=0.1)
    # the spoil went outside the design area, at least the spoil clearance from it
    outside = ~design.sample(grid).inside
    assert np.sum(grid.z[outside]) * 0.01 == pytest.approx(moved, rel=0.05)
    xc, yc = cell_centres(grid)
    near = outside & (np.abs(yc) < 0.5 + planner.settings.spoil_clearance - 0.1) & (xc > -0.5) & (xc < 10.5)
    assert np.abs(grid.z[near]).max() < 0.05


def test_planner_builds_a_two_faced_embankment_to_within_3cm() -> None:
    design = embankment("bank", start=[2.0, 0.5], end=[4.0, 0.5], crest_width=0.4, height=0.4, base_z=0.0,
                        slope_left=1.5, slope_right=1.5, margin=1.5)
    grid = _flat(-2.0, -9.0, 10.0, 5.0)
    xc, yc = cell_centres(grid)
    grid.z[:] = 1.2 * np.exp(-((xc - 3.0) ** 2 + (yc + 1.2) ** 2) / (2 * 0.45 ** 2))  # the soil pile, in the apron
    pile = float(np.sum(grid.z)) * 0.01
    start = surface_error(design, grid)
    print(f"\nembankment: pile {pile:.2f} m3, fill needed {start.fill_volume:.2f} m3; start {start.summary()}")
    assert pile > start.fill_volume and start.mae > 0.05
    planner = PassPlanner(MACHINE)
    done, passes, moved = _run(planner, grid, design, BasePose(3.0, -5.5, math.pi / 2, 0.0))
    e = done.error
    print(f"embankment: {passes} passes, {moved:.2f} m3 moved; stop: {done.reason}; {e.summary()}")
    # the supply runs out before the last toe cells are filled: the stop is then "nothing worth a pass"
    assert done.reason.startswith(("within tolerance", "nothing reachable worth a pass")), done.reason
    assert e.p95 <= planner.settings.tolerance_p95
    assert e.mae <= 0.03 and e.fill_volume < 0.15 * start.fill_volume
    crest = design.sample(grid).target >= 0.4 - 1e-9
    assert abs(float(np.mean(grid.z[crest])) - 0.4) < 0.03  # the crest was built up, not only the pile removed


def test_planner_stops_when_nothing_is_reachable() -> None:
    design = trench("far", start=[0, 0], end=[10, 0], width=1.0, ground_z=0.0, depth=0.5)
    planner = PassPlanner(MACHINE)
    grid = _flat(-2.0, -6.0, 12.0, 4.0)
    d = planner.next_pass(grid, design, BasePose(40.0, 0.0, 0.0, 0.0))
    assert d.cut is None and d.reason.startswith("nothing reachable"), d.reason
    assert d.error.cut_volume == pytest.approx(5.0, rel=1e-6)
    # from beside the trench's west end, the east end is out of reach: the run stops with it untouched
    done, passes, _ = _run(planner, grid, design, BasePose(-1.0, -3.5, math.pi / 2, 0.0))
    print(f"\ntrench from its west end: {passes} passes, stop: {done.reason}; {done.error.summary()}")
    assert passes > 0 and done.reason.startswith("nothing reachable") and done.error.mae > 0.03
    xc, yc = cell_centres(grid)
    axis = planner.swing_axis(BasePose(-1.0, -3.5, math.pi / 2, 0.0))
    r = np.hypot(xc - axis[0], yc - axis[1])
    in_trench = design.sample(grid).inside
    assert np.all(grid.z[in_trench & (r > planner.reach.r_max.max())] == 0.0)  # beyond any reach: never cut
    assert np.all(grid.z[in_trench & (r < 6.0) & (r > planner.min_radius + 0.5)] < -0.45)  # within reach: dug


def test_planner_stops_within_tolerance_and_uses_the_description() -> None:
    design = embankment("flat", start=[0.0, 0.0], end=[2.0, 0.0], crest_width=0.4, height=0.4, base_z=0.0,
                        slope_left=1.5, slope_right=1.5, margin=2.0)
    grid = _flat(-2.0, -7.0, 4.0, 2.0)
    xc, yc = cell_centres(grid)
    grid.z[:] = design.height(xc, yc) + 0.005
    planner = PassPlanner(MACHINE)
    d = planner.next_pass(grid, design, BasePose(1.0, -5.0, math.pi / 2, 0.0))
    assert d.cut is None and d.reason.startswith("within tolerance") and d.error.mae == pytest.approx(0.005)
    # a smaller bucket in the description: smaller passes, the same planner code
    small = dataclasses.replace(MACHINE, bucket=dataclasses.replace(MACHINE.bucket, capacity=0.1, width=0.5))
    grid.z[:] = design.height(xc, yc) + 0.4 * (np.abs(xc - 1.0) < 1.5) * (yc < -0.8) * (yc > -2.8)
    settings = PlannerSettings()
    p_big = PassPlanner(MACHINE, settings).next_pass(grid, design, BasePose(1.0, -5.5, math.pi / 2, 0.0)).cut
    p_small = PassPlanner(small, settings).next_pass(grid, design, BasePose(1.0, -5.5, math.pi / 2, 0.0)).cut
    assert p_big is not None and p_small is not None
    assert p_small.volume <= 0.1 + 1e-9 < p_big.volume and p_small.width == 0.5
