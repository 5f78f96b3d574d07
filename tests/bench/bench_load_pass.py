"""ZX200 load passes in-process: tms_sp targets -> planner -> arm controller -> MuJoCo plant, no ROS/CAN.

What one load pass of the paper experiment (trees/paper_zx200_load.xml: excavate, carry_over_vessel,
release, let_the_soil_fall, return_over_mound) yields when only the cores are in the loop: the excavation target from
tms_sp's mound
processor on the plant's height field, the release target from its vessel processor (IC120 standing at
P1), the planner's segments, the HQP controller at the paper launch's 50 Hz on the plant's clock, and
the plant's hydraulics (dead times, lags, pump) and soil model. It isolates geometry and motion from the
transport and CPU of the full launch, so it shows what digging and release settings are worth:

    python -m tests.bench load_pass            # LOAD_PASS_N passes (default 6)
    LOAD_PASS_LATE=0.4 python -m tests.bench load_pass   # 40 % of the control ticks a period late
    LOAD_PASS_PASS_THROUGH=0 python -m tests.bench load_pass   # the carry waits for rest at its goal
    LOAD_PASS_RETURN=0 python -m tests.bench load_pass   # no return leaf: the excavate's approach swings back
    LOAD_PASS_SOIL_FALL=0.5 python -m tests.bench load_pass   # the delay before the swing back [s] (default: the
    tree's)
    LOAD_PASS_TRANSPORT=2 python -m tests.bench load_pass   # measurements 2 periods old, commands 2 periods late
    LOAD_PASS_GAP=0.2 python -m tests.bench load_pass   # the controller idles this long [s] before each next goal
    LOAD_PASS_DIG_MEASURED=1 python -m tests.bench load_pass   # penetrate and drag reached on the measured tip
    LOAD_PASS_PENETRATION=1 python -m tests.bench load_pass   # the plant with soil.penetration on (the bucket
    pressed into the ground meets the soil's bearing; off in the shipped plant YAMLs)

Prints per pass: simulated time of each action and of the pass, soil cut, soil that reached the vessel,
soil spilled elsewhere, and the totals. ``make demo`` runs the same cores in separate processes.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import xml.etree.ElementTree as ET
from collections import deque

import numpy as np

from sim_bridge.config import load_plant
from sim_bridge.plant import Plant
from tests.rosproc import ROOT
from tests.tms_sp.treeutil import load_seed
from tms_common.config import config_path
from tms_model.excavator import codes
from tms_model.excavator.kinematics import load_kinematics
from tms_model.geometry import Pose2D
from tms_rc.excavator.controller import ArmController, load_controller_config
from tms_rp.arm.planner import ArmPlanner, load_planner_config
from tms_sp.config import load_sensing_config
from tms_sp.heightgrid import HeightGrid
from tms_sp.mound import assess_mound
from tms_sp.vessel import assess_vessel, release_in_excavator

#: The paper launch's choices (config/launch/paper_experiment.yaml): 50 Hz controller.
RATE_HZ = 50.0
#: The carry as the seed's target_release_pose asks (pass_through: 1); LOAD_PASS_PASS_THROUGH=0 waits for rest.
PASS_THROUGH = os.environ.get("LOAD_PASS_PASS_THROUGH", "1") != "0"
#: The tree's let_the_soil_fall delay after the release [s] (trees/paper_zx200_load.xml; LOAD_PASS_SOIL_FALL).
SOIL_FALL_S = float(os.environ.get("LOAD_PASS_SOIL_FALL") or 1e-3 * float(
    ET.parse(ROOT / "trees" / "paper_zx200_load.xml").find(".//Delay[@name='let_the_soil_fall']").get("delay_msec")))
#: The tree's return_over_mound after that delay (seed record target_excavate_approach_pose); LOAD_PASS_RETURN=0:
#: none, the excavate's approach does the swing back (the tree's earlier form).
RETURN = os.environ.get("LOAD_PASS_RETURN", "1") != "0"
#: Control periods of transport delay each way (LOAD_PASS_TRANSPORT; 0: none, the plant reads the command at once).
TRANSPORT = int(os.environ.get("LOAD_PASS_TRANSPORT", "0"))
#: Simulated seconds the controller idles before each goal after the first (LOAD_PASS_GAP; 0: the next goal
#: starts at the next tick), as the goal round trip tree -> subtask server -> planner -> controller takes in the stack.
GAP_S = float(os.environ.get("LOAD_PASS_GAP", "0"))
#: The plant's soil.penetration (LOAD_PASS_PENETRATION=1: on; default: the plant YAML's, off).
PENETRATION = os.environ.get("LOAD_PASS_PENETRATION", "0") != "0"
#: LOAD_PASS_DIG_MEASURED=0/1: the planner's dig_measured instead of its config's (penetrate and drag reached on the
#: measured tip, not the prediction alone)
DIG_MEASURED = os.environ.get("LOAD_PASS_DIG_MEASURED")
#: The seed's theta_w_tolerance of that record.
APPROACH_TOLERANCE = next(d["theta_w_tolerance"] for d in load_seed()["parameters"]
                          if d.get("record_name") == "target_excavate_approach_pose")


class PassRig:
    """The plant of the paper experiment with the ZX200 cores driving it in simulated time."""

    def __init__(self) -> None:
        spec = load_plant(config_path("sim", "paper_plant.yaml"))
        if PENETRATION:
            spec = dataclasses.replace(spec, soil=dataclasses.replace(spec.soil, penetration=True))
        self.plant = Plant(spec)
        self.kin = load_kinematics()
        cfg = load_controller_config(self.kin.machine)
        cfg = dataclasses.replace(cfg, rate_hz=RATE_HZ)
        self.ctl_cfg = cfg
        # one controller for every action, as excavator_arm_controller keeps one: a goal that ends at a
        # pass-through point leaves commands in flight, and the next goal starts from their prediction
        self.ctl = ArmController(self.kin, cfg)
        planner_cfg = load_planner_config(self.kin.machine.kind)
        if DIG_MEASURED is not None:
            planner_cfg = dataclasses.replace(planner_cfg, dig_measured=DIG_MEASURED != "0")
        self.planner = ArmPlanner(self.kin, planner_cfg, ground_min_z=cfg.ground_min_z)
        self.sensing = load_sensing_config()
        self.sub_steps = max(1, round(1.0 / (RATE_HZ * self.plant.dt)))
        self._measured: deque = deque(maxlen=TRANSPORT + 1)
        self._commands: deque = deque()
        self._started = False
        pts = self.sensing.points
        self.base = pts["zx200_base"]
        self.plant.set_truth("ic120", pts["P1"].x, pts["P1"].y, pts["P1"].yaw, {})

    @property
    def q(self) -> np.ndarray:
        return np.array(self.plant.excavator.front.q, dtype=float)

    def run(self, targets: list, limit_s: float = 300.0) -> tuple[int, str, float]:
        """Run one action's targets to the end; returns (result code, message, simulated seconds).

        :attr:`segment_s` gets the simulated time spent in each segment (by label).
        """
        ctl = self.ctl
        self.segment_s: dict[str, float] = {}
        t0 = self.plant.time  # the gap counts in the action's time, as in the stack's leaf times
        while self._started and self.plant.time - t0 < GAP_S - 1e-9:
            self.step_controller()
        self._started = True
        ctl.start(targets)
        # LOAD_PASS_LATE: the fraction of control ticks that come a period late (the previous command acts
        # for two periods), as a sim-time timer does on a loaded machine: the stack's conditions.
        late = float(os.environ.get("LOAD_PASS_LATE", "0"))
        rng = np.random.default_rng(1)
        while self.plant.time - t0 < limit_s:
            self.step_controller(skip=bool(late and rng.random() < late))
            label = ctl.status.label or ctl.status.mode
            self.segment_s[label] = self.segment_s.get(label, 0.0) + self.sub_steps * self.plant.dt
            if ctl.status.result is not None:
                return ctl.status.result, ctl.status.message, self.plant.time - t0
        return -1, f"no result within {limit_s} s", self.plant.time - t0

    def step_controller(self, skip: bool = False) -> None:
        """One control period: the controller's command (the previous one again when ``skip``: a late tick).

        ``LOAD_PASS_TRANSPORT=k``: the measurement the controller gets is k periods old and its command
        reaches the plant k periods later, as joint_states and commands over ROS and CAN do in the stack.
        """
        front = self.plant.excavator.front
        self._measured.append((np.array(front.q, dtype=float), np.array(front.v, dtype=float)))
        q, v = self._measured[0]
        if not skip:
            u = self.ctl.step(q, v, now=self.plant.time)
            self._commands.append(u)
        if len(self._commands) > TRANSPORT:
            u = self._commands.popleft()
            self.plant.excavator.set_front_velocity(dict(zip(front.names, u.tolist(), strict=True)))
        for _ in range(self.sub_steps):
            self.plant.step()

    def mound_targets(self) -> tuple[tuple[list[float], float, float], dict]:
        """(excavation position, theta_w, offset), and the approach record tms_sp writes with it."""
        spec = self.sensing.mound_grid
        xg, yg = spec.centres()
        g = self.plant.ground
        rows = np.clip(((yg - g.y0) / g.res).astype(int), 0, g.ny - 1)
        cols = np.clip(((xg - g.x0) / g.res).astype(int), 0, g.nx - 1)
        grid = HeightGrid(spec, g.h[rows, cols], 1.0)
        axis = self.base.to_map(np.array([*self.sensing.swing_axis_in_base, 0.0]))
        a = assess_mound(grid, (float(axis[0]), float(axis[1])), self.sensing.excavation)
        if a.target is None:
            raise RuntimeError(f"no excavation target: {a}")
        f = a.target.record_fields(self.base)
        return ([f["x"], f["y"], f["z"]], f["theta_w"], f["offset"]), a.target.approach_record_fields(
            self.base, self.sensing.approach_height)

    def release_target(self) -> tuple[list[float], float, float]:
        geom = self.sensing.vessel_geom
        spec = geom.grid_spec(self.sensing.resolution)
        # Load shape: the plant keeps a volume only; spread it evenly (the scanner's heap is similar).
        h = self.plant.soil.vessel / (geom.inner_length * geom.inner_width)
        grid = HeightGrid(spec, np.full((spec.ny, spec.nx), h), 1.0)
        v = assess_vessel(grid, geom, self.sensing.vessel)
        ic = self.plant.truth("ic120")
        pose, angle = release_in_excavator(v.release_xyz, Pose2D(ic.x, ic.y, ic.yaw), self.base, geom,
                                       self.sensing.swing_axis_in_base, self.sensing.vessel.carry_theta_w)
        return [pose["x"], pose["y"], pose["z"]], pose["theta_w"], angle["target_angle"]


def main() -> None:
    n = int(os.environ.get("LOAD_PASS_N", "6"))
    rig = PassRig()
    soil = rig.plant.soil
    ground = rig.plant.ground
    print(f"load passes in-process (MuJoCo plant, controller {RATE_HZ:.0f} Hz, no transport delay): {n} passes, "
          f"{float(os.environ.get('LOAD_PASS_LATE', '0')):.0%} of the ticks a period late (LOAD_PASS_LATE)")
    wall0 = time.monotonic()
    sim0 = rig.plant.time
    totals = {"cut": 0.0, "vessel": 0.0, "pass_s": []}
    for k in range(n):
        mound0, vessel0, dug0 = ground.mound_volume(), soil.vessel, soil.dug
        ground_out0 = ground.ground_soil_volume() - ground.mound_volume()
        times = {}
        (pos, th, off), _ = rig.mound_targets()
        code, msg, times["excavate"] = rig.run(rig.planner.excavate(pos, th, off))
        dig_segments = dict(rig.segment_s)
        cut = soil.dug - dug0
        in_bucket = soil.bucket
        if code != codes.SUCCESS:
            print(f"  pass {k + 1}: excavate ended {code}: {msg}")
        rpos, rth, angle = rig.release_target()
        # the seed's target_release_pose has pass_through: 1; the planner node plans the release from the
        # carry's end while the arm is on its way there (ArmPlanner.start_state)
        carry = rig.planner.change_pose(positions_with_angle=[(rpos, rth)], current_q=rig.q, pass_through=PASS_THROUGH)
        code2, msg2, times["carry"] = rig.run(carry)
        carried = soil.bucket
        carry_segments = dict(rig.segment_s)
        q_release = rig.planner.start_state(rig.q, rig.planner.pass_through_end(carry))
        release_targets = rig.planner.release(angle, q_release)
        code3, msg3, times["release"] = rig.run(release_targets)
        release_segments = dict(rig.segment_s)
        for c, m, what in ((code2, msg2, "carry"), (code3, msg3, "release")):
            if c != codes.SUCCESS:
                print(f"  pass {k + 1}: {what} ended {c}: {m}")
        # the tree's let_the_soil_fall: the release ends on the prediction, the open bucket reaches the plant
        # ~1.3 s later and spills for 1.5 s; the swing back starts after the delay (its dead time covers the rest)
        t_settle = rig.plant.time
        while rig.plant.time - t_settle < SOIL_FALL_S:
            rig.step_controller()  # idle between goals, as the node's 50 Hz loop goes on
        times["soil_fall"] = rig.plant.time - t_settle
        if RETURN:
            _, approach = rig.mound_targets()
            back = rig.planner.change_pose(
                positions_with_angle=[([approach["x"], approach["y"], approach["z"]], approach["theta_w"])],
                current_q=rig.planner.start_state(rig.q, rig.planner.pass_through_end(release_targets)),
                pass_through=True, theta_w_tolerance=APPROACH_TOLERANCE)
            code4, msg4, times["return"] = rig.run(back)
            if code4 != codes.SUCCESS:
                print(f"  pass {k + 1}: return ended {code4}: {msg4}")
        else:
            t_rest = rig.plant.time  # no return leaf: the next excavate's approach swings back
            while soil.bucket > 1e-3 and rig.plant.time - t_rest < 5.0:
                rig.step_controller()
        into = soil.vessel - vessel0
        spilled_out = ground.ground_soil_volume() - ground.mound_volume() - ground_out0
        pass_s = sum(times.values())
        totals["cut"] += cut
        totals["vessel"] += into
        totals["pass_s"].append(pass_s)
        print(
            f"  pass {k + 1}: target r {math.hypot(pos[0], pos[1]):.2f} m z {pos[2]:.2f} theta_w {th:.2f} "
            f"drag {off:.2f}; "
            f"cut {cut:.3f} m3 (bucket after dig {in_bucket:.3f}, after carry {carried:.3f}), "
            f"into vessel {into:.3f} m3, "
            f"spilled off the mound {spilled_out:.3f} m3, mound {mound0:.2f} -> {ground.mound_volume():.2f} m3; "
            + ", ".join(f"{a} {s:.1f} s" for a, s in times.items())
            + f", pass {pass_s:.1f} s",
            flush=True,
        )
        for what, segs in (("excavate", dig_segments), ("carry", carry_segments), ("release", release_segments)):
            print(f"    {what} segments [s]: " + ", ".join(f"{a} {s:.1f}" for a, s in segs.items()))
    sim = rig.plant.time - sim0
    print(f"  total: cut {totals['cut']:.2f} m3, into the vessel {totals['vessel']:.2f} m3 "
          f"({totals['vessel'] / max(n, 1):.3f} m3 per pass); pass time median {np.median(totals['pass_s']):.1f} s "
          f"simulated (goal <= 20 s); {sim:.0f} s simulated in {time.monotonic() - wall0:.0f} s wall")


if __name__ == "__main__":
    main()
