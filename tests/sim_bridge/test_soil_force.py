"""The soil-tool force (Reece's earthmoving equation, McKyes' factors) against hand computations and its contract.

The hand computations below write McKyes' factors out term by term in scalar ``math`` and search the failure angle
on a 0.01-degree grid, independently of the module's vectorised grid-and-parabola search.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from sim_bridge.errors import SimConfigError
from sim_bridge.soil_force import (
    GRAVITY,
    SoilParams,
    fee_force,
    load_soil_types,
    rake_range,
    surcharge_pressure,
    tool_force,
)
from tms_common.config import config_path

SOILS = load_soil_types()
SANDY_LOAM = SOILS["sandy_loam"]
DEG = math.radians


def _cot(x: float) -> float:
    return math.cos(x) / math.sin(x)


def _hand(soil: SoilParams, alpha: float, d: float, w: float, q: float = 0.0, v: float = 0.0):
    """(beta*, P, H on the soil, V on the soil) by McKyes' formulas, one beta at a time."""
    phi, delta = soil.phi, soil.delta
    best = (math.inf, 0.0)
    for k in range(1, 9000):
        beta = DEG(k * 0.01)
        den = math.cos(alpha + delta) + math.sin(alpha + delta) * _cot(beta + phi)
        if den <= 0.0:
            continue
        n_gamma = (_cot(alpha) + _cot(beta)) / (2.0 * den)
        n_c = (1.0 + _cot(beta) * _cot(beta + phi)) / den
        n_q = (_cot(alpha) + _cot(beta)) / den
        n_a = (1.0 - _cot(alpha) * _cot(beta + phi)) / den
        # the speed term as the Lunar-Excavation-Simulation McKyesModel writes it (a different algebraic form)
        n_v = (math.tan(beta) + _cot(beta + phi)) / (1.0 + math.tan(beta) * _cot(alpha)) / den
        p = (soil.unit_weight * d * d * n_gamma + soil.cohesion * d * n_c + (q + soil.surcharge) * d * n_q
             + soil.adhesion * d * n_a + soil.density * v * v * d * n_v) * w
        best = min(best, (p, beta))
    p, beta = best
    h = p * math.sin(alpha + delta) + soil.adhesion * d * w * _cot(alpha)
    v_soil = p * math.cos(alpha + delta) - soil.adhesion * d * w
    return beta, p, h, v_soil


def test_sandy_loam_reference_case_by_hand():
    """gamma g 15 kN/m3, c 10 kPa, phi 35, delta 22, alpha 60, d 0.3 m: beta* about 31 deg, P about 12 kN per m."""
    alpha, d = DEG(60.0), 0.3
    beta_h, p_h, h_h, v_h = _hand(SANDY_LOAM, alpha, d, 1.0)
    f = fee_force(SANDY_LOAM, alpha, d, 1.0)
    print(f"sandy loam alpha 60 d 0.3 w 1: hand beta* {math.degrees(beta_h):.2f} deg P {p_h:.0f} N; "
          f"module beta* {math.degrees(f.beta[0]):.2f} deg P {f.passive[0]:.0f} N H {f.horizontal[0]:.0f} N "
          f"V {f.vertical[0]:.0f} N")
    assert abs(math.degrees(beta_h) - 31.0) < 1.0 and abs(p_h - 12e3) / 12e3 < 0.05  # the published sanity case
    assert abs(f.beta[0] - beta_h) < DEG(0.1)
    assert f.passive[0] == pytest.approx(p_h, rel=1e-4)
    assert f.horizontal[0] == pytest.approx(h_h, rel=1e-4)
    assert f.vertical[0] == pytest.approx(-v_h, rel=1e-4)  # the soil pulls the tool down (alpha + delta < 90)
    assert f.vertical[0] < 0.0


@pytest.mark.parametrize("case", [
    dict(soil="clay_loam", alpha=45.0, d=0.25, w=1.2, q=0.0, v=0.0, adhesion=15e3),
    dict(soil="agx_dirt_1", alpha=75.0, d=0.4, w=1.0, q=3e3, v=0.8, adhesion=0.0),
    dict(soil="loam", alpha=100.0, d=0.15, w=3.1, q=0.0, v=1.5, adhesion=5e3),
])
def test_every_term_against_the_hand_computation(case):
    """Adhesion, surcharge and the speed term, including a rake past vertical (a forward-leaning blade)."""
    base = SOILS[case["soil"]]
    soil = SoilParams(base.unit_weight, base.cohesion, base.phi, base.delta, adhesion=case["adhesion"])
    alpha = DEG(case["alpha"])
    beta_h, p_h, h_h, v_h = _hand(soil, alpha, case["d"], case["w"], case["q"], case["v"])
    f = fee_force(soil, alpha, case["d"], case["w"], surcharge=case["q"], speed=case["v"])
    print(f"{case}: hand beta* {math.degrees(beta_h):.2f} P {p_h:.0f}; module beta* "
          f"{math.degrees(f.beta[0]):.2f} P {f.passive[0]:.0f} H {f.horizontal[0]:.0f} V {f.vertical[0]:.0f}")
    assert abs(f.beta[0] - beta_h) < DEG(0.15)
    assert f.passive[0] == pytest.approx(p_h, rel=1e-4)
    assert f.horizontal[0] == pytest.approx(h_h, rel=1e-4)
    assert f.vertical[0] == pytest.approx(-v_h, rel=1e-4)


