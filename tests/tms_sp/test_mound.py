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


def test_a_cell_whose_drag_cuts_almost_nothing_is_no_target():
    """Soil left as a rim at the foot, just outside reach_min (its drag cut short to ~0.2 m), and a block further
    out: the distance penalty alone sent the bucket to the rim (a fleet demo: 27 near-empty passes); with
    ``min_cut`` the block is the target, and with only the rim left the mound counts as depleted."""
    from tms_sp.mound import assess_mound

    cfg = load_sensing_config()
    g, params = cfg.mound_grid, cfg.excavation
    ax, ay = cfg.swing_axis_map()
    my = cfg.mound.cy
    assert params.min_cut > 0.0

    def surface(block: bool):
        def z(x, y):
            r = np.hypot(x - ax, y - ay)
            rim = (r >= params.reach_min) & (r <= params.reach_min + 0.4) & (np.abs(y - my) < 1.5)
            far = (r >= 6.8) & (r <= 7.8) & (np.abs(y - my) < 1.0) & block
            return np.where(rim, 0.35, 0.0) + np.where(far, 0.5, 0.0) + cfg.mound.ground_z
        return z

    rng = np.random.default_rng(11)
    grid = rasterize(syn.scan(surface(True), (g.x_min, g.x_max), (g.y_min, g.y_max), 40000, rng, noise=0.0), g)
    penalty_only = assess_mound(grid, (ax, ay), dataclasses.replace(params, min_cut=0.0)).target
    r_before = np.hypot(penalty_only.x - ax, penalty_only.y - ay)
    assert r_before < params.reach_min + 0.5 and penalty_only.expected_volume < params.min_cut  # the old choice
    chosen = assess_mound(grid, (ax, ay), params)
    r = np.hypot(chosen.target.x - ax, chosen.target.y - ay)
    assert chosen.has_soil and 6.5 < r < 8.0 and chosen.target.expected_volume >= params.min_cut, chosen.target
    rim_only = rasterize(syn.scan(surface(False), (g.x_min, g.x_max), (g.y_min, g.y_max), 40000, rng, noise=0.0), g)
    left = assess_mound(rim_only, (ax, ay), params)
    assert left.volume_in_reach >= params.min_volume  # soil in reach, but no pass would cut min_cut
    assert not left.has_soil and left.target is None
