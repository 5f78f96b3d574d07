"""Plant-core CPU probe, run as a script by ``bench_sim_bridge`` against one source tree (current or a baseline).

``python tests/bench/sim_probe.py --tree ROOT --plant sim/plant.yaml --seconds 36`` builds
``sim_bridge.plant.Plant(load_plant(<config>/sim/plant.yaml))`` from the tree on ``PYTHONPATH`` (run it with
``AMENT_PREFIX_PATH`` unset, so ``config/`` is the tree's own too), steps it with the scripted dig cycle and prints
one JSON line: CPU seconds (``time.process_time``: every thread of this process) of the stepping alone, simulated
seconds, and what was done (dig-cycle poses reached, dug volume, the carrier's load).

``--serve`` is the bench's lock-step mode: after building, the probe prints ``{"ready": ...}`` and then reads
commands from stdin, ``step N`` (answers ``{"cpu_s": ...}`` for those N steps) or ``end`` (answers the summary and
exits). The bench keeps a baseline and a current probe alive and alternates short chunks between them, so both
see the same load from the rest of the machine (a shared 2-core machine drifts within seconds).

It uses only what exists both before and after the kinematic -> dynamic rewrite of the plant (``Plant(spec)``,
``load_plant(path)``, ``plant.step()``, ``set_truth``, the machines' command setters and
:mod:`sim_bridge.scenario`), so the same file measures either tree. It imports nothing from ``tests``.

Commands: the digging excavator (``spec.excavator``) follows ``DIG_CYCLE`` with ``servo_velocity``; the soil carrier
(``spec.carrier``) stands still at site point P1 under the dumps (where ``DIG_CYCLE`` assumes it); every other
machine gets simple motion commands, toggled every ``TOGGLE_S``: tracks on a 2 m circle (0.3 m/s, 0.15 rad/s),
excavator swing +-0.3 rad/s and boom +-0.1 rad/s, vessel up/down (target 1 rad / 0, clamped to its limits),
carrier swing +-0.5 rad, dozer blade between its lift limits. ``--others idle`` leaves them without commands.
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


class Probe:
    """The plant of one tree and the scripted commands; :meth:`advance` steps and returns the CPU it took."""

    def __init__(self, tree: Path, plant_file: str, others: str) -> None:
        _check_tree(tree)
        from sim_bridge.config import load_plant
        from sim_bridge.plant import Plant
        from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
        from tms_common.config import config_path

        self._cycle, self._reached, self._servo = DIG_CYCLE, pose_reached, servo_velocity
        c0 = time.process_time()
        self.plant = plant = Plant(load_plant(config_path(*plant_file.split("/"))))
        spec = plant.spec
        if plant.excavator is None or plant.carrier is None:
            raise SystemExit(f"sim_probe: {plant_file} has no digging excavator or soil carrier")
        plant.set_truth(spec.carrier, *P1, {})
        self.moving = [n for n in plant.machines if n not in (spec.excavator, spec.carrier)] if others == "move" else []
        self.build_cpu_s = time.process_time() - c0
        self.tree, self.plant_file = tree, plant_file
        self.k = 0  # dig-cycle poses reached
        self.steps = 0
        self.cpu_s = 0.0

    def _others(self, t: float) -> None:
        from sim_bridge.machines import CrawlerCarrier, Dozer, Excavator

        sign = 1.0 if int(t / TOGGLE_S) % 2 == 0 else -1.0
        for name in self.moving:
            m = self.plant.machines[name]
            m.set_centre_velocity(0.3, 0.15)
            if isinstance(m, Excavator):
                m.set_front_velocity({"swing_joint": 0.3 * sign, "boom_joint": 0.1 * sign})
            elif isinstance(m, CrawlerCarrier):
                m.set_vessel_target(1.0 if sign > 0 else 0.0)
                if m.has_swing:
                    m.set_swing_target(0.5 * sign)
            elif isinstance(m, Dozer):
                m.set_lift_target(1.0 * sign)  # clamped to the lift joint's limits

    def advance(self, steps: int) -> float:
        plant, exc = self.plant, self.plant.excavator
        names, cycle = exc.front.names, self._cycle
        c0 = time.process_time()
        for _ in range(steps):
            q = dict(zip(names, exc.front.q, strict=True))
            if self._reached(q, cycle[self.k % len(cycle)], tol=0.05):
                self.k += 1
            exc.set_front_velocity(self._servo(q, cycle[self.k % len(cycle)]))
            if self.moving:
                self._others(plant.time)
            plant.step()
        cpu = time.process_time() - c0
        self.steps += steps
        self.cpu_s += cpu
        return cpu

    def summary(self) -> dict:
        p, spec = self.plant, self.plant.spec
        return {
            "tree": str(self.tree), "plant": self.plant_file, "machines": list(p.machines), "moving": self.moving,
            "excavator": spec.excavator, "carrier": spec.carrier, "sim_s": self.steps * p.dt, "steps": self.steps,
            "cpu_s": self.cpu_s, "build_cpu_s": self.build_cpu_s, "poses_reached": self.k,
            "dug_m3": float(p.soil.dug), "vessel_m3": float(p.soil.vessels.get(spec.carrier, 0.0)),
        }


def _serve(probe: Probe) -> int:
    print(json.dumps({"ready": True, "dt": probe.plant.dt}), flush=True)
    for line in sys.stdin:
        cmd = line.split()
        if cmd[:1] == ["step"] and len(cmd) == 2:
            print(json.dumps({"cpu_s": probe.advance(int(cmd[1]))}), flush=True)
        elif cmd == ["end"]:
            print(json.dumps(probe.summary()), flush=True)
            return 0
        else:
            raise SystemExit(f"sim_probe: unknown command {line.strip()!r} (expected 'step N' or 'end')")
    return 1  # stdin closed without 'end': the bench went away


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", required=True, type=Path, help="source tree root expected on PYTHONPATH")
    ap.add_argument("--plant", default="sim/plant.yaml", help="plant YAML relative to the tree's config/")
    ap.add_argument("--seconds", type=float, default=36.0, help="simulated seconds to step (without --serve)")
    ap.add_argument("--others", choices=("move", "idle"), default="move")
    ap.add_argument("--serve", action="store_true", help="lock-step mode: 'step N' / 'end' commands on stdin")
    a = ap.parse_args(argv)
    probe = Probe(a.tree.resolve(), a.plant, a.others)
    if a.serve:
        return _serve(probe)
    probe.advance(round(a.seconds / probe.plant.dt))
    print(json.dumps(probe.summary()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
