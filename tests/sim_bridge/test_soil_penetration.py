"""The bucket pressed into the ground: bearing capacity (Terzaghi/Meyerhof) after a Winkler ramp, in the plant.

No ROS: :func:`sim_bridge.soil_force.bearing_capacity` and :func:`penetration_force` against hand computations, and
the plant core in-process with ``soil.penetration`` on and off (the ZX200 swung away from the mound, its bucket
lowered onto flat ground by the boom at a fixed pilot, then held).
"""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType

import mujoco
import numpy as np
import pytest

from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.plant import Plant
from sim_bridge.soil_force import (
    SoilParams,
    bearing_capacity,
    bearing_factors,
    load_soil_types,
    penetration_force,
)
from tms_common.config import config_path

SOILS = load_soil_types()
DEG = math.radians
#: the bucket over flat ground: swung a quarter turn away from the mound (east of the machine), tip 1.3 m up,
#: its pin->tip line 86 degrees below horizontal (edge down)
FRONT = {"swing_joint": -math.pi / 2, "boom_joint": -0.6, "arm_joint": 1.5, "bucket_joint": 0.6}
BOOM_DOWN_PILOT = 1.5  # [MPa] boom down (as tests/bench/bench_piston.py's bury_bucket)


def _hand_q_ult(soil: SoilParams, depth: float, b: float, w: float) -> float:
    """Terzaghi's superposition with Meyerhof's (1963) factors and shape factors, term by term."""
    phi, c, gamma = soil.phi, soil.cohesion, soil.unit_weight
    k_p = math.tan(DEG(45.0) + phi / 2) ** 2
    n_q = math.exp(math.pi * math.tan(phi)) * k_p
    n_c = (n_q - 1.0) / math.tan(phi)
    n_gamma = (n_q - 1.0) * math.tan(1.4 * phi)
    s_c = 1.0 + 0.2 * k_p * b / w
    s_q = 1.0 + 0.1 * k_p * b / w if phi >= DEG(10.0) else 1.0 + 0.1 * k_p * b / w * phi / DEG(10.0)
    return c * n_c * s_c + gamma * depth * n_q * s_q + 0.5 * gamma * b * n_gamma * s_q


def test_bearing_factors_match_meyerhofs_table():
    """Meyerhof's (1963) tabulated factors: phi 30 deg N_c 30.14, N_q 18.40, N_gamma 15.67; phi 40 deg 75.31,
    64.20, 93.69; and Prandtl's N_c -> 2 + pi as phi -> 0."""
    for phi, table in ((30.0, (30.14, 18.40, 15.67)), (40.0, (75.31, 64.20, 93.69))):
        got = bearing_factors(DEG(phi))
        for g, t in zip(got, table, strict=True):
            assert float(g) == pytest.approx(t, abs=0.01)
    assert float(bearing_factors(1e-6)[0]) == pytest.approx(2.0 + math.pi, abs=1e-4)
    with pytest.raises(ValueError, match="phi"):
        bearing_factors(DEG(61.0))


@pytest.mark.parametrize("name", ["agx_dirt_1", "clay_loam", "loose_sand"])
def test_bearing_capacity_by_hand(name):
    soil = SOILS[name]
    depths = np.array([0.0, 0.1, 0.45])
    got = bearing_capacity(soil, depths, 0.3, 1.0)
    for d, g in zip(depths, got, strict=True):
        assert g == pytest.approx(_hand_q_ult(soil, float(d), 0.3, 1.0), rel=1e-12)
    # agx_dirt_1 at the surface, B 0.3 m x L 1.0 m, written out: c N_c s_c + 0.5 gamma B N_gamma s_gamma
    if name == "agx_dirt_1":
        gamma = 1474.0 * 9.81
        hand = 2.1e3 * 75.31 * (1 + 0.2 * 4.599 * 0.3) + 0.5 * gamma * 0.3 * 93.69 * (1 + 0.1 * 4.599 * 0.3)
        assert got[0] == pytest.approx(hand, rel=2e-4)


