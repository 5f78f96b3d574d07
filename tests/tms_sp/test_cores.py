"""Sensing cores on synthetic, noisy height fields: targets within tolerance, flags right."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.geometry import Pose2D
from tms_sp import synthetic as syn
from tms_sp.arrival import ArrivalDetector, ArrivalParams
from tms_sp.config import load_sensing_config
from tms_sp.errors import SensingError
from tms_sp.heightgrid import GridSpec, HeightGrid, rasterize
from tms_sp.mound import assess_mound
from tms_sp.vessel import assess_vessel, release_in_excavator

CFG = load_sensing_config()


def _mound_grid(surface, rng, n=40000, noise=0.03, outliers=0.01):
    g = CFG.mound_grid
    pts = syn.scan(surface, (g.x_min, g.x_max), (g.y_min, g.y_max), n, rng, noise=noise, outliers=outliers)
    return rasterize(pts, g, sensor="mound")


def _cone():
    m = CFG.mound
    return syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height, m.ground_z)


def test_rasterize_recovers_surface_despite_noise_and_outliers():
    rng = np.random.default_rng(3)
    grid = _mound_grid(_cone(), rng)
    xg, yg = grid.spec.centres()
    err = np.abs(grid.z - _cone()(xg, yg))
    assert np.median(err) < 0.03
    assert np.percentile(err, 99) < 0.2  # 2 m outliers are gone
    assert grid.coverage > 0.9


def test_mound_volume_matches_truncated_cone():
    rng = np.random.default_rng(4)
    a = assess_mound(_mound_grid(_cone(), rng), CFG.swing_axis_map(), CFG.excavation)
    assert a.volume_total == pytest.approx(CFG.mound.bank_volume(), rel=0.05)
    assert a.max_height == pytest.approx(CFG.mound.height, abs=0.08)
    assert a.has_soil


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_excavation_target_is_on_the_mound_in_reach_below_the_surface(seed):
    rng = np.random.default_rng(seed)
    surface = _cone()
    a = assess_mound(_mound_grid(surface, rng), CFG.swing_axis_map(), CFG.excavation)
    t = a.target
    assert t is not None
    p = CFG.excavation
    ax, ay = CFG.swing_axis_map()
    r = math.hypot(t.x - ax, t.y - ay)
    assert p.reach_min <= r <= p.reach_max
    true_surface = float(surface(np.array(t.x), np.array(t.y)))
    assert t.surface_z == pytest.approx(true_surface, abs=0.06)
    depth = true_surface - t.z
    assert t.z == pytest.approx(0.0, abs=0.06) or p.penetration_depth - 0.06 <= depth <= p.max_penetration_depth + 0.06
    assert p.theta_w_min <= t.theta_w <= p.theta_w_max
    assert 0 < t.offset <= p.drag_length
    # On the machine-facing half of the mound, where one level drag fills the bucket.
    assert t.x < CFG.mound.cx + 0.2
    assert t.expected_volume >= 0.9 * p.bucket_volume
    # The expected cut, integrated independently on the true surface (5 cm samples): the soil above the
    # drag level in the bucket-wide strip from the target towards the machine.
    ux, uy = (t.x - ax) / r, (t.y - ay) / r
    s_along, s_across = np.meshgrid(
        np.arange(0.025, t.offset, 0.05), np.arange(-p.bucket_radius + 0.025, p.bucket_radius, 0.05)
    )
    xs, ys = t.x - ux * s_along - uy * s_across, t.y - uy * s_along + ux * s_across
    true_cut = float(np.clip(surface(xs, ys) - t.z, 0.0, None).sum() * 0.05 * 0.05)
    assert t.expected_volume == pytest.approx(true_cut, rel=0.2)


def test_excavation_target_moves_away_from_a_dug_pit():
    rng = np.random.default_rng(5)
    first = assess_mound(_mound_grid(_cone(), rng), CFG.swing_axis_map(), CFG.excavation).target
    dug = syn.dig_pit(_cone(), first.x, first.y, radius=0.8, depth=1.2)
    second = assess_mound(_mound_grid(dug, rng), CFG.swing_axis_map(), CFG.excavation).target
    assert math.hypot(second.x - first.x, second.y - first.y) > 0.6


def test_target_fields_in_zx200_base_frame_follow_the_base_pose():
    rng = np.random.default_rng(6)
    t = assess_mound(_mound_grid(_cone(), rng), CFG.swing_axis_map(), CFG.excavation).target
    moved = Pose2D(x=t.x - 5.0, y=t.y, yaw=0.0)
    fields = t.record_fields(moved)
    assert fields["position_with_angle"] == 1
    assert (fields["x"], fields["y"], fields["z"]) == pytest.approx((5.0, 0.0, t.z))
    turned = Pose2D(x=t.x, y=t.y - 5.0, yaw=math.pi / 2)  # target straight ahead of a base facing north
    assert t.in_base(turned)[:2] == pytest.approx((5.0, 0.0), abs=1e-9)


def test_depleted_mound_clears_check_mound_flag():
    rng = np.random.default_rng(7)
    m = CFG.mound
    thin = syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, 0.08, m.ground_z)  # a 8 cm skin
    a = assess_mound(_mound_grid(thin, rng, outliers=0.0), CFG.swing_axis_map(), CFG.excavation)
    assert not a.has_soil and a.target is None
    flat = assess_mound(_mound_grid(lambda x, y: np.zeros_like(x), rng), CFG.swing_axis_map(), CFG.excavation)
    assert not flat.has_soil and flat.volume_in_reach < CFG.excavation.min_volume


def test_mound_out_of_reach_is_not_diggable():
    rng = np.random.default_rng(8)
    far = syn.truncated_cone(0.0, 0.0, 1.5, 0.5, 1.0)  # a heap under the machine itself, inside reach_min
    g = GridSpec(-3, -3, 3, 3, 0.1)
    pts = syn.scan(far, (-3, 3), (-3, 3), 10000, rng)
    a = assess_mound(rasterize(pts, g), (0.0, 0.0), CFG.excavation)
    assert a.volume_total > 1.0 and not a.has_soil


def test_no_points_in_region_names_the_sensor():
    with pytest.raises(SensingError, match=r"mound: no point inside"):
        rasterize(np.array([[100.0, 100.0, 0.0]]), CFG.mound_grid, sensor="mound")
    with pytest.raises(SensingError, match=r"vessel: only .* cells measured"):
        rasterize(np.array([[0.0, 0.0, 0.0]]), CFG.vessel_geom.grid_spec(0.1), sensor="vessel")
    with pytest.raises(SensingError, match=r"expected points of shape"):
        rasterize(np.zeros((4, 2)), CFG.mound_grid, sensor="mound")


def _vessel(volume, rng, cx=0.0, was_loaded=False):
    g = CFG.vessel_geom
    spec = g.grid_spec(CFG.resolution)
    surface = syn.vessel_heap(volume, g.inner_length, g.inner_width, cx=cx) if volume > 0 else (lambda x, y: 0 * x)
    pts = syn.scan(surface, (spec.x_min, spec.x_max), (spec.y_min, spec.y_max), 8000, rng, noise=0.02)
    return assess_vessel(rasterize(pts, spec, sensor="vessel"), g, CFG.vessel, was_loaded=was_loaded)


def test_loaded_flag_holds_through_scan_noise_at_the_threshold_and_clears_on_dump():
    rng = np.random.default_rng(21)
    cap = CFG.vessel_geom.capacity
    # the load whose estimate lies at the threshold (the synthetic scan reads ~2.5 % high)
    bias = np.mean([_vessel(0.6 * cap, rng).volume for _ in range(4)]) / (0.6 * cap)
    at_threshold = CFG.vessel.target_fill * cap / bias
    # Without the previous flag, repeated scans of a load at the threshold read loaded and not loaded.
    plain = [_vessel(at_threshold, rng).loaded for _ in range(12)]
    assert any(plain) and not all(plain), plain
    # Once loaded, the same scans keep it loaded (the band is target_fill - loaded_hysteresis).
    flag, held = False, []
    for _ in range(12):
        flag = _vessel(at_threshold, rng, was_loaded=flag).loaded
        held.append(flag)
    assert held[held.index(True):] == [True] * (12 - held.index(True)), held
    # A dump (empty vessel) clears it, and a load clearly below the band does not count as loaded.
    assert not _vessel(0.0, rng, was_loaded=True).loaded
    below = (CFG.vessel.target_fill - CFG.vessel.loaded_hysteresis - 0.05) * cap
    assert not _vessel(below, rng, was_loaded=True).loaded


def test_vessel_volume_and_loaded_flag():
    rng = np.random.default_rng(9)
    cap = CFG.vessel_geom.capacity
    empty = _vessel(0.0, rng)
    assert empty.volume < 0.1 and not empty.loaded
    half = _vessel(0.5 * cap, rng)
    assert half.volume == pytest.approx(0.5 * cap, rel=0.08) and not half.loaded
    full = _vessel(0.9 * cap, rng)
    assert full.volume == pytest.approx(0.9 * cap, rel=0.08) and full.loaded


def test_release_target_goes_to_the_empty_end_of_the_vessel():
    rng = np.random.default_rng(10)
    g = CFG.vessel_geom
    front_heap = _vessel(2.0, rng, cx=1.0)
    x, y, z = front_heap.release_xyz
    assert x < -0.5  # away from the heap at the front
    assert abs(x) <= g.inner_length / 2 - CFG.vessel.wall_margin + 1e-9
    assert abs(y) <= g.inner_width / 2 - CFG.vessel.wall_margin + 1e-9
    assert z >= g.rim_above_floor + CFG.vessel.clearance - 1e-9
    rear_heap = _vessel(2.0, rng, cx=-1.0)
    assert rear_heap.release_xyz[0] > 0.5
    empty = _vessel(0.0, rng)
    assert abs(empty.release_xyz[0]) < 0.6 and abs(empty.release_xyz[1]) < 0.5  # centre when empty


def test_release_in_excavator_frame_and_swing_angle_at_loading_point():
    g = CFG.vessel_geom
    p1 = CFG.points["P1"]
    pose, angle = release_in_excavator(
        (0.0, 0.0, 1.0), p1, CFG.excavator_base, g, CFG.swing_axis_in_base, CFG.vessel.carry_theta_w
    )
    centre = p1.to_map(g.origin_in_base())
    assert (pose["x"], pose["y"]) == pytest.approx((centre[0], centre[1]))  # zx200 base at the map origin
    assert pose["z"] == pytest.approx(g.hinge_xyz[2] + g.floor_above_hinge + 1.0)
    assert pose["position_with_angle"] == 1 and pose["theta_w"] == pytest.approx(CFG.vessel.carry_theta_w)
    sx, sy = CFG.swing_axis_in_base
    assert angle["target_angle"] == pytest.approx(math.atan2(centre[1] - sy, centre[0] - sx))
    # The vessel centre at P1 is within the ZX200's reach (about 9.5 m) and to its left.
    assert math.hypot(centre[0] - sx, centre[1] - sy) < 8.5
    assert 1.2 < angle["target_angle"] < 1.9


def test_arrival_needs_position_heading_stillness_and_hold_time():
    target = Pose2D(1.2, 6.5, 0.0)
    det = ArrivalDetector(target, ArrivalParams(position_tolerance=0.5, yaw_tolerance=math.radians(10), max_speed=0.05,
                                                hold_s=0.5, speed_window_s=0.5))
    # Approaching in reverse at 0.5 m/s: never arrived while moving.
    flags = [det.update(t * 0.1, Pose2D(1.2 + 3.0 - 0.05 * t, 6.5, 0.0)) for t in range(60)]
    assert not any(flags)
    # Stopped at 0.2 m from the point: the flag rises after speed_window_s + hold_s.
    t0 = 6.0
    stopped = [det.update(t0 + k * 0.1, Pose2D(1.4, 6.5, 0.02)) for k in range(25)]
    assert not stopped[5] and stopped[-1]
    first_true = stopped.index(True)
    assert 0.9 <= first_true * 0.1 <= 1.25
    # Wrong heading (arrived forwards instead of in reverse) never raises it.
    det2 = ArrivalDetector(target, det.params)
    assert not any(det2.update(k * 0.1, Pose2D(1.2, 6.5, math.pi)) for k in range(30))
    # Leaving drops it at once.
    assert not det.update(t0 + 2.6, Pose2D(1.6, 6.5, 0.0))


def test_arrival_flag_does_not_flicker_with_millimetre_jitter_at_50_hz():
    """A standing machine's contact jitter (1 mm at 50 Hz = 0.05 m/s between samples) keeps the flag up."""
    target = Pose2D(1.2, 6.5, 0.0)
    det = ArrivalDetector(target, ArrivalParams(position_tolerance=0.5, yaw_tolerance=math.radians(10), max_speed=0.05,
                                                hold_s=0.5, speed_window_s=0.5))
    rng = np.random.default_rng(3)
    flags = [det.update(k * 0.02, Pose2D(1.3 + rng.uniform(-1e-3, 1e-3), 6.5 + rng.uniform(-1e-3, 1e-3), 0.0))
             for k in range(300)]
    first = flags.index(True)
    assert 0.9 <= first * 0.02 <= 1.1, first
    assert all(flags[first:]), "flag fell while the machine stood still"
    # Creeping at 0.1 m/s (e.g. sliding) keeps it down.
    det2 = ArrivalDetector(target, det.params)
    assert not any(det2.update(k * 0.02, Pose2D(1.0 + 0.002 * k, 6.5, 0.0)) for k in range(150))


