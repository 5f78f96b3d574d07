"""ZX200 arm benchmark (pure core, first-order-lag + dead-time plant; no ROS, no MuJoCo).

Prints: success rate of 100 random reachable targets of each kind (joint / pose / position+theta_w)
within 3 cm and 2 deg with zero limit violations, QP solve time per control step (median, p99), the RMS
tip tracking error of a 2 m Cartesian move, and the period jitter of a 100 Hz control loop.
Run: ``.venv/bin/python -m tests.bench zx200`` (``ZX200_BENCH_N`` = targets per kind, default 100).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pinocchio as pin

from tests.bench.stats import summary_ms
from tms_rc.zx200.controller import ArmController, load_controller_config
from tms_rc.zx200.plant import LagDeadTimePlant
from tms_rp.zx200 import errors as codes
from tms_rp.zx200.errors import PlanningError
from tms_rp.zx200.kinematics import load_kinematics
from tms_rp.zx200.planner import Zx200Planner, load_planner_config


def _run(kin, cfg, q0, targets, solve_times, max_steps=8000):
    ctl = ArmController(kin, cfg)
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    q, v = q0.copy(), np.zeros(4)
    ctl.start(targets)
    violations, errs = 0, []
    for _ in range(max_steps):
        u = ctl.step(q, v)
        solve_times.append(ctl.last_result.solve_time_s)
        if np.sum(cfg.flow_per_rad_s * np.abs(u)) > cfg.pump_flow_lpm * 1.001 or np.any(np.abs(u) > kin.limits.velocity + 1e-9):
            violations += 1
        q, v = plant.step(u)
        if kin.limits.violation(q) is not None:
            violations += 1
        if ctl.reference_tip is not None:
            errs.append(float(np.linalg.norm(kin.tip_position(q) - ctl.reference_tip)))
        if ctl.status.result is not None:
            break
    return ctl.status, q, violations, errs


def main() -> None:
    kin = load_kinematics()
    cfg = load_controller_config()
    planner = Zx200Planner(kin, load_planner_config(), ground_min_z=cfg.ground_min_z)
    n = int(os.environ.get("ZX200_BENCH_N", "100"))
    rng = np.random.default_rng(7)
    solve_times: list[float] = []
    lo = np.array([-math.pi, -1.1, 0.65, -0.55])
    hi = np.array([math.pi, -0.15, 2.6, 2.3])

    def random_reachable():
        while True:
            q = rng.uniform(lo, hi)
            p = kin.tip_position(q)
            tip, _, pin_p, _ = kin.jacobians(q)
            rho = [np.linalg.norm(x[:2] - kin.swing_origin[:2]) for x in (tip, pin_p)]
            if min(rho) > cfg.body_min_radius + 0.3 and min(tip[2], pin_p[2]) > cfg.ground_min_z + 0.3:
                return q, p

    print(f"zx200 bench: {n} random reachable targets per kind, lag+dead-time plant "
          f"(dead {cfg.dead_time_s.tolist()} s, lag {cfg.lag_s.tolist()} s)")
    for kind in ("joint", "pose", "position_with_angle"):
        ok = viol_total = 0
        worst_pos = worst_ang = 0.0
        t0 = time.perf_counter()
        for _ in range(n):
            q_start, _ = random_reachable()
            q_goal, p_goal = random_reachable()
            try:
                if kind == "joint":
                    targets = planner.change_pose(joint_names=["swing_joint", "boom_joint", "arm_joint", "bucket_joint"],
                                                  joint_points=[q_goal.tolist()], current_q=q_start)
                elif kind == "pose":
                    pose = kin.tip_pose(q_goal)
                    targets = planner.change_pose(poses=[(pose.translation.tolist(), pin.Quaternion(pose.rotation).coeffs().tolist())])
                else:
                    targets = planner.change_pose(positions_with_angle=[(p_goal.tolist(), kin.theta_w(q_goal))])
            except PlanningError as exc:
                print(f"  planner refused a reachable target: {exc}")
                continue
            status, q_end, viol, _ = _run(kin, cfg, q_start, targets, solve_times)
            pos_err = float(np.linalg.norm(kin.tip_position(q_end) - p_goal))
            ang_err = abs(kin.theta_w(q_end) - kin.theta_w(q_goal))
            if kind == "joint":
                d = q_end - q_goal
                d[0] = math.atan2(math.sin(d[0]), math.cos(d[0]))
                ang_err = float(np.max(np.abs(d)))
            worst_pos, worst_ang = max(worst_pos, pos_err), max(worst_ang, ang_err)
            viol_total += viol
            if status.result == codes.SUCCESS and pos_err < 0.03 and ang_err < math.radians(2) and viol == 0:
                ok += 1
        print(f"  {kind:20s}: {ok}/{n} within 3 cm / 2 deg ({100.0 * ok / n:.0f}%), limit violations {viol_total}, "
              f"worst {100 * worst_pos:.2f} cm / {math.degrees(worst_ang):.2f} deg, {time.perf_counter() - t0:.0f} s")
    print("  QP solve time per control step: " + summary_ms(solve_times))

    q0 = kin.home.copy()
    p0 = kin.tip_position(q0)
    status, q_end, viol, errs = _run(kin, cfg, q0, planner.change_pose(positions_with_angle=[((p0 + [-2.0, 0, 0]).tolist(), kin.theta_w(q0))]), [])
    print(f"  2 m Cartesian move: RMS tracking error {1000 * math.sqrt(np.mean(np.square(errs))):.2f} mm, "
          f"max {1000 * max(errs):.2f} mm, result {status.result}, violations {viol}")

    ctl = ArmController(kin, cfg)
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    ctl.start(planner.change_pose(positions_with_angle=[((p0 + [-2.0, 0, 0]).tolist(), kin.theta_w(q0))]))
    q, v = q0.copy(), np.zeros(4)
    periods, next_t, last = [], time.monotonic(), None
    for _ in range(500):
        next_t += cfg.dt
        time.sleep(max(0.0, next_t - time.monotonic()))
        now = time.monotonic()
        if last is not None:
            periods.append(now - last)
        last = now
        q, v = plant.step(ctl.step(q, v))
    jitter = np.abs(np.array(periods) - cfg.dt)
    print(f"  100 Hz loop (5 s, controller + plant in one thread): period {summary_ms(periods)}; "
          f"|period - 10 ms| median {1000 * np.median(jitter):.3f} ms, p99 {1000 * np.percentile(jitter, 99):.3f} ms")


if __name__ == "__main__":
    main()