def test_penetration_force_is_a_winkler_ramp_capped_at_the_capacity():
    soil = SOILS["agx_dirt_1"]
    b, w = 0.3, 1.0
    area = b * w
    cap0 = float(bearing_capacity(soil, 0.0, b, w)[()]) * area
    yield_at = cap0 / (soil.subgrade_modulus * area)  # about 1 cm
    f = penetration_force(soil, [-0.01, 0.5 * yield_at, 2.0 * yield_at], 0.0, b, w)
    assert f.force[0] == 0.0 and f.excess[0] == 0.0
    assert f.force[1] == pytest.approx(soil.subgrade_modulus * area * 0.5 * yield_at)
    assert f.excess[1] == 0.0
    # beyond the yield the force is the capacity at the depth the tool has reached, and the excess the overshoot
    cap = float(bearing_capacity(soil, 2.0 * yield_at, b, w)[()]) * area
    assert f.force[2] == pytest.approx(cap) and f.capacity[2] == pytest.approx(cap)
    assert f.excess[2] == pytest.approx(2.0 * yield_at - cap / (soil.subgrade_modulus * area))
    with pytest.raises(ValueError, match="subgrade_modulus"):
        penetration_force(dataclasses.replace(soil, subgrade_modulus=None), 0.01, 0.0, b, w)


def test_penetration_is_off_in_the_shipped_plants_and_a_misspelt_key_is_refused(tmp_path):
    for f in sorted(config_path("sim").glob("*plant*.yaml")):
        assert load_plant(f).soil.penetration is False, f
    text = config_path("sim", "paper_plant.yaml").read_text()
    bad = tmp_path / "plant.yaml"
    bad.write_text(text.replace("  dump_radius: 1.2", "  penetraton: true\n  dump_radius: 1.2"))
    with pytest.raises(SimConfigError, match="penetraton"):
        load_plant(bad)
    on = tmp_path / "on.yaml"
    on.write_text(text.replace("  dump_radius: 1.2", "  penetration: true\n  dump_radius: 1.2"))
    assert load_plant(on).soil.penetration is True


def _plant(penetration: bool, soil: str | None = None) -> Plant:
    spec = load_plant(config_path("sim", "paper_plant.yaml"))
    pm = spec.machines[spec.excavator]
    machines = dict(spec.machines)
    machines[spec.excavator] = dataclasses.replace(pm, start_joints=MappingProxyType({**pm.start_joints, **FRONT}))
    cutting = SOILS[soil] if soil else spec.soil.cutting
    return Plant(dataclasses.replace(spec, machines=MappingProxyType(machines),
                                     soil=dataclasses.replace(spec.soil, penetration=penetration, cutting=cutting)))


def _press(plant: Plant, push_s: float = 5.0, hold_s: float = 3.0) -> float:
    """Boom down at BOOM_DOWN_PILOT for ``push_s``, then the pilot held ``hold_s`` more; the tip's depth below the
    original ground [m]."""
    zx = plant.excavator
    x, y, _ = plant.bucket_tip()
    assert plant.ground.height(x, y) == plant.spec.soil.ground_z  # flat ground under the bucket
    for _ in range(round((push_s + hold_s) / plant.dt)):
        zx.set_front_pilot({"swing_joint": 0.0, "boom_joint": BOOM_DOWN_PILOT, "arm_joint": 0.0, "bucket_joint": 0.0})
        plant.step()
    return plant.spec.soil.ground_z - plant.bucket_tip()[2]