def test_bad_parameters_name_the_key(tmp_path):
    from tms_common.config import config_path
    from tms_common.errors import ConfigError

    good = config_path("tms_sp", "sensing.yaml").read_text()
    bad = tmp_path / "sensing.yaml"
    for old, new, message in (
        ("reach_min: 4.0", "reach_min: 9.5", r"sensing.yaml:\d+: excavation: ExcavationParams: reach_min 9.5"),
        ("point: P1", "point: P9", r"sensing.yaml:\d+: arrival.point: 'P9' is not a pose"),
        (
            "  min_cut: 0.2",
            "  min_cut: 0.2\n  bucket_radius: 0.5",
            r"sensing.yaml:\d+: excavation.bucket_radius: unknown key",
        ),
        ("depth_steps: 5", "depth_steps: five", r"sensing.yaml:\d+: excavation.depth_steps: expected an integer"),
        (
            "carriers: [ic120]",
            "carriers: [ic120, nobody]",
            r"sensing.yaml:\d+: carriers: 'nobody': .*no machine 'nobody'",
        ),
        (
            "carriers: [ic120]",
            "carriers: [zx120]",
            r"sensing.yaml:\d+: carriers: 'zx120': .*is a excavator, expected a crawler_dump",
        ),
        ("excavator: zx200 ", "excavator: ic120 ", r"sensing.yaml:\d+: excavator: 'ic120': .*expected a excavator"),
    ):
        assert old in good, old
        bad.write_text(good.replace(old, new))
        with pytest.raises(ConfigError, match=message):
            load_sensing_config(sensing=bad)


