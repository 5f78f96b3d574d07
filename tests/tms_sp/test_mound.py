"""tms_sp.mound's depth search."""

import dataclasses

import numpy as np

from tms_sp import synthetic as syn
from tms_sp.config import load_sensing_config
from tms_sp.heightgrid import rasterize


def test_level_cuts_pick_the_shallowest_depth_that_fills_the_bucket_else_the_deepest():
    """The depth search stops per cell at its first filling depth: check against every depth's cut computed whole."""
    from tms_sp.mound import _level_cuts

    cfg = load_sensing_config()
    g, params = cfg.mound_grid, cfg.excavation
    m = cfg.mound
    cone = syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height, m.ground_z)
    grid = rasterize(syn.scan(cone, (g.x_min, g.x_max), (g.y_min, g.y_max), 40000, np.random.default_rng(3)), g)
    xg, yg = g.centres()
    ax, ay = cfg.swing_axis_map()
    r = np.hypot(xg - ax, yg - ay)
    rows, cols = np.nonzero((r >= params.reach_min) & (r <= params.reach_max) & (grid.z > params.ground_z + 0.05))
    depth, cut = _level_cuts(grid.z, g, rows, cols, r[rows, cols], (ax, ay), params)
    depths = np.linspace(params.penetration_depth, params.max_penetration_depth, params.depth_steps)
    whole = {}
    for d in depths:  # one depth at a time: the search's answer must be one of these, the shallowest that fills
        p = dataclasses.replace(params, penetration_depth=d, max_penetration_depth=d, depth_steps=1)
        whole[d] = _level_cuts(grid.z, g, rows, cols, r[rows, cols], (ax, ay), p)[1]
    expected = np.full(len(rows), depths[-1])
    for d in reversed(depths):
        expected = np.where(whole[d] >= params.bucket_volume, d, expected)
    assert np.array_equal(depth, expected)
    assert np.allclose(cut, [whole[d][i] for i, d in enumerate(depth)], rtol=0, atol=1e-12)
    assert len(set(depth)) > 1, "every cell at one depth: the case does not test the search"