@pytest.mark.parametrize("name", sorted(SOILS))
def test_force_rises_with_depth(name):
    """0.1, 0.2, 0.4 m: rising, and faster than linearly (the gamma term is quadratic in d, the others linear)."""
    f = fee_force(SOILS[name], DEG(60.0), [0.1, 0.2, 0.4], 1.0)
    print(f"{name}: horizontal per m width at d 0.1/0.2/0.4 m: "
          + " / ".join(f"{h / 1e3:.2f}" for h in f.horizontal) + " kN")
    assert np.all(np.diff(f.horizontal) > 0.0)
    ratios = f.horizontal[1:] / f.horizontal[:-1]
    assert np.all(ratios > 2.0) and np.all(ratios <= 4.0 + 1e-9)


@pytest.mark.parametrize("name", ["loose_sand", "dense_sand_gravel"])
def test_cohesionless_soil_scales_with_depth_squared(name):
    depths = np.array([0.1, 0.2, 0.4])
    f = fee_force(SOILS[name], DEG(55.0), depths, 1.0)
    np.testing.assert_allclose(f.horizontal / f.horizontal[0], (depths / depths[0]) ** 2, rtol=1e-9)
    np.testing.assert_allclose(f.vertical / f.vertical[0], (depths / depths[0]) ** 2, rtol=1e-9)
    assert np.ptp(f.beta) < 1e-12  # without c, c_a, q and v the failure angle does not depend on d


def test_zero_force_out_of_the_soil():
    f = fee_force(SANDY_LOAM, DEG(60.0), [0.0, -0.2, 0.2], [1.0, 1.0, 1.0], surcharge=5e3, speed=1.0)
    assert np.all(f.horizontal[:2] == 0.0) and np.all(f.vertical[:2] == 0.0) and np.all(f.passive[:2] == 0.0)
    assert f.horizontal[2] > 0.0
    # a rake without a failure wedge does not matter for a tool out of the soil
    assert np.all(fee_force(SANDY_LOAM, DEG(170.0), 0.0, 1.0).horizontal == 0.0)
    out = tool_force(SANDY_LOAM, [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], DEG(60.0), [0.0, 0.3], 1.0)
    assert np.all(out == 0.0)  # the first is out of the soil, the second at rest


@pytest.mark.parametrize("heading_deg", [0.0, 37.0, 135.0, -90.0, 200.0])
def test_force_opposes_the_horizontal_motion(heading_deg):
    h = DEG(heading_deg)
    speed = 0.5
    vel = np.array([speed * math.cos(h), speed * math.sin(h), -0.1])  # sinking a little as it cuts
    force = tool_force(SANDY_LOAM, vel, DEG(60.0), 0.3, 1.2)[0]
    ref = fee_force(SANDY_LOAM, DEG(60.0), 0.3, 1.2, speed=speed)
    horizontal = force[:2]
    assert np.linalg.norm(horizontal) == pytest.approx(ref.horizontal[0], rel=1e-12)
    # antiparallel to the horizontal velocity
    assert np.dot(horizontal, vel[:2]) == pytest.approx(-np.linalg.norm(horizontal) * speed, rel=1e-12)
    assert force[2] == pytest.approx(ref.vertical[0]) and force[2] < 0.0
    # a rake past 90 - delta: the soil's push on the tool turns upward
    steep = tool_force(SANDY_LOAM, vel, DEG(95.0), 0.3, 1.2)[0]
    assert steep[2] > 0.0 and np.dot(steep[:2], vel[:2]) < 0.0


def test_slow_tools_ramp_to_zero():
    full = tool_force(SANDY_LOAM, [0.02, 0.0, 0.0], DEG(60.0), 0.3, 1.0)[0]
    half = tool_force(SANDY_LOAM, [0.01, 0.0, 0.0], DEG(60.0), 0.3, 1.0)[0]
    np.testing.assert_allclose(half, 0.5 * full * (fee_force(SANDY_LOAM, DEG(60.0), 0.3, 1.0, speed=0.01).passive
                                                    / fee_force(SANDY_LOAM, DEG(60.0), 0.3, 1.0, speed=0.02).passive),
                               rtol=1e-12)