def test_release_spot_holds_against_scan_noise_and_moves_for_a_real_heap():
    g = CFG.vessel_geom
    spec = g.grid_spec(CFG.resolution)
    rng = np.random.default_rng(12)

    def grid(surface):
        pts = syn.scan(surface, (spec.x_min, spec.x_max), (spec.y_min, spec.y_max), 8000, rng, noise=0.02)
        return rasterize(pts, spec, sensor="vessel")

    even = lambda x, y: 0.2 + 0 * x  # noqa: E731 - the plant's even layer of load
    free = [assess_vessel(grid(even), g, CFG.vessel).release_xyz[:2] for _ in range(12)]
    assert max(np.hypot(x - free[0][0], y - free[0][1]) for x, y in free) > 0.2, "noise alone should move the argmin"
    spot = free[0]
    held = [assess_vessel(grid(even), g, CFG.vessel, previous_xy=spot).release_xyz[:2] for _ in range(12)]
    assert all(np.hypot(x - spot[0], y - spot[1]) < 0.11 for x, y in held), held
    # a heap where the spot was (soil landed there): the release moves away from it
    heap = lambda x, y: 0.2 + 0.3 * np.exp(-((x - spot[0]) ** 2 + (y - spot[1]) ** 2) / 0.3)  # noqa: E731
    moved = assess_vessel(grid(heap), g, CFG.vessel, previous_xy=spot).release_xyz[:2]
    assert np.hypot(moved[0] - spot[0], moved[1] - spot[1]) > 0.5, (moved, spot)


