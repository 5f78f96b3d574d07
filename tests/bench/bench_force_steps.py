"""Force steps of the arm and bucket cylinders with the bucket pressed on flat ground, with and without the soil's
bearing (``soil.penetration``), against the plant core in-process.

``python -m tests.bench force_steps``: reads the arm's and the bucket's look-up tables identified over CAN
(``config/tms_rc/identified/zx200_piston_lut.yaml``; ``PISTON_LUTS=in_process``: identified on
``config/sim/paper_plant.yaml`` as ``python -m tests.bench piston`` does; the dead-zone compensation of
:class:`tms_rc.excavator.piston.PistonForceController` needs their crack pilots), then per function and case:

* ``ON, flat ground``: the plant with ``soil.penetration: true``, the ZX200 swung a quarter turn away from the mound
  over flat ground, boom at its lowest and arm reached out (there the arm's and the bucket's motion moves the edge
  more down than along); the arm presses the edge onto the ground (1 MPa of pilot until it stalls or 1 m deep),
  rests, then steps of the function's commanded cylinder force, once with the stall's PI gains (``force`` of
  ``config/tms_rc/piston_control.yaml``) and once with the contact gains (``force_contact``);
* ``OFF, flat ground``: the same without the bearing (the shipped plants): nothing carries the edge, it sinks;
* ``OFF, in the mound``: bench_piston's old scenario (the bucket lowered 1 m into the mound, held by the cutting
  resistance as joint friction), the figures the README quotes for the stalled bucket (stall gains).

Printed per step: time to 10 %, rise 10-90 %, steady-state error (mean of f_ref - f over the last 2 s of 8 s); per
case the edge's depth, the soil's bearing force and the boom cylinder's force against its pulling relief force (the
description's bores and relief) after the steps: pressing the edge down lifts the front, which the boom holds down
on its rod side; at the rod-side relief (~387 kN on the ZX200) the boom rises and the pressing force stops growing.
``FORCE_STEPS_FUNCTIONS=arm_joint`` limits the functions (default arm and bucket).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from types import MappingProxyType

from sim_bridge.plant import Plant
from tests.bench.bench_piston import PlantRig, bury_bucket, controller_luts, force_steps
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    PiGains,
    PilotPair,
    cylinder_of,
    load_piston_settings,
    piston_length,
)

#: over flat ground east of the machine (the mound is north), boom 0.05 rad above its lowest, arm reached out: the
#: edge about 0.4 m above the ground, 9.7 m out; the arm's and the bucket's motion there moves the edge about twice
#: as much down as along (tip Jacobian)
FLAT_FRONT = {"swing_joint": -math.pi / 2, "boom_joint": -0.15, "arm_joint": 0.75, "bucket_joint": -0.2}
TARGETS = [100e3, 250e3, 150e3, 0.0, -100e3]  # [N] as bench_piston's (the buried bucket)
#: [N] on flat ground after the arm's press, per function: above what holds the reached-out front up (the arm ~100 kN,
#: below it the edge lifts off and nothing is pressed) and below where the boom's rod-side relief lets the front rise
#: (the arm ~238 kN, the bucket ~171 kN in this pose: measured, the boom at -387 kN); the former targets 250 and 300 kN
#: of the arm lie beyond it and were never reached
FLAT_TARGETS = {"arm_joint": [150e3, 220e3, 180e3, 120e3, 200e3],
                "bucket_joint": [110e3, 160e3, 130e3, 90e3, 150e3]}
PRESS_PILOT = 1.0  # [MPa] the function pressing the edge onto the ground
HOLD_S, WINDOW_S = 8.0, 2.0


class FlatRig(PlantRig):
    """:class:`PlantRig` on the paper plant started at ``front`` (default :data:`FLAT_FRONT`), ``soil.penetration``
    as asked."""

    def __init__(self, penetration: bool, front: dict[str, float] | None = None) -> None:
        super().__init__()
        spec = self.plant.spec
        pm = spec.machines[spec.excavator]
        machines = dict(spec.machines)
        machines[spec.excavator] = dataclasses.replace(
            pm, start_joints=MappingProxyType({**pm.start_joints, **(FLAT_FRONT if front is None else front)}))
        self.plant = Plant(dataclasses.replace(spec, machines=MappingProxyType(machines),
                                               soil=dataclasses.replace(spec.soil, penetration=penetration)))
        self.zx = self.plant.excavator
        self.front = self.zx.front
        self._last = {fn: self.length(fn) for fn in CYLINDER_FUNCTIONS}
        self.start_length = dict(self._last)


def press(rig: PlantRig, fn: str, limit_s: float = 6.0, depth: float = 1.0) -> None:
    """``fn`` driven to press the edge down (crowd / curl: +joint) at :data:`PRESS_PILOT` until the edge stalls on
    the ground (after touching it, slower than 1 cm/s) or is ``depth`` deep, then 2 s of rest."""
    touched = False
    for _ in range(round(limit_s / rig.dt)):
        for n in rig.names:
            rig.pairs[n] = PilotPair(0.0, 0.0)
        rig.pairs[fn] = PilotPair(PRESS_PILOT, 0.0)  # plus = the joint's + direction (crowd, curl)
        rig.advance()
        touched = touched or rig.tip_depth() > 0.0
        if rig.tip_depth() >= depth or (touched and rig.plant.tip_speed < 0.01):
            break
    rig.rest(2.0)


def run_case(label: str, rig: PlantRig, fn: str, lut, settings, flat: bool, gains: PiGains | None = None) -> None:
    targets = FLAT_TARGETS[fn] if flat else TARGETS
    f0 = rig.force(fn)
    boom = cylinder_of(rig.machine, "boom_joint")
    boom_pull = rig.machine.cylinders.relief_pa * boom.rod_area  # [N] the boom's pulling force at its relief
    print(f"  {label}: edge {100 * rig.tip_depth():.1f} cm into the ground, {fn} holding {f0 / 1e3:.1f} kN, bearing "
          f"{rig.plant.press_force / 1e3:.1f} kN")
    t0 = time.monotonic()
    for st in force_steps(rig, fn, lut, settings, targets, hold_s=HOLD_S, window_s=WINDOW_S, gains=gains):
        rise = f"{st.rise_s:.2f} s" if math.isfinite(st.rise_s) else "never (90 % not reached)"
        print(f"    {st.f_from / 1e3:+7.1f} -> {st.f_to / 1e3:+7.1f} kN: 10 % after {st.delay_s:.2f} s, rise 10-90 % "
              f"{rise}, steady-state error {st.steady_error / 1e3:+.2f} kN")
    print(f"    after the steps: edge {100 * rig.tip_depth():.1f} cm into the ground, bearing "
          f"{rig.plant.press_force / 1e3:.1f} kN, boom {rig.force('boom_joint') / 1e3:+.0f} kN (its pulling relief "
          f"-{boom_pull / 1e3:.0f} kN) ({time.monotonic() - t0:.1f} s wall)")


def main() -> None:
    settings = load_piston_settings()
    functions = [f for f in os.environ.get("FORCE_STEPS_FUNCTIONS", "arm_joint,bucket_joint").split(",") if f]
    wall0 = time.monotonic()
    rig = PlantRig()
    print(f"force steps in-process (MuJoCo plant core, config/sim/paper_plant.yaml, {settings.rate_hz:.0f} Hz); "
          f"{HOLD_S:.0f} s each, steady-state error = mean of f_ref - f over the last {WINDOW_S:.0f} s")
    luts, source = controller_luts(rig, functions, settings)
    print(f"  tables of {', '.join(functions)} {source}")
    for fn in functions:
        print(f"{fn} cylinder:")
        for on, which in ((True, "force"), (True, "force_contact"), (False, "force_contact")):
            rig = FlatRig(on)
            press(rig, "arm_joint")
            run_case(f"{'ON' if on else 'OFF'}, flat ground (pressed by arm_joint at {PRESS_PILOT:g} MPa), {which} "
                     "gains", rig, fn, luts[fn], settings, flat=True, gains=getattr(settings, which)[fn])
        rig = PlantRig()
        bury_bucket(rig)
        run_case("OFF, buried 1 m in the mound (bench_piston's scenario), force gains", rig, fn, luts[fn], settings,
                 flat=False)
    lengths = {fn: piston_length(rig.machine, fn, FLAT_FRONT[fn]) for fn in functions}
    print(f"  flat-ground start lengths {', '.join(f'{k} {v:.3f} m' for k, v in lengths.items())}; "
          f"{time.monotonic() - wall0:.1f} s wall")


if __name__ == "__main__":
    main()
