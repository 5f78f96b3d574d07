"""IC120 benchmark: planner / controller / EKF timing, localisation accuracy, 20 runs of the paper route.

``python -m tests.bench ic120``. Figures:
* global planning on a 200 m x 200 m map at 0.1 m (2000 x 2000 cells, random blocks + a long wall; goal < 200 ms);
* controller step (goal < 2 ms) and EKF odometry/GNSS/azimuth update times;
* synthetic localisation: RMS with 2 cm GNSS noise and 4 % slip, 10 s outage, 5 m jump;
* 20 runs of the paper route (start -> P2 -> P1 reached in reverse -> P2 -> P3, turn -> P4 -> P5) with the
  EKF in the loop on a kinematic tracked model (dead time 0.2 s, lag 0.4 s, 5 % slip, 15 % yaw slip,
  GNSS 2 cm), start pose perturbed per run: final errors at P1 and P5 (p95) and footprint collisions.
* ``IC120_BENCH_PLANT_RUNS=N`` adds N runs of the same route through sim_plant + com3_bridge over COM3 CAN
  (real time, about 3 min per run).
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tests.bench.stats import percentile, summary_ms  # noqa: E402


def bench_planner() -> None:
    from tms_rp.ic120.costmap import Costmap, Footprint, OccupancyMap
    from tms_rp.ic120.planner import GridPlanner

    rng = np.random.default_rng(0)
    g = np.zeros((2000, 2000), np.int8)
    for _ in range(150):
        r, c = rng.integers(0, 2000, 2)
        g[r:r + rng.integers(10, 80), c:c + rng.integers(10, 80)] = 100
    g[1000:1010, 100:1900] = 100
    t = time.perf_counter()
    cm = Costmap(OccupancyMap(g, 0.1, (0.0, 0.0)), Footprint(6.05, 3.37))
    _ = cm.labels
    print(f"costmap 2000x2000 build (inflation + components, once per map): {(time.perf_counter() - t) * 1e3:.0f} ms")
    planner = GridPlanner()
    times = []
    starts_goals = [((5, 5), (195, 195)), ((195, 5), (5, 195)), ((5, 100), (195, 120)), ((100, 5), (100, 195))]
    for i in range(20):
        s, goal = starts_goals[i % len(starts_goals)]
        if cm.blocked[cm.map.world_to_cell(*s)] or cm.blocked[cm.map.world_to_cell(*goal)]:
            continue
        t = time.perf_counter()
        path = planner.plan(cm, s, goal)
        times.append(time.perf_counter() - t)
    print(f"global plan 200 m x 200 m @ 0.1 m (goal < 200 ms): {summary_ms(times)}; last path {len(path)} points")


def bench_controller() -> None:
    from tms_rp.ic120.config import load_nav_config
    from tms_rp.ic120.controller import TrackedPurePursuit

    cfg = load_nav_config()
    ctl = TrackedPurePursuit(cfg.controller, cfg.limits)
    s = np.linspace(0, 200, 2001)
    path = np.column_stack([s, 5 * np.sin(s / 20)])
    ctl.set_path(path, 1, 0.0)
    times = []
    x, y, yaw = 0.0, 0.0, 0.2
    for _ in range(3000):
        t = time.perf_counter()
        cmd = ctl.compute((x, y, yaw), 0.05)
        times.append(time.perf_counter() - t)
        x += cmd.v * 0.05 * math.cos(yaw)
        y += cmd.v * 0.05 * math.sin(yaw)
        yaw += cmd.w * 0.05
    print(f"controller step (goal < 2 ms): {summary_ms(times)}")


def bench_ekf() -> None:
    from tests.ic120.synth import simulate
    from tms_rp.ic120.ekf import Ic120Ekf

    samples = simulate(120.0)
    ekf = Ic120Ekf()
    t_odom, t_gnss, t_az = [], [], []
    for s in samples:
        t = time.perf_counter()
        ekf.odometry(s.t, *s.odom)
        t_odom.append(time.perf_counter() - t)
        t = time.perf_counter()
        ekf.gnss(s.t, *s.gnss)
        t_gnss.append(time.perf_counter() - t)
        t = time.perf_counter()
        ekf.azimuth(s.t, s.azimuth)
        t_az.append(time.perf_counter() - t)
    print(f"EKF odometry predict: {summary_ms(t_odom)}")
    print(f"EKF GNSS update (gated): {summary_ms(t_gnss)}")
    print(f"EKF azimuth update: {summary_ms(t_az)}")
    # accuracy on synthetic data (same cases as tests/ic120/test_localization_core.py)
    from tests.ic120.test_localization_core import _run

    _, err, _, _ = _run(simulate(120.0, gnss_sigma=0.02, slip=0.04))
    print(f"synthetic localisation RMS (2 cm GNSS, 4 % slip): {math.sqrt(float(np.mean(err[10:] ** 2))) * 100:.2f} cm")
    _, err, tr, _ = _run(simulate(60.0), outage=(20.0, 30.0))
    print(f"10 s GNSS outage: max error {err[200:299].max():.3f} m, cov trace x{tr[298] / tr[199]:.0f}")
    _, err, _, res = _run(simulate(60.0), jump=(30.0, 33.0))
    print(f"5 m GNSS jump for 3 s: {sum(not r.accepted for r in res)}/{len(res)} fixes rejected, max error {err[300:330].max():.3f} m")


def _ekf_loop_route(seed: int):  # noqa: ANN202
    """One paper cycle with the EKF in the loop on the kinematic model; returns final errors and collisions."""
    from tests.ic120.harness import paper_legs, site_points
    from tests.ic120.kinematics import TrackedModel
    from tms_rp.ic120.config import load_nav_config
    from tms_rp.ic120.ekf import Ic120Ekf

    rng = np.random.default_rng(seed)
    cfg = load_nav_config()
    nav = cfg.build_navigator()
    pts = site_points()
    sx, sy, syaw = pts["ic120_start"]
    model = TrackedModel((sx + rng.normal(0, 0.3), sy + rng.normal(0, 0.3), syaw + rng.normal(0, 0.05)), dt=0.05,
                         slip=0.05 + rng.uniform(-0.02, 0.02), yaw_slip=0.15 + rng.uniform(-0.05, 0.05))
    ekf = Ic120Ekf(cfg.ekf)
    odom = [0.0, 0.0, model.yaw]
    t = 0.0
    results = {}
    trace = []
    for leg, name in zip(paper_legs(pts), ("P1", "P5"), strict=True):
        nav.start(leg, yaw_at_each=False)
        status = "RUNNING"
        while status == "RUNNING" and t < 2000:
            # odometry: the bridge integrates measured track speeds with the azimuth sensor's yaw
            ekf.odometry(t, *odom)
            ekf.gnss(t, model.x + rng.normal(0, 0.02), model.y + rng.normal(0, 0.02))
            ekf.azimuth(t, model.yaw + rng.normal(0, 0.005))
            step = nav.step(ekf.pose, t, model.dt)
            px, py = model.x, model.y
            model.step(step.v, step.w)
            reported = math.hypot(model.x - px, model.y - py) / (1 - model.slip) * (1 if step.v >= 0 else -1)
            odom = [odom[0] + reported * math.cos(model.yaw), odom[1] + reported * math.sin(model.yaw), model.yaw]
            trace.append((model.x, model.y, model.yaw))
            t += model.dt
            status = step.status
        for _ in range(40):
            s = nav.step(ekf.pose, t, model.dt)
            model.step(s.v, s.w)
            t += model.dt
        goal = leg[-1]
        results[name] = (status, math.hypot(model.x - goal[0], model.y - goal[1]),
                         abs((model.yaw - goal[2] + math.pi) % (2 * math.pi) - math.pi))
    tr = np.array(trace)
    hits = int(nav.costmap.footprint_hits(tr[:, 0], tr[:, 1], tr[:, 2]).sum())
    return results, hits, t


def bench_route(runs: int = 20) -> None:
    errs = {"P1": ([], []), "P5": ([], [])}
    fails, hits_total, sim_time = 0, 0, []
    t0 = time.perf_counter()
    for seed in range(runs):
        res, hits, t = _ekf_loop_route(seed)
        hits_total += hits
        sim_time.append(t)
        for name, (status, exy, eyaw) in res.items():
            fails += status != "SUCCEEDED"
            errs[name][0].append(exy)
            errs[name][1].append(eyaw)
    print(f"paper route x{runs} (kinematic model + EKF in the loop; {time.perf_counter() - t0:.0f} s wall, "
          f"{statistics.mean(sim_time):.0f} s simulated per run): {fails} failed legs, {hits_total} footprint collisions")
    for name, (exy, eyaw) in errs.items():
        print(f"  {name}: final error p95 {percentile(exy, 95):.3f} m / {percentile(eyaw, 95):.3f} rad "
              f"(max {max(exy):.3f} m / {max(eyaw):.3f} rad; goal < 0.2 m / 0.1 rad)")


def bench_plant_route(runs: int) -> None:
    """Runs of the paper route through the MuJoCo plant over COM3 CAN (real time)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tests.ic120.harness import paper_legs, site_points
    from tests.ic120.rosutil import ActionCall, Truth, pose_stamped, spin_for, spin_until
    from tests.ic120.stack import start_ours, start_plant_and_bridge
    from tests.rosproc import Proc, isolated_domain, ros_env
    from tms_msg.action import NavigateThroughPoses
    from tms_rp.ic120.config import load_nav_config

    pts = site_points()
    costmap = load_nav_config().build_costmap()
    errs = {"P1": ([], []), "P5": ([], [])}
    started: list[Proc] = []
    with isolated_domain() as domain:
        def procs(cmd, name=None):  # noqa: ANN001, ANN202
            p = Proc([str(c) for c in cmd], ros_env(domain), name=name)
            started.append(p)
            return p

        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        ctx = Context()
        rclpy.init(context=ctx, domain_id=domain)
        node = rclpy.create_node("bench_ic120", context=ctx)
        node.executor_for_test = SingleThreadedExecutor(context=ctx)
        node.executor_for_test.add_node(node)
        try:
            start_plant_and_bridge(procs, domain)
            start_ours(procs)
            truth = Truth(node)
            assert spin_until(node, lambda: len(truth.poses) > 5, 60.0)
            spin_for(node, 3.0)
            for _ in range(runs):
                for leg, name in zip(paper_legs(pts), ("P1", "P5"), strict=True):
                    goal = NavigateThroughPoses.Goal()
                    goal.poses = [pose_stamped(*p) for p in leg]
                    status, result = ActionCall(node, NavigateThroughPoses, "/ic120/navigate_through_poses", goal).wait(400.0)
                    spin_for(node, 1.0)
                    x, y, yaw = truth.last
                    g = leg[-1]
                    errs[name][0].append(math.hypot(x - g[0], y - g[1]))
                    errs[name][1].append(abs((yaw - g[2] + math.pi) % (2 * math.pi) - math.pi))
                    print(f"  plant {name}: status {status} code {result.error_code} error {errs[name][0][-1]:.3f} m "
                          f"{errs[name][1][-1]:.3f} rad", flush=True)
            tr = np.array([p[1:] for p in truth.poses])
            hits = int(costmap.footprint_hits(tr[:, 0], tr[:, 1], tr[:, 2]).sum())
        finally:
            for p in started:
                p.kill()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
    print(f"paper route x{runs} through sim_plant over COM3 CAN: {hits} footprint collisions")
    for name, (exy, eyaw) in errs.items():
        print(f"  {name}: final error p95 {percentile(exy, 95):.3f} m / {percentile(eyaw, 95):.3f} rad")


def main() -> None:
    bench_planner()
    bench_controller()
    bench_ekf()
    bench_route(20)
    plant_runs = int(os.environ.get("IC120_BENCH_PLANT_RUNS", "0"))
    if plant_runs:
        bench_plant_route(plant_runs)


if __name__ == "__main__":
    main()