def test_excavation_target_holds_against_scan_noise_and_moves_once_dug():
    rng = np.random.default_rng(13)
    axis = CFG.swing_axis_map()
    free = [assess_mound(_mound_grid(_cone(), rng, noise=0.02), axis, CFG.excavation).target for _ in range(12)]
    assert max(math.hypot(t.x - free[0].x, t.y - free[0].y) for t in free) > 0.2, (
        "noise alone should move the best cell"
    )
    spot = (free[0].x, free[0].y)
    held = [assess_mound(_mound_grid(_cone(), rng, noise=0.02), axis, CFG.excavation, previous_xy=spot).target
            for _ in range(12)]
    assert all(math.hypot(t.x - spot[0], t.y - spot[1]) < 0.01 for t in held), [(t.x, t.y) for t in held]
    # the target cell dug out: the target moves away from it
    dug = syn.dig_pit(_cone(), spot[0], spot[1], radius=0.8, depth=1.2)
    moved = assess_mound(_mound_grid(dug, rng, noise=0.02), axis, CFG.excavation, previous_xy=spot).target
    assert math.hypot(moved.x - spot[0], moved.y - spot[1]) > 0.6


def test_check_mound_flag_stays_down_through_noise_at_the_threshold():
    e, spec = CFG.excavation, CFG.mound_grid
    ax, ay = CFG.swing_axis_map()
    m = CFG.mound
    d = math.hypot(m.cx - ax, m.cy - ay)
    px, py = ax + (m.cx - ax) / d * 5.5, ay + (m.cy - ay) / d * 5.5  # 5.5 m out towards the mound: in reach
    xg, yg = spec.centres()
    block = np.hypot(xg - px, yg - py) <= 0.6

    def grid(volume):  # a level block of soil holding ``volume`` in reach, on bare ground
        return HeightGrid(spec, np.where(block, m.ground_z + volume / (block.sum() * spec.cell_area), m.ground_z), 1.0)

    just_above = grid(e.min_volume + 0.5 * e.depleted_hysteresis)
    assert assess_mound(just_above, (ax, ay), e).has_soil  # still diggable while it was
    assert not assess_mound(just_above, (ax, ay), e, was_depleted=True).has_soil  # noise does not revive it
    assert assess_mound(grid(e.min_volume + 1.5 * e.depleted_hysteresis), (ax, ay), e, was_depleted=True).has_soil
