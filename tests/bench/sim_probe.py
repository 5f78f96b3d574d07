"""Plant-core CPU probe, run as a script by ``bench_sim_bridge`` against one source tree (current or a baseline).

``python tests/bench/sim_probe.py --tree ROOT --plant sim/plant.yaml --seconds 30`` builds
``sim_bridge.plant.Plant(load_plant(<config>/sim/plant.yaml))`` from the tree on ``PYTHONPATH`` and steps it with
the scripted dig cycle, then prints one JSON line: CPU seconds (``time.process_time``: every thread of this
process) of the stepping loop alone, simulated seconds, and what was done (dug volume, dig-cycle poses reached).

It uses only what exists both before and after the kinematic -> dynamic rewrite of the plant (``Plant(spec)``,
``load_plant(path)``, ``plant.step()``, ``set_truth``, the machines' command setters and
:mod:`sim_bridge.scenario`), so the same file measures either tree. It imports nothing from ``tests``.

Commands: the digging excavator (``spec.excavator``) follows ``DIG_CYCLE`` with ``servo_velocity``; the soil carrier
(``spec.carrier``) stands still at site point P1 under the dumps (where ``DIG_CYCLE`` assumes it); with
``--others move`` (default) every other machine gets simple motion commands, toggled every ``TOGGLE_S``: tracks
on a 2 m circle (0.3 m/s, 0.15 rad/s), excavator swing +-0.3 rad/s and boom +-0.1 rad/s, vessel up/down
(target 1 rad / 0, clamped to its limits), carrier swing +-0.5 rad, dozer blade between its lift limits.
``--others idle`` leaves them without commands.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

TOGGLE_S = 8.0  # [s] period of the others' back-and-forth commands
P1 = (1.2, 6.5, 0.0)  # site.yaml point P1 (loading): x, y, yaw; DIG_CYCLE dumps over it


def _check_tree(tree: Path) -> None:
    """The packages and the config must both come from ``tree`` (a wrong PYTHONPATH measures the other tree)."""
    import sim_bridge
    from tms_common.config import data_root

    pkg = Path(sim_bridge.__file__).resolve()
    if tree not in pkg.parents:
        raise SystemExit(f"sim_probe: sim_bridge imported from {pkg}, not from --tree {tree} (check PYTHONPATH)")
    if data_root().resolve() != tree:
        raise SystemExit(f"sim_probe: config/ resolved under {data_root()}, not {tree} "
                         "(unset AMENT_PREFIX_PATH so tms_common finds the tree's own config/)")


def _others(plant, names: list[str], t: float) -> None:
    from sim_bridge.machines import CrawlerCarrier, Dozer, Excavator

    sign = 1.0 if int(t / TOGGLE_S) % 2 == 0 else -1.0
    for name in names:
        m = plant.machines[name]
        m.set_centre_velocity(0.3, 0.15)
        if isinstance(m, Excavator):
            m.set_front_velocity({"swing_joint": 0.3 * sign, "boom_joint": 0.1 * sign})
        elif isinstance(m, CrawlerCarrier):
            m.set_vessel_target(1.0 if sign > 0 else 0.0)
            if m.has_swing:
                m.set_swing_target(0.5 * sign)
        elif isinstance(m, Dozer):
            m.set_lift_target(1.0 * sign)  # clamped to the lift joint's limits


def run(tree: Path, plant_file: str, seconds: float, others: str) -> dict:
    _check_tree(tree)
    from sim_bridge.config import load_plant
    from sim_bridge.plant import Plant
    from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
    from tms_common.config import config_path

    c0 = time.process_time()
    plant = Plant(load_plant(config_path(*plant_file.split("/"))))
    spec = plant.spec
    if plant.excavator is None or plant.carrier is None:
        raise SystemExit(f"sim_probe: {plant_file} has no digging excavator or soil carrier")
    plant.set_truth(spec.carrier, *P1, {})
    moving = [n for n in plant.machines if n not in (spec.excavator, spec.carrier)] if others == "move" else []
    build = time.process_time() - c0

    exc = plant.excavator
    names = exc.front.names
    steps = round(seconds / plant.dt)
    k = 0
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(steps):
        q = dict(zip(names, exc.front.q, strict=True))
        if pose_reached(q, DIG_CYCLE[k % len(DIG_CYCLE)], tol=0.05):
            k += 1
        exc.set_front_velocity(servo_velocity(q, DIG_CYCLE[k % len(DIG_CYCLE)]))
        if moving:
            _others(plant, moving, plant.time)
        plant.step()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return {
        "tree": str(tree), "plant": plant_file, "machines": list(plant.machines), "moving": moving,
        "excavator": spec.excavator, "carrier": spec.carrier, "sim_s": steps * plant.dt, "steps": steps,
        "cpu_s": cpu, "wall_s": wall, "build_cpu_s": build, "poses_reached": k,
        "dug_m3": float(plant.soil.dug), "vessel_m3": float(plant.soil.vessels.get(spec.carrier, 0.0)),
    }


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", required=True, type=Path, help="source tree root expected on PYTHONPATH")
    ap.add_argument("--plant", default="sim/plant.yaml", help="plant YAML relative to the tree's config/")
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds to step")
    ap.add_argument("--others", choices=("move", "idle"), default="move")
    a = ap.parse_args(argv)
    print(json.dumps(run(a.tree.resolve(), a.plant, a.seconds, a.others)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