def _cylinders_vertical_at_tip(plant: Plant) -> float:
    """The vertical force [N, up on the tip] that balances the boom joint's drive torque and the front's weight
    about it at rest: -(qfrc_actuator - qfrc_bias) / (dz_tip / dq_boom). Every other force on the front (arm and
    bucket cylinders, the four-bar's constraint) is internal to what the boom joint turns."""
    m, d = plant.model.model, plant.model.data
    dof = plant.model.dof(f"{plant.spec.excavator}_boom_joint")
    jac = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jac, None, plant.model.tip_site)
    return float(-(d.qfrc_actuator[dof] - d.qfrc_bias[dof]) / jac[2, dof])


def test_a_bucket_pressed_on_flat_ground_rests_on_the_soils_bearing_and_sinks_without_it():
    on = _plant(True)
    v0 = on.total_volume()
    depth_on = _press(on)
    tip_speed = on.tip_speed
    balance = _cylinders_vertical_at_tip(on)
    soil = on.spec.soil.cutting
    b, w = on.spec.soil.penetration_breadth, on.excavator.bucket.width
    x, y, z = on.bucket_tip()
    delta = on.ground.height(x, y) - z
    law = penetration_force(soil, delta, on.spec.soil.ground_z - z, b, w)
    print(f"\nON: tip {100 * depth_on:.2f} cm below the ground ({100 * delta:.2f} cm into the soil under it), at "
          f"{tip_speed:.4f} m/s; soil bearing {on.press_force / 1e3:.1f} kN (capacity {on.press_capacity / 1e3:.1f} "
          f"kN), cylinders + weight at the tip {balance / 1e3:.1f} kN; boom cylinder {on.drives.force[1] / 1e3:.0f} "
          f"kN; displaced {on.press_displaced:.5f} m^3, bucket {on.soil.bucket:.5f} m^3")
    off = _plant(False)
    depth_off = _press(off)
    print(f"OFF: tip {100 * depth_off:.1f} cm below the ground, bucket {off.soil.bucket:.3f} m^3")
    assert tip_speed < 0.01  # at rest
    assert 0.0 < depth_on < 0.05  # comes to rest a few centimetres in
    assert on.press_force > 0.0 and on.press_force == pytest.approx(balance, rel=0.10)
    assert on.press_force == pytest.approx(float(law.force[()]), rel=0.05)  # the plant's law is the function's
    assert depth_off > depth_on + 0.3  # without the bearing the same push sinks the bucket through the ground
    assert abs(on.total_volume() - v0) <= 1e-6 * v0


def test_a_push_beyond_the_capacity_sinks_until_the_overburden_carries_it():
    """In loose sand (bearing about 12 kN at the surface for the 0.3 m x 1 m contact) the same push sinks the bucket
    until q_ult(D) B w carries it; the soil it displaces is heaved beside the bucket (volume conserved)."""
    plant = _plant(True, "loose_sand")
    v0 = plant.total_volume()
    depth = _press(plant)
    print(f"\nloose sand: tip {100 * depth:.1f} cm below the ground, bearing {plant.press_force / 1e3:.1f} kN of "
          f"capacity {plant.press_capacity / 1e3:.1f} kN, displaced {plant.press_displaced:.4f} m^3")
    assert plant.press_displaced > 0.0
    assert depth > 0.1
    assert plant.press_force <= plant.press_capacity
    # a metre down, the passive wedge's resistance is Coulomb friction on the front's joints (Plant._loads): at rest
    # it carries part of the push, at most its friction torque on the boom joint over dz_tip / dq_boom
    m, d = plant.model.model, plant.model.data
    dof = plant.model.dof(f"{plant.spec.excavator}_boom_joint")
    jac = np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jac, None, plant.model.tip_site)
    friction = m.dof_frictionloss[dof] / abs(jac[2, dof])
    balance = _cylinders_vertical_at_tip(plant)
    print(f"cylinders + weight at the tip {balance / 1e3:.1f} kN, the wedge's friction up to {friction / 1e3:.1f} kN")
    assert abs(plant.press_force - balance) <= friction + 0.02 * balance
    assert abs(plant.total_volume() - v0) <= 1e-6 * v0