def test_vectorised_equals_the_scalar_loop():
    rng = np.random.default_rng(3)
    n = 25
    soil = SOILS["agx_dirt_1"]
    alpha = rng.uniform(DEG(20.0), DEG(110.0), n)
    depth = rng.uniform(-0.1, 0.6, n)
    width = rng.uniform(0.5, 3.5, n)
    q = rng.uniform(0.0, 8e3, n)
    vel = rng.normal(0.0, 0.6, (n, 3))
    vec = fee_force(soil, alpha, depth, width, surcharge=q, speed=np.abs(vel[:, 0]))
    vec_tool = tool_force(soil, vel, alpha, depth, width, surcharge=q)
    for i in range(n):
        one = fee_force(soil, float(alpha[i]), float(depth[i]), float(width[i]), surcharge=float(q[i]),
                        speed=abs(float(vel[i, 0])))
        for field in ("horizontal", "vertical", "passive", "beta"):
            assert getattr(one, field)[0] == pytest.approx(getattr(vec, field)[i], rel=1e-12, abs=1e-9)
        np.testing.assert_allclose(tool_force(soil, vel[i], float(alpha[i]), float(depth[i]), float(width[i]),
                                              surcharge=float(q[i]))[0], vec_tool[i], rtol=1e-12, atol=1e-9)
    assert np.count_nonzero(vec.horizontal) == np.count_nonzero(depth > 0.0) > 0


def test_surcharge_raises_the_force_as_a_heap_would():
    heap = surcharge_pressure(SANDY_LOAM, 0.5)
    assert float(heap) == pytest.approx(SANDY_LOAM.unit_weight * 0.5)
    bare = fee_force(SANDY_LOAM, DEG(60.0), 0.3, 1.0)
    loaded = fee_force(SANDY_LOAM, DEG(60.0), 0.3, 1.0, surcharge=heap)
    assert loaded.horizontal[0] > 1.5 * bare.horizontal[0]


def test_a_rake_without_a_failure_wedge_names_the_tool():
    with pytest.raises(ValueError, match=r"^fee_force: tool 1: rake 130\.0 deg has no failure wedge in soil "
                                         r"sandy_loam; expected 0 < rake < 121\.0 deg$"):
        fee_force(SANDY_LOAM, [DEG(60.0), DEG(130.0)], [0.2, 0.2], 1.0)
    with pytest.raises(ValueError, match=r"^fee_force: tool 0: width must be finite and >= 0"):
        fee_force(SANDY_LOAM, DEG(60.0), 0.2, -1.0)
    with pytest.raises(ValueError, match=r"^fee_force: tool 2: depth must be finite, got nan$"):
        fee_force(SANDY_LOAM, DEG(60.0), [0.2, 0.1, math.nan], 1.0)
    with pytest.raises(ValueError, match=r"^fee_force: tool 1: rake must be finite, got inf$"):
        fee_force(SANDY_LOAM, [DEG(60.0), math.inf], [0.2, 0.0], 1.0)  # even out of the soil
    with pytest.raises(ValueError, match=r"^fee_force: tool 0: speed must be finite and >= 0, got -0\.5$"):
        fee_force(SANDY_LOAM, DEG(60.0), 0.2, 1.0, speed=-0.5)
    # just inside the limit the force is large but finite, with the wedge nearly flat
    lo, hi = rake_range(SANDY_LOAM)
    near = fee_force(SANDY_LOAM, [hi - 1e-6, DEG(60.0)], 0.2, 1.0)
    assert np.all(np.isfinite(near.horizontal)) and near.horizontal[0] > 5.0 * near.horizontal[1]
    assert near.beta[0] < DEG(2.0)


def test_soil_types_are_cited_and_in_si_units():
    assert set(SOILS) == {"sandy_loam", "loam", "clay_loam", "loose_sand", "dense_sand_gravel", "agx_dirt_1"}
    assert all(s.source for s in SOILS.values())
    assert SANDY_LOAM.unit_weight == 15e3 and SANDY_LOAM.cohesion == 10e3
    assert SANDY_LOAM.phi == pytest.approx(DEG(35.0)) and SANDY_LOAM.delta == pytest.approx(DEG(22.0))
    assert SOILS["agx_dirt_1"].density == pytest.approx(1474.0)
    assert SOILS["agx_dirt_1"].unit_weight == pytest.approx(1474.0 * GRAVITY)


def _line_of(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.mark.parametrize(("edit", "needle", "problem"), [
    (("cohesion_kpa: 20.0", "cohesion_kp: 20.0"), "cohesion_kp:", r"soil_types\.loam\.cohesion_kp: unknown key"),
    (("    friction_deg: 10.0", "    friction_deg: -10.0"), "    friction_deg: -10.0",
     r"soil_types\.clay_loam\.friction_deg: must be >= 1\.0, got -10\.0"),
    (("density_kg_m3: 1474.0", "density_kg_m3: 1474.0\n    unit_weight_kn_m3: 14.5"), "agx_dirt_1:",
     r"soil_types\.agx_dirt_1: give exactly one of unit_weight_kn_m3 and density_kg_m3"),
])
def test_a_bad_soil_types_yaml_is_one_line_naming_file_and_line(tmp_path, edit, needle, problem):
    text = config_path("sim", "soil_types.yaml").read_text(encoding="utf-8")
    assert edit[0] in text
    bad = text.replace(edit[0], edit[1], 1)
    path = tmp_path / "soil_types.yaml"
    path.write_text(bad, encoding="utf-8")
    with pytest.raises(SimConfigError) as exc:
        load_soil_types(path)
    message = str(exc.value)
    print(message)
    assert "\n" not in message
    assert re.fullmatch(rf"{re.escape(str(path))}:{_line_of(bad, needle)}: {problem}.*", message)
