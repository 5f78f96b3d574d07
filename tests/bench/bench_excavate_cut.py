"""One excavate across the design trench's place on flat ground, in-process: where the bucket edge really went and
what it cut, against the goal (the design run's pass execution, one pass at a time).

``python -m tests.bench excavate_cut``: the paper launch's cores (arm planner, arm controller at 50 Hz) drive the
design run's plant (``config/sim/design_plant.yaml``: a 0.05 m patch of the height field over the trench) as
``bench_load_pass``'s :class:`PassRig` does, without ROS or CAN. The ZX200 starts as in the paper launch (facing
east) and digs behind itself: an excavate to (-5.5, 0, -0.3) in its base frame (= map), entry edge angle 1.1 rad,
a 1 m drag toward the swing axis, i.e. a pass of the design trench at x -5.5 .. -4.5. Two cases, each on a fresh
plant:

* ``straight``: the excavate alone (its approach swings about pi and the penetrate follows at once), as the design
  subtask's passes run;
* ``settled``: the excavate's approach point first as a goal of its own run to rest (design run 7's change_pose over
  the pass, measured and not kept: tms_rp/excavation/README.md), then the excavate.

Each case twice: with the penetrate and the drag passed on the controller's prediction (the kind's planning file),
and on the measured tip too (``dig_measured``, as the design run's ``config/tms_rp/zx200_planner_design.yaml``).

Printed per case: the truth bucket tip's lateral offset from the drag line and its height against the goal's -0.3 m
while it is below the ground (the surface under it before that period) in the penetrate and the drag (mean,
extremes), the ground's height along the drag line after the excavate (every 0.1 m from the far end), the length at
the far end left uncut, and the volume cut.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from sim_bridge.config import load_plant
from sim_bridge.plant import Plant
from tests.bench.bench_load_pass import PassRig
from tms_common.config import config_path

TARGET = np.array([-5.5, 0.0, -0.3])  # [m] base frame = map: the penetration point, the drag's far end
THETA_W, DRAG = 1.1, 1.0


class CutRig(PassRig):
    """:class:`PassRig` on the design run's plant; records the truth tip per control period."""

    def __init__(self) -> None:
        super().__init__()
        self.plant = Plant(load_plant(config_path("sim", "design_plant.yaml")))
        self.tips: list[tuple[str, np.ndarray, float]] = []

    def step_controller(self, skip: bool = False) -> None:
        x, y, _ = self.plant.bucket_tip()
        surface = self.plant.ground.height(x, y)  # before this period cuts it
        super().step_controller(skip)
        self.tips.append((self.ctl.status.label or "", np.array(self.plant.bucket_tip(), dtype=float), surface))


def run_case(settle: bool, measured: bool) -> None:
    rig = CutRig()
    rig.planner.cfg = dataclasses.replace(rig.planner.cfg, dig_measured=measured)
    t0 = time.monotonic()
    targets = rig.planner.excavate(TARGET, THETA_W, DRAG)
    if settle:
        code, message, _ = rig.run([targets[0]])
        if code != 1:
            raise RuntimeError(f"settling at the approach point: {message}")
        targets = rig.planner.excavate(TARGET, THETA_W, DRAG)
    rig.tips.clear()
    dug0 = rig.plant.soil.dug
    code, message, sim_s = rig.run(targets)
    segs = ", ".join(f"{k} {v:.1f}" for k, v in rig.segment_s.items())
    ground = rig.plant.ground
    u = -TARGET[:2] / np.linalg.norm(TARGET[:2])  # toward the swing axis (at the origin)
    lateral = np.array([-u[1], u[0]])
    inside = [(lab, p) for lab, p, surface in rig.tips if lab in ("penetrate", "drag") and p[2] < surface]
    print(f"  {'settled' if settle else 'straight'}, dig segments passed on the "
          f"{'measured tip' if measured else 'prediction'}: result {code} ({message}); segments [s] {segs}; "
          f"{sim_s:.1f} s simulated, {time.monotonic() - t0:.1f} s wall")
    if inside:
        pts = np.array([p for _, p in inside])
        off = (pts[:, :2] - TARGET[:2]) @ lateral
        print(f"    edge below the ground in penetrate + drag ({len(pts)} periods): beside the drag line mean "
              f"{100 * off.mean():+.1f} cm (extremes {100 * off.min():+.1f}, {100 * off.max():+.1f}); height mean "
              f"{100 * pts[:, 2].mean():+.1f} cm, lowest {100 * pts[:, 2].min():+.1f} cm (goal {100 * TARGET[2]:+.0f})")
    else:
        print("    the edge never went below the ground in the penetrate or the drag")
    along = np.arange(0.0, DRAG + 1e-9, 0.1)
    heights = [ground.height(*(TARGET[:2] + s * u)) for s in along]
    print("    ground along the drag after it [cm] (far end first, every 0.1 m): "
          + " ".join(f"{100 * h:+.0f}" for h in heights))
    fine = np.arange(0.0, DRAG, 0.01)
    cut = [s for s in fine if ground.height(*(TARGET[:2] + s * u)) < -0.05]
    uncut = cut[0] if cut else DRAG
    print(f"    far end left uncut over {100 * uncut:.0f} cm; cut {rig.plant.soil.dug - dug0:.3f} m^3")


def main() -> None:
    print(f"excavate to {TARGET.tolist()} (base frame), theta_w {THETA_W}, drag {DRAG} m, on the design plant; "
          f"the truth tip every control period")
    for settle in (False, True):
        for measured in (False, True):
            run_case(settle, measured)


if __name__ == "__main__":
    main()
