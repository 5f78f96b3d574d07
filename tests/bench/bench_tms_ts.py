"""tms_ts figures: tick overhead per node, leaf round trip through a subtask server, 10 tasks at 50 Hz.

1. A 200-node tree (ReactiveSequence over groups of AlwaysSuccess / SetLocalBlackboard /
   ConditionalExpression, ending in a RUNNING KeepRunningUntilFailure) ticks all 200 nodes per tick;
   time per tick / 200 = overhead per node (goal < 20 us).
2. LeafNode round trip: this process sends LeafNodeBase goals exactly as the manager does (ManagerRosPort)
   to a ``tms_ts_subtasks`` process, which reads the DB record and calls a planning stub process that
   succeeds at once; goal sent -> SUCCEEDED seen.
3. A ``tms_ts_manager`` process at 50 Hz running 10 tasks (endless loops of a LeafNode, a DB read, a DB write
   and an expression) against subtask servers and planning stubs: at nice 0, at nice -10, with
   ``realtime_priority`` 10, then that with ``db_checkpoint_period_s`` 0 (the WAL checkpoint back inside the
   tick's flag writes); its ``/tms_ts/tick_stats`` gives ticks, missed ticks and tick durations.
4. The executor's share: the same manager node in this process, the same 10 tasks, ``TS_EXEC_S`` seconds
   on the SingleThreadedExecutor and then on ``events`` (tms_common.node.make_executor): ticks, missed
   ticks, goals completed and the process's CPU (rusage) per second and per tick.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time

from tests.bench.stats import summary_ms
from tests.rosproc import ROOT, Proc, executable, isolated_domain, ros_env

N_GOALS = 100
LOAD_SECONDS = 30.0
EXEC_SECONDS = float(os.environ.get("TS_EXEC_S", "20"))


def _tree_200(mixed: bool = True) -> str:
    group = ('<Sequence><AlwaysSuccess/><Action ID="SetLocalBlackboard" value="{i}" output_key="k{i}"/>'
             '<Condition ID="ConditionalExpression" conditional_expression="k{i} == {i} and FLG == true"/></Sequence>')
    if not mixed:
        group = "<Sequence><AlwaysSuccess/><AlwaysSuccess/><AlwaysSuccess/></Sequence>"
    body = "".join(group.format(i=i) for i in range(49))
    xml = (f'<root><BehaviorTree ID="B"><ReactiveSequence><AlwaysSuccess/>{body}'
           f"<KeepRunningUntilFailure><AlwaysSuccess/></KeepRunningUntilFailure></ReactiveSequence></BehaviorTree></root>")
    return xml


def _tick_overhead() -> list[str]:
    from tms_ts.bt.core import RUNNING
    from tms_ts.loader import load_tree

    out = []
    for label, xml in (("mixed (SetLocalBlackboard, ConditionalExpression, AlwaysSuccess)", _tree_200()),
                       ("AlwaysSuccess only", _tree_200(mixed=False))):
        tree = load_tree(xml)
        tree.ctx.blackboard.set("FLG", True)
        assert len(tree.nodes) == 200, len(tree.nodes)
        assert tree.tick() is RUNNING
        n = 2000
        samples = []
        for _ in range(5):
            start = time.perf_counter()
            for _ in range(n):
                tree.tick()
            samples.append((time.perf_counter() - start) / n)
        best = min(samples)
        out.append(f"tick overhead, 200-node tree, {label}: {best / 200 * 1e6:.2f} us/node "
                   f"({best * 1e3:.3f} ms/tick, best of 5 x {n} ticks)")
    return out


def _seed(db: str) -> None:
    from tms_db import open_store

    with open_store(path=db) as store:
        store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "initial_pose", "trajectory": 1,
                                "swing_joint": 0.0, "boom_joint": -0.3, "arm_joint": 1.2, "bucket_joint": 0.5})
        store.upsert_parameter({"model_name": "ic120", "type": "static", "record_name": "load_point",
                                "x": 10.0, "y": 2.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0})
        store.upsert_parameter({"record_name": "BENCH_BB", "type": "dynamic", "FLG": True, "N": 0})
        for i in range(10):
            model, leaf, subtask, record = (("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose")
                                            if i % 2 else ("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere",
                                                           "load_point"))
            xml = (
                f'<root><BehaviorTree ID="B"><Repeat num_cycles="-1"><Sequence>'
                f'<Action ID="{leaf}" model_name="{model}" subtask_name="{subtask}" record_name="{record}"/>'
                '<Action ID="BlackboardValueReaderMongo" output_port="flg" mongo_record_name="BENCH_BB" '
                'mongo_param_name="FLG"/>'
                f'<Action ID="MongoValueWriter" input_value="{i}" mongo_record_name="BENCH_BB" '
                f'mongo_param_name="T{i}"/>'
                f'<Condition ID="ConditionalExpression" conditional_expression="flg == true"/>'
                f"</Sequence></Repeat></BehaviorTree></root>"
            )
            store.add_task(xml, task_id=100 + i, description=f"bench task {i}")


def _start_servers(domain: int, db: str, duration: float) -> list[Proc]:
    env = ros_env(domain, PYTHONPATH=str(ROOT))
    procs = [Proc([sys.executable, "-m", "tests.tms_ts.planning_stub", "--ros-args", "-p", f"duration_s:={duration}"],
                  env, name="stub")]
    for machine in ("zx200", "ic120"):
        procs.append(Proc([str(executable("tms_ts", "tms_ts_subtasks")), "--ros-args", "-p", f"machine:={machine}",
                           "-p", f"db_path:={db}", "-p", "planning_wait_s:=30.0"], env, name=machine))
    for p in procs:
        if not p.wait_for("ready" if p.name == "stub" else "subtask servers", 60):
            raise RuntimeError(f"{p.name} did not start:\n{p.output}")
    return procs


def _round_trip(domain: int, db: str) -> str:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tms_ts.leaf import ACCEPTED, PENDING, SUCCEEDED
    from tms_ts.nodes.ros_port import ManagerRosPort

    procs = _start_servers(domain, db, 0.0)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("bench_leaf", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    port = ManagerRosPort(node)
    times: list[float] = []
    try:
        deadline = time.monotonic() + 30
        while not port.subtask_server_ready("zx200", "subtask_zx200_change_pose") and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        for i in range(N_GOALS + 5):
            start = time.perf_counter()
            goal = port.send_subtask_goal("zx200", "subtask_zx200_change_pose", "initial_pose")
            limit = time.monotonic() + 30
            while goal.state in (PENDING, ACCEPTED) and time.monotonic() < limit:
                ex.spin_once(timeout_sec=0.01)
            if goal.state != SUCCEEDED:
                raise RuntimeError(f"goal {i} ended {goal.state}: {goal.message}")
            if i >= 5:  # warm-up
                times.append(time.perf_counter() - start)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        for p in procs:
            p.kill()
    return f"leaf goal -> result through tms_ts_subtasks (DB read + planning goal): {summary_ms(times)}"


def _ten_tasks(domain: int, db: str, nice: int = 0, rt: int = 0, checkpoint_s: float = 1.0) -> str:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Bool, String

    from tms_msg.msg import TaskIds, TaskState, TaskStatus

    procs = _start_servers(domain, db, 0.2)
    env = ros_env(domain)
    manager = Proc(
        [
            "nice",
            "-n",
            str(nice),
            str(executable("tms_ts", "tms_ts_manager")),
            "--ros-args",
            "-p",
            f"db_path:={db}",
            "-p",
            "tick_rate_hz:=50.0",
            "-p",
            "server_wait_s:=30.0",
            "-p",
            f"realtime_priority:={rt}",
            "-p",
            f"db_checkpoint_period_s:={checkpoint_s}",
        ],
        env,
        name="manager",
    )
    procs.append(manager)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("bench_probe", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    stats: list[dict] = []
    status: list[TaskStatus] = []
    node.create_subscription(String, "/tms_ts/tick_stats", lambda m: stats.append(json.loads(m.data)), 10)
    node.create_subscription(TaskStatus, "/tms_ts/status", status.append, 10)
    start_pub = node.create_publisher(TaskIds, "/tms_ts/start", 10)
    emg_pub = node.create_publisher(Bool, "/emergency_signal", 10)

    def spin(seconds: float, until=None) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
            if until is not None and until():
                return

    try:
        if not manager.wait_for("tms_ts_manager ready", 60):
            raise RuntimeError(manager.output)
        spin(30, lambda: start_pub.get_subscription_count() > 0)
        start_pub.publish(TaskIds(task_ids=list(range(100, 110))))

        def all_running() -> bool:
            return bool(status) and sum(1 for t in status[-1].tasks if t.state == TaskState.RUNNING
                                        and t.running_leaves) == 10

        spin(60, all_running)
        base = stats[-1] if stats else {"ticks": 0, "missed": 0}
        spin(LOAD_SECONDS)
        last = stats[-1]
        failed = [t for t in status[-1].tasks if t.state != TaskState.RUNNING]
        emg_pub.publish(Bool(data=True))
        spin(30, lambda: status and all(t.state == TaskState.CANCELED for t in status[-1].tasks))
        canceled = sum(1 for t in status[-1].tasks if t.state == TaskState.CANCELED)
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        for p in procs:
            p.kill()
    ticks = last["ticks"] - base["ticks"]
    missed = last["missed"] - base["missed"]
    how = (f"SCHED_FIFO {rt}" if rt else f"nice {nice}") + (
        f", WAL checkpoint every {checkpoint_s:g} s in a thread"
        if checkpoint_s
        else ", SQLite's automatic WAL checkpoint"
    )
    return (
        f"10 tasks at 50 Hz for {LOAD_SECONDS:g} s, manager at {how}: {ticks} ticks (expected "
        f"{int(LOAD_SECONDS * 50)}), "
        f"missed {missed}, mean tick {last['mean_tick_ms']:.2f} ms, max tick {last['max_tick_ms']:.1f} ms, "
        f"max late {last['max_late_ms']:.1f} ms; tasks not running at the end: {len(failed)}; "
        f"after /emergency_signal {canceled}/10 CANCELED"
    )


def _manager_on(kind: str, domain: int, db: str) -> str:
    import resource

    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.task import Future

    from tms_common.node import make_executor
    from tms_ts.leaf import SUCCEEDED
    from tms_ts.nodes.tms_ts_manager import TaskManager

    procs = _start_servers(domain, db, 0.2)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = TaskManager(context=ctx, parameter_overrides=[
        Parameter("db_path", value=db), Parameter("tick_rate_hz", value=50.0), Parameter("server_wait_s", value=30.0)])
    ex = make_executor(kind, context=ctx)
    ex.add_node(node)
    done = [0]
    sent = node.ros.send_subtask_goal

    def counted(*args, **kwargs):  # count the goals that end SUCCEEDED
        goal = sent(*args, **kwargs)
        on_result = goal._on_result

        def on_result_counted(future):
            on_result(future)
            done[0] += goal.state == SUCCEEDED
        goal._on_result = on_result_counted
        return goal
    node.ros.send_subtask_goal = counted

    def spin_for(seconds: float) -> None:
        if kind == "events":
            ex.spin_until_future_complete(Future(), timeout_sec=seconds)
            return
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.1)

    try:
        for task_id in range(100, 110):
            node.start_task(task_id)
        spin_for(10.0)  # servers found, every task looping
        s0, d0, r0, w0 = dict(node._stats), done[0], resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
        spin_for(EXEC_SECONDS)
        s1, r1, wall = node._stats, resource.getrusage(resource.RUSAGE_SELF), time.monotonic() - w0
        running = sum(1 for r in node.runs.values() if not r.done)
    finally:
        ex.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        for p in procs:
            p.kill()
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    ticks, missed = s1["ticks"] - s0["ticks"], s1["missed"] - s0["missed"]
    return (f"manager on {kind:6s}: {ticks} ticks of {wall * 50:.0f} in {wall:.1f} s, missed {missed}, "
            f"{done[0] - d0} goals succeeded, {running}/10 tasks running; process CPU {cpu / wall * 100:.1f} % of a "
            f"core, {cpu / max(1, ticks) * 1e3:.2f} ms per tick period served")


def main() -> None:
    for line in _tick_overhead():
        print(line, flush=True)
    with tempfile.TemporaryDirectory() as tmp, isolated_domain() as domain:
        db = f"{tmp}/db"
        _seed(db)
        print(_round_trip(domain, db), flush=True)
        # as a process of its own at nice 0, then at the control path's nice -10 (config/launch: the manager's
        # container), back to back
        for nice in (0, -10):
            print(_ten_tasks(domain, db, nice), flush=True)
        # and with the manager's tick thread under SCHED_FIFO (realtime_priority; refused without CAP_SYS_NICE,
        # which the manager's log says)
        print(_ten_tasks(domain, db, rt=10), flush=True)
        # and SCHED_FIFO with the WAL checkpoint back inside the flag writes of the tick (db_checkpoint_period_s 0)
        print(_ten_tasks(domain, db, rt=10, checkpoint_s=0.0), flush=True)
        for kind in ("single", "events"):
            print(_manager_on(kind, domain, db), flush=True)


if __name__ == "__main__":
    main()
