"""ZX200 arm benchmark: (1) the pure core against the first-order-lag + dead-time model, (2) the whole
stack (sim_plant MuJoCo + com3_bridge + excavator_arm_controller + zx200_planner, separate processes, COM3
CAN over udp_multicast) with goals sent over ROS and accuracy from the plant's truth.

Prints for each: success rate of 100 random reachable targets of each kind (joint / pose / position+theta_w)
within 3 cm and 2 deg with zero limit violations, QP solve time per control step (median, p99), the RMS
tip tracking error of a 2 m Cartesian move, and the period jitter of a 100 Hz control loop. The core also
replays the QP problems of its first 12,000 control steps 5 times and reports the per-step minimum thread CPU
time: the solve's own cost, which a machine loaded by other jobs cannot inflate (the live figures can).
Run: ``.venv/bin/python -m tests.bench zx200`` (``ZX200_BENCH_N`` = targets per kind, default 100, for the
core; ``ZX200_BENCH_PLANT_N`` for the plant, default = ZX200_BENCH_N; ``ZX200_BENCH_PLANT=0`` skips the plant,
``ZX200_BENCH_CORE=0`` the core; ``ZX200_BENCH_SPEED`` = the plant's real-time factor, default 1.0). A target that fails
(rejected, timed out, no result) is counted and reported;
it never aborts the campaign.
In the plant: limit violations = joint_states samples outside the position limits (> 1 mrad) or above the
velocity limits (> 2 %); the 2 m move reports the truth tip's RMS distance from the straight reference line;
jitter is the period of ``/zx200/front_cmd`` as received by the probe.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pinocchio as pin

from tests.bench.stats import summary_ms
from tms_model.excavator import codes
from tms_model.excavator.codes import PlanningError
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.controller import ArmController, load_controller_config
from tms_rc.excavator.plant import LagDeadTimePlant
from tms_rp.arm.planner import ArmPlanner, load_planner_config

#: at most this many control steps of QP problems are recorded for the solve-alone replay
_RECORD_STEPS = 12000
_HQPS = ("hqp_cartesian", "hqp_joint")


class _Recording:
    """The (A, b) of every level the controllers' hierarchies got, flat in one preallocated array.

    One array, not a list of arrays per step: ~10^5 small Python containers held for the whole campaign
    made the cyclic garbage collector's full passes (milliseconds) land inside the timed solves.
    """

    def __init__(self, width: int = 256) -> None:
        self.data = np.zeros((_RECORD_STEPS, width))
        self.which = np.zeros(_RECORD_STEPS, dtype=np.int8)  # index into _HQPS
        self.run = np.zeros(_RECORD_STEPS, dtype=np.int32)  # controller (fresh solvers) the step belongs to
        self.steps = 0
        self.runs = 0

    def attach(self, ctl: ArmController) -> None:
        """Record what ``ctl`` solves from now on, as a new run."""
        run = self.runs
        self.runs += 1
        for i, name in enumerate(_HQPS):
            hqp = getattr(ctl, name)

            def recording(tasks, _solve=hqp.solve, _i=i, _run=run):
                if self.steps < _RECORD_STEPS:
                    flat = np.concatenate([np.ravel(np.asarray(x, dtype=float)) for task in tasks for x in task])
                    self.data[self.steps, : flat.size] = flat
                    self.which[self.steps], self.run[self.steps] = _i, _run
                    self.steps += 1
                return _solve(tasks)

            hqp.solve = recording

    def replay(self, kin, cfg, repeats: int = 5) -> list[float]:
        """Solve the recorded steps again ``repeats`` times (fresh, warm-started solvers per run, as in the
        campaign) and return, per step, the smallest thread CPU time: the cost of the solve itself, without
        what a loaded machine adds (preemption, another process on the sibling hyperthread, cache misses)."""
        best = np.full(self.steps, np.inf)
        for _ in range(repeats):
            run, hqps = -1, []
            for k in range(self.steps):
                if self.run[k] != run:
                    run = self.run[k]
                    ctl = ArmController(kin, cfg)
                    hqps = [getattr(ctl, name) for name in _HQPS]
                hqp = hqps[self.which[k]]
                tasks, pos = [], 0
                for lv in hqp.levels:
                    a = self.data[k, pos : pos + lv.rows * hqp.n].reshape(lv.rows, hqp.n)
                    pos += lv.rows * hqp.n
                    tasks.append((a, self.data[k, pos : pos + lv.rows]))
                    pos += lv.rows
                best[k] = min(best[k], hqp.solve(tasks).solve_cpu_s)
        return best.tolist()


def _run(kin, cfg, q0, targets, solve_times, max_steps=8000, cpu_times=None, record=None):
    ctl = ArmController(kin, cfg)
    if record is not None:
        record.attach(ctl)
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    q, v = q0.copy(), np.zeros(4)
    ctl.start(targets)
    violations, errs = 0, []
    for _ in range(max_steps):
        u = ctl.step(q, v)
        solve_times.append(ctl.last_result.solve_time_s)
        if cpu_times is not None:
            cpu_times.append(ctl.last_result.solve_cpu_s)
        # pump flow of the velocities that act together (delays equalised per joint: the solved u_prev)
        if np.sum(cfg.flow_per_rad_s * np.abs(ctl.u_prev)) > cfg.pump_flow_lpm * 1.001 or np.any(
            np.abs(u) > kin.limits.velocity + 1e-9
        ):
            violations += 1
        q, v = plant.step(u)
        if kin.limits.violation(q) is not None:
            violations += 1
        if ctl.reference_tip is not None:
            errs.append(float(np.linalg.norm(kin.tip_position(q) - ctl.reference_tip)))
        if ctl.status.result is not None:
            break
    return ctl.status, q, violations, errs


def core() -> None:
    kin = load_kinematics()
    cfg = load_controller_config(kin.machine)
    planner = ArmPlanner(kin, load_planner_config(kin.machine.kind), ground_min_z=cfg.ground_min_z)
    n = int(os.environ.get("ZX200_BENCH_N", "100"))
    rng = np.random.default_rng(7)
    solve_times: list[float] = []
    cpu_times: list[float] = []
    recorded = _Recording()
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
                    targets = planner.change_pose(
                        joint_names=["swing_joint", "boom_joint", "arm_joint", "bucket_joint"],
                        joint_points=[q_goal.tolist()],
                        current_q=q_start,
                    )
                elif kind == "pose":
                    pose = kin.tip_pose(q_goal)
                    targets = planner.change_pose(
                        poses=[(pose.translation.tolist(), pin.Quaternion(pose.rotation).coeffs().tolist())]
                    )
                else:
                    targets = planner.change_pose(positions_with_angle=[(p_goal.tolist(), kin.theta_w(q_goal))])
            except PlanningError as exc:
                print(f"  planner refused a reachable target: {exc}")
                continue
            status, q_end, viol, _ = _run(kin, cfg, q_start, targets, solve_times, cpu_times=cpu_times, record=recorded)
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
              f"worst {100 * worst_pos:.2f} cm / {math.degrees(worst_ang):.2f} deg, {time.perf_counter() - t0:.0f} s",
              flush=True)
    print("  QP solve time per control step (wall): " + summary_ms(solve_times))
    print("  QP solve time per control step (thread CPU time, without preemption): " + summary_ms(cpu_times))
    replayed = recorded.replay(kin, cfg)
    print("  QP solve alone, the campaign's first recorded steps solved again 5 times (per-step minimum of the thread "
          "CPU time, the load-independent cost): " + summary_ms(replayed))

    q0 = kin.home.copy()
    p0 = kin.tip_position(q0)
    status, q_end, viol, errs = _run(
        kin, cfg, q0, planner.change_pose(positions_with_angle=[((p0 + [-2.0, 0, 0]).tolist(), kin.theta_w(q0))]), []
    )
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


def plant() -> None:  # one campaign
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from com3_msgs.msg import JointCmd
    from tests.arm_stack import ArmStack
    from tests.rosproc import Proc, executable, free_can_ports, isolated_domain, ros_env
    from tests.tms_if_opera.test_plant_integration import joint_goal, pose_goal, pwa_goal

    kin = load_kinematics()
    cfg = load_controller_config(kin.machine)
    n = int(os.environ.get("ZX200_BENCH_PLANT_N", os.environ.get("ZX200_BENCH_N", "100")))
    speed = float(os.environ.get("ZX200_BENCH_SPEED", "1.0"))
    rng = np.random.default_rng(11)
    lo = np.array([-1.5, -1.0, 0.8, -0.3])
    hi = np.array([1.5, -0.2, 2.4, 2.1])
    with isolated_domain() as domain:
        port = free_can_ports(domain, 1)[0]
        bus = ["-p", "zx200_can_interface:=udp_multicast", "-p", f"zx200_can_channel:=239.77.{domain}.9",
               "-p", f"zx200_can_port:={port}"]
        env = ros_env(domain)
        procs = [
            Proc(
                [str(executable("sim_bridge", "sim_plant")), "--ros-args", "-p", f"speed:={speed}", *bus],
                env,
                name="sim",
            )
        ]
        try:
            assert procs[0].wait_for("sim_plant: running", 90), procs[0].output
            procs.append(Proc([str(executable("com3_can", "com3_bridge")), "--ros-args", "-r", "__ns:=/zx200",
                               "-p", "machine:=zx200", "-p", "can_interface:=udp_multicast",
                               "-p", f"can_channel:=239.77.{domain}.9", "-p", f"can_port:={port}",
                               "-p", "use_sim_time:=true"], env, name="bridge"))
            # the planner's waits are wall time; on /clock it would wake every plant step for nothing (as in
            # config/launch/paper_experiment.yaml)
            for pkg, exe, sim_time in (
                ("tms_rc", "excavator_arm_controller", "true"),
                ("tms_if_opera", "zx200_planner", "false"),
            ):
                procs.append(
                    Proc(
                        [
                            str(executable(pkg, exe)),
                            "--ros-args",
                            "-r",
                            "__ns:=/zx200",
                            "-p",
                            f"use_sim_time:={sim_time}",
                        ],
                        env,
                        name=exe,
                    )
                )
            for p, text in zip(
                procs[1:], ("com3_bridge ready", "excavator_arm_controller ready", "zx200_planner ready"), strict=True
            ):
                assert p.wait_for(text, 60), p.output
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
            ctx = Context()
            rclpy.init(context=ctx, domain_id=domain)
            node = rclpy.create_node("zx200_bench_probe", context=ctx)
            node.executor_for_test = SingleThreadedExecutor(context=ctx)
            node.executor_for_test.add_node(node)
            cmd_t: list[float] = []
            node.create_subscription(JointCmd, "/zx200/front_cmd", lambda _m: cmd_t.append(time.monotonic()), 100)
            st = ArmStack(node)
            assert st.spin_until(lambda: st.q is not None and st.tip is not None, 30), "no state from the plant"
            print(f"zx200 bench in the MuJoCo plant over CAN: {n} random reachable targets per kind (speed {speed})")
            violations = 0

            def count_violations(since: float) -> int:
                bad = 0
                for t, q, v in st.dq_log:
                    if t >= since and (kin.limits.violation(np.array(q), margin=1e-3) is not None
                                       or np.any(np.abs(v) > kin.limits.velocity * 1.02)):
                        bad += 1
                return bad

            t_campaign = time.monotonic()
            for kind in ("joint", "pose", "position_with_angle"):
                ok = 0
                worst_p = worst_a = 0.0
                t0 = time.monotonic()
                for _ in range(n):
                    while True:
                        qg = rng.uniform(lo, hi)
                        tip, _, pin_p, _ = kin.jacobians(qg)
                        rho = [np.linalg.norm(x[:2] - kin.swing_origin[:2]) for x in (tip, pin_p)]
                        if min(rho) > cfg.body_min_radius + 0.3 and min(tip[2], pin_p[2]) > 0.3:
                            break
                    goal = {"joint": joint_goal, "pose": pose_goal}.get(kind)
                    g = goal(qg) if goal else pwa_goal(kin.tip_position(qg), kin.theta_w(qg))
                    try:  # a failed target is counted and reported; it never aborts the campaign
                        status, res = st.run("change_pose", g, timeout=180)
                    except AssertionError as exc:
                        print(f"    miss: {kind} target q={np.round(qg, 3).tolist()}: {exc}")
                        st.spin(2.0)
                        continue
                    st.spin(0.3)
                    q_end = np.array(st.q)
                    perr = float(np.linalg.norm(np.array(st.tip) - kin.tip_position(qg)))
                    if kind == "joint":
                        d = q_end - qg
                        d[0] = math.atan2(math.sin(d[0]), math.cos(d[0]))
                        aerr = float(np.max(np.abs(d)))
                    else:
                        aerr = abs(kin.theta_w(q_end) - kin.theta_w(qg))
                    worst_p, worst_a = max(worst_p, perr), max(worst_a, aerr)
                    if status == 4 and perr < 0.03 and aerr < math.radians(2):
                        ok += 1
                    else:
                        # where the error lies: the controller's view (FK of the measured joints) or the plant's truth
                        fk_err = float(np.linalg.norm(kin.tip_position(q_end) - kin.tip_position(qg)))
                        truth_vs_fk = float(np.linalg.norm(np.array(st.tip) - kin.tip_position(q_end)))
                        print(
                            f"    miss: {kind} status {status} {res.message!r} {100 * perr:.1f} cm "
                            f"{math.degrees(aerr):.2f} deg "
                            f"(FK of measured joints {100 * fk_err:.1f} cm off the target, "
                            f"truth {100 * truth_vs_fk:.1f} cm off that FK), target q={np.round(qg, 3).tolist()}, "
                            f"end q={np.round(q_end, 4).tolist()}",
                            flush=True,
                        )
                took = time.monotonic() - t0
                print(
                    f"  {kind:20s}: {ok}/{n} within 3 cm / 2 deg ({100.0 * ok / n:.0f}%), "
                    f"worst {100 * worst_p:.2f} cm / "
                    f"{math.degrees(worst_a):.2f} deg, {took:.0f} s ({took / n:.1f} s per target)",
                    flush=True,
                )
            violations = count_violations(t_campaign)
            print(f"  limit violations over the run (joint_states samples): {violations} of "
                  f"{sum(1 for t, _, _ in st.dq_log if t >= t_campaign)}")
            # 2 m Cartesian move (tip 2 m towards the machine, constant theta_w) from a mid pose
            q0 = np.array([0.0, -0.6, 1.5, 1.0])
            st.run("change_pose", joint_goal(q0), timeout=120)
            st.spin(1.0)
            p0 = np.array(st.tip)
            p1 = p0 + np.array([-2.0, 0.0, 0.0])
            th0 = kin.theta_w(np.array(st.q))
            tips: list[np.ndarray] = []
            from geometry_msgs.msg import PointStamped

            node.create_subscription(PointStamped, "/sim/truth/zx200/bucket_tip",
                                     lambda m: tips.append(np.array([m.point.x, m.point.y, m.point.z])), 100)
            cmd_t.clear()
            status, res = st.run("change_pose", pwa_goal(p1, th0), timeout=120)
            u = (p1 - p0) / np.linalg.norm(p1 - p0)
            dev = [float(np.linalg.norm((t - p0) - np.clip((t - p0) @ u, 0, 2.0) * u)) for t in tips]
            print(f"  2 m Cartesian move: status {status}, RMS distance from the straight reference line "
                  f"{1000 * math.sqrt(np.mean(np.square(dev))):.1f} mm, max {1000 * max(dev):.1f} mm "
                  f"({len(dev)} truth samples), end error {1000 * float(np.linalg.norm(np.array(st.tip) - p1)):.1f} mm")
            periods = np.diff(np.array(cmd_t))
            jit = np.abs(periods - cfg.dt)
            print(f"  front_cmd period at the probe (100 Hz, sim time at speed {speed}): {summary_ms(list(periods))}; "
                  f"|period - 10 ms| median {1000 * np.median(jit):.3f} ms, p99 {1000 * np.percentile(jit, 99):.3f} ms")
            node.executor_for_test.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
        finally:
            for p in procs:
                p.kill()


def main() -> None:
    print(f"load average at start: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f} "
          f"({os.cpu_count()} CPUs)")
    if os.environ.get("ZX200_BENCH_CORE", "1") != "0":
        core()
    if os.environ.get("ZX200_BENCH_PLANT", "1") != "0":
        plant()


if __name__ == "__main__":
    main()
