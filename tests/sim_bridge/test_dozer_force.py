"""The D37PXi's blade meets the soil's resistance and its tracks slip under it (pure plant: no ROS, no CAN).

A plant of the dozer alone (``experiment: none``) on the kinds site's flat ground, facing east along y = -10. A slab
of soil ``depth`` thick stands ahead of the blade, whose edge is held at ground level (lift 0): the blade cuts the
slab's full height. Checked: the resistance (Reece/McKyes wedge + friction of the pushed pile) rises with depth, the
load slip is the one of Wong's track equation for that resistance and the ground speed falls with it; a slab deeper
than the tracks can push stalls the dozer while its tracks keep running; with the blade out of the soil (or backing
up) the dozer moves at the track speed less the constant slip, as before; the soil's volume is conserved; a dozer
without its traction figures in ``physics:`` is refused.
Run with ``-s`` to see the figures.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.physics import G
from sim_bridge.plant import Plant
from sim_bridge.profiles.dozer import DozerPlantProfile
from sim_bridge.soil_force import fee_force
from tms_common.config import config_path

TRACK = 0.5  # [m/s] commanded track speed
Y0 = -10.0  # the dozer's lane, away from the site's mound


def _plant(tmp_path: Path) -> Plant:
    base = config_path("sim", "kinds_plant.yaml").read_text()
    site = base[base.index("site: site.yaml"):].split("initial_poses:")[0]
    path = tmp_path / "plant.yaml"
    path.write_text("machines: {d37pxi: machines/d37pxi.yaml}\nexperiment: none\n"
                    f"initial_poses: {{d37pxi: [-14.0, {Y0}, 0.0]}}\n" + site + base[base.index("soil:"):])
    return Plant(load_plant(path))


def _settle_blade(plant: Plant, lift: float) -> None:
    dz = plant.dozers["d37pxi"]
    dz.set_lift_target(lift)
    for _ in range(100):
        plant.step()


def _slab(plant: Plant, x0: float, depth: float, length: float = 8.0) -> None:
    """Raise the ground by ``depth`` over x0 .. x0 + length, 2 m either side of the lane."""
    g = plant.ground
    cols = (g.xs >= x0) & (g.xs <= x0 + length)
    rows = abs(g.ys - Y0) <= 2.0
    g.h[rows[:, None] & cols[None, :]] += depth
    g.version += 1


def _f_max(plant: Plant) -> float:
    """Traction limit [N]: the YAML's coefficient x the description's masses x g."""
    dz, phys = plant.dozers["d37pxi"], plant.spec.machines["d37pxi"].physics
    return phys.traction_coefficient * sum(dz.description.masses.values()) * G


def _thrust(plant: Plant, slip: float) -> float:
    """Wong's thrust of a uniform-pressure track at ``slip`` from the YAML's figures, written out again."""
    phys = plant.spec.machines["d37pxi"].physics
    x = slip * phys.track_contact_length_m / phys.shear_modulus_m
    return _f_max(plant) * (1.0 - (1.0 - math.exp(-x)) / x)


def _push(plant: Plant, depth: float, into: float) -> dict[str, float]:
    """Drive at TRACK into a slab ``depth`` thick until the edge is ``into`` [m] past its face (or 20 s); the figures
    there, with the resistance of the step before (the tracks see it one step late)."""
    dz = plant.dozers["d37pxi"]
    face = plant.blade_edge("d37pxi")[0] + 0.5
    _slab(plant, face, depth)
    before = plant.total_volume()
    dz.set_track_speeds(TRACK, TRACK)
    odometry = ground = 0.0
    x_start = dz.base.x
    for _ in range(2000):
        drawbar = plant.blade_force["d37pxi"]
        plant.step()
        odometry += 0.5 * (dz.base.vl + dz.base.vr) * plant.dt
        if plant.blade_edge("d37pxi")[0] >= face + into:
            break
    ground = dz.base.x - x_start
    edge = plant.blade_edge("d37pxi")
    return {"depth": depth + plant.spec.soil.ground_z - edge[2], "resistance": drawbar, "slip": dz.base.load_slip,
            "v": dz.base.v, "track": 0.5 * (dz.base.vl + dz.base.vr), "load": plant.soil.blades["d37pxi"],
            "odometry": odometry, "ground": ground, "volume_error": plant.total_volume() - before}


def test_blade_resistance_rises_with_depth_and_slows_the_dozer(tmp_path: Path) -> None:
    rows = []
    for depth in (0.05, 0.15, 0.3):
        plant = _plant(tmp_path)
        _settle_blade(plant, 0.0)
        r = _push(plant, depth, into=1.0)
        dz = plant.dozers["d37pxi"]
        print(f"depth {r['depth']:.3f} m: resistance {r['resistance'] / 1e3:6.2f} kN (load {r['load']:.2f} m^3), "
              f"load slip {r['slip']:.4f}, ground {r['v']:.4f} m/s, track {r['track']:.4f} m/s")
        assert r["depth"] == pytest.approx(depth, abs=0.02)  # the edge held at ground level under the slab's top
        assert r["track"] == pytest.approx(TRACK, rel=1e-3)
        assert r["load"] > 0.5 * depth * dz.blade.width  # the blade cut and carries the slab it passed
        # the slip is the one whose thrust carries the resistance (Wong's equation, written out independently)
        # the resistance: the wedge of the Reece/McKyes equation at the blade's rake and width + the pile's friction
        soil = plant.spec.soil.cutting
        wedge = fee_force(soil, math.radians(55.0), r["depth"], dz.blade.width).horizontal[0]
        pile = r["load"] * plant.spec.soil.loose_density * G * math.tan(soil.phi)
        assert r["resistance"] == pytest.approx(wedge + pile, rel=0.03)
        assert _thrust(plant, r["slip"]) == pytest.approx(r["resistance"], rel=0.01)
        assert r["v"] == pytest.approx(r["track"] * (1 - dz.description.track_drive.slip) * (1 - r["slip"]), rel=1e-9)
        assert abs(r["volume_error"]) < 1e-6  # soil conserved: ground + blade
        rows.append(r)
    forces = [r["resistance"] for r in rows]
    speeds = [r["v"] for r in rows]
    assert forces[0] < forces[1] < forces[2]
    assert speeds[0] > speeds[1] > speeds[2]
    assert forces[0] > 1e3 and forces[2] < 55e3  # a cut and a pile; not the stall of the next test


def test_a_blade_too_deep_stalls_the_dozer_while_its_tracks_run(tmp_path: Path) -> None:
    plant = _plant(tmp_path)
    _settle_blade(plant, 0.0)
    r = _push(plant, 0.8, into=5.0)  # never gets 5 m in: 20 s of pushing
    f_max = _f_max(plant)
    print(f"stall: depth {r['depth']:.3f} m, resistance {r['resistance'] / 1e3:.1f} kN (traction "
          f"{f_max / 1e3:.1f} kN), slip {r['slip']:.3f}, ground {r['v']:.4f} m/s, track {r['track']:.4f} m/s, "
          f"odometry {r['odometry']:.2f} m, moved {r['ground']:.2f} m")
    assert r["resistance"] > f_max
    assert r["slip"] == 1.0
    assert abs(r["v"]) < 0.05 * r["track"] and r["track"] == pytest.approx(TRACK, rel=1e-3)
    # 20 s of track odometry at 0.5 m/s against the ~0.5 m the body moved before the blade met the slab's face
    assert r["odometry"] > 9.0 and r["ground"] < 1.0
    assert abs(r["volume_error"]) < 1e-6


def test_blade_out_of_the_soil_or_backing_up_moves_as_before(tmp_path: Path) -> None:
    plant = _plant(tmp_path)
    dz = plant.dozers["d37pxi"]
    slip = dz.description.track_drive.slip
    lo = dz.lift.lower
    _settle_blade(plant, lo)  # raised
    assert plant.blade_edge("d37pxi")[2] > plant.spec.soil.ground_z + 0.1
    dz.set_track_speeds(TRACK, TRACK)
    for _ in range(300):
        plant.step()
        assert plant.blade_force["d37pxi"] == 0.0 and dz.base.load_slip == 0.0
        assert dz.base.v == 0.5 * (dz.base.vl + dz.base.vr) * (1.0 - slip)  # exactly today's model
    print(f"free: ground {dz.base.v:.4f} m/s, track {0.5 * (dz.base.vl + dz.base.vr):.4f} m/s")
    assert dz.base.v == pytest.approx(TRACK * (1 - slip), rel=2e-3)
    # blade lowered into a slab behind the edge, then backing up through nothing: no resistance
    dz.set_track_speeds(-TRACK, -TRACK)
    _settle_blade(plant, 0.1)
    _slab(plant, plant.blade_edge("d37pxi")[0] - 0.1, 0.3)
    for _ in range(200):
        plant.step()
        assert plant.blade_force["d37pxi"] == 0.0 and dz.base.load_slip == 0.0
    assert dz.base.v == pytest.approx(-TRACK * (1 - slip), rel=2e-3)


def test_a_dozer_without_its_traction_figures_is_refused(tmp_path: Path) -> None:
    machine = _plant(tmp_path).spec.machines["d37pxi"]
    bare = dataclasses.replace(machine, physics=dataclasses.replace(machine.physics, traction_coefficient=None,
                                                                    blade_rake_deg=None))
    with pytest.raises(SimConfigError, match=r"d37pxi.yaml: physics: missing traction_coefficient, blade_rake_deg"):
        DozerPlantProfile.make_machine(bare, 0.01)
