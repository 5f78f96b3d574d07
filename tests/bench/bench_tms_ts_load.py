"""tms_ts manager under a 5 MB tree and under many finished runs (issue 38, item 3).

1. **A 5 MB tree sent while two tasks run.** A ``tms_ts_manager`` process at 20 Hz (``manager_probe.py``, which
   notes when each tick starts) runs tasks 1 and 2 (each tick reads a DB flag, then a Sleep keeps them RUNNING).
   This process sends a 172,707-node tree (5.2 MB: a Sequence whose first child fails, then 172,705
   AlwaysSuccess) on ``/task_sequence``, 0.5 s later ``/tms_ts/cancel`` for task 1; then a second such tree and
   0.5 s later ``/emergency_signal``. Printed: the tick lateness (gap between two tick starts minus the period)
   while the trees load and over the whole run (max, p99, ticks late by more than half a period), how long
   the cancel and the emergency stop took to show CANCELED on ``/tms_ts/status``, and what became of the
   big trees (the log's line). ``TS_LOAD_OLD=/tmp/old`` runs the same against the code checked out there
   (``git worktree add --detach /tmp/old <commit>``; several paths separated by ``:``), after this code's run
   (``TS_LOAD_SKIP_NEW=1``: without it).
2. **RSS with 100 finished runs.** A manager with ``status_rate_hz`` 10 and ``finished_retention_s`` 3600 runs
   100 tasks of 1000 nodes each to SUCCESS, then publishes its status for ``TS_RSS_S`` seconds (600 by
   default, the issue's 10 minutes) while this process subscribes to it. Printed: the manager's RSS every
   ``TS_RSS_S / 10`` s, the status messages' size and how many carried a snapshot after the runs ended.
   ``TS_RSS_OLD_S`` (60) seconds of the same against ``TS_LOAD_OLD`` when it is set.

``.venv/bin/python -m tests.bench tms_ts_load``
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

from tests.bench.stats import percentile
from tests.rosproc import ROOT, Proc, isolated_domain, ros_env

PROBE = Path(__file__).with_name("manager_probe.py")
RATE_HZ = 20.0
BIG_NODES = 172_707
RSS_SECONDS = float(os.environ.get("TS_RSS_S", "600"))
RSS_OLD_SECONDS = float(os.environ.get("TS_RSS_OLD_S", "60"))
#: tick lateness is taken from a tree's sending for at least this long (and until its start was over)
WINDOW_S = 3.0

RUNNING_TREE = (
    '<root><BehaviorTree ID="B"><ReactiveSequence>'
    '<Action ID="BlackboardValueReaderMongo" output_port="flg" mongo_record_name="BENCH_BB" mongo_param_name="FLG"/>'
    '<Sleep msec="3600000"/></ReactiveSequence></BehaviorTree></root>'
)


def big_tree(nodes: int = BIG_NODES, tag: str = "") -> str:
    """A valid tree of ``nodes`` nodes (about 30 bytes each) that ends FAILURE at its first tick."""
    body = "".join(f'<AlwaysSuccess name="{tag}s{i}"/>' for i in range(nodes - 2))
    return (f'<root BTCPP_format="4" main_tree_to_execute="Big"><BehaviorTree ID="Big"><Sequence>'
            f"<AlwaysFailure/>{body}</Sequence></BehaviorTree></root>")


def finishing_tree(nodes: int = 1000) -> str:
    """``nodes`` nodes that end SUCCESS at the first tick."""
    body = "".join(f'<AlwaysSuccess name="a{i}"/>' for i in range(nodes - 1))
    return (f'<root BTCPP_format="4" main_tree_to_execute="T"><BehaviorTree ID="T"><Sequence>{body}'
            f"</Sequence></BehaviorTree></root>")


def seed(db: str, finished: int = 0) -> None:
    from tms_db import open_store

    with open_store(path=db) as store:
        store.upsert_parameter({"record_name": "BENCH_BB", "type": "dynamic", "FLG": True})
        store.add_task(RUNNING_TREE, task_id=1, description="reads a flag every tick")
        store.add_task(RUNNING_TREE.replace('"B"', '"B2"'), task_id=2, description="reads a flag every tick")
        for i in range(finished):
            store.add_task(finishing_tree().replace('"T"', f'"T{i}"'), task_id=100 + i, description="ends at once")


def start_manager(domain: int, db: str, ticks: str, code: str | None, *params: str) -> Proc:
    env = ros_env(domain, TMS_PROBE_TICKS=ticks, PYTHONPATH=code or str(ROOT))
    manager = Proc([sys.executable, str(PROBE), "--ros-args", "-r", "__node:=tms_ts_manager", "-p", f"db_path:={db}",
                    "-p", f"tick_rate_hz:={RATE_HZ}", *params], env, name="manager")
    if not manager.wait_for("tms_ts_manager ready", 60):
        raise RuntimeError(f"manager did not start:\n{manager.output}")
    return manager


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def tick_times(path: str) -> list[float]:
    try:
        return [float(x) for x in Path(path).read_text().split()]
    except FileNotFoundError:
        return []


def lateness_ms(times: list[float], start: float = 0.0, end: float = float("inf")) -> list[float]:
    """Per tick starting in [start, end]: gap to the previous tick start minus the period [ms] (as the manager
    counts)."""
    period = 1.0 / RATE_HZ
    return [max(0.0, (b - a - period) * 1e3) for a, b in zip(times, times[1:], strict=False) if start <= b <= end]


def late_summary(late: list[float]) -> str:
    if not late:
        return "no ticks"
    missed = sum(1 for x in late if x > 0.5e3 / RATE_HZ)
    return (f"max {max(late):.1f} ms, p99 {percentile(late, 99):.1f} ms, {missed} of {len(late)} ticks "
            f"more than half a period late")


class Probe:
    """This process's ROS side: publishers, the status and the log lines it needs."""

    def __init__(self, domain: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from std_msgs.msg import Bool, Int32, String

        from tms_msg.msg import TaskIds, TaskStatus

        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node("bench_load_probe", context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.status: list[tuple[float, object]] = []
        self.keep_status = True
        self.sizes: list[int] = []
        self.with_snapshot_after: dict[int, int] = {}
        self.ended_at: float | None = None
        self.node.create_subscription(TaskStatus, "/tms_ts/status", self._on_status, reliable)
        self.pubs = {"start": self.node.create_publisher(TaskIds, "/tms_ts/start", reliable),
                     "seq": self.node.create_publisher(String, "/task_sequence", reliable),
                     "cancel": self.node.create_publisher(Int32, "/tms_ts/cancel", reliable),
                     "emg": self.node.create_publisher(Bool, "/emergency_signal", reliable)}
        self.TaskIds, self.String, self.Int32, self.Bool = TaskIds, String, Int32, Bool

    def _on_status(self, msg) -> None:
        now = time.monotonic()
        if self.keep_status:  # states only: an old manager's status carried megabytes of snapshots
            self.status.append((now, {t.task_id: t.state for t in msg.tasks}))
        self.sizes.append(sum(len(t.tree_snapshot) + len(t.message) + 64 for t in msg.tasks))
        if self.ended_at is not None:
            for t in msg.tasks:
                if t.tree_snapshot:
                    self.with_snapshot_after[t.task_id] = self.with_snapshot_after.get(t.task_id, 0) + 1

    def state(self, task_id: int) -> int | None:
        for _, states in reversed(self.status):
            if task_id in states:
                return states[task_id]
        return None

    def spin(self, seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.02)
            if until is not None and until():
                return True
        return until is None

    def publish(self, key: str, msg) -> None:
        pub = self.pubs[key]
        self.spin(20, lambda: pub.get_subscription_count() > 0)
        pub.publish(msg)

    def close(self) -> None:
        import rclpy

        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def _wait_state(probe: Probe, task_id: int, state: int, timeout: float) -> float | None:
    """Seconds until ``task_id`` shows ``state`` on /tms_ts/status (None: not within ``timeout``)."""
    start = time.monotonic()
    if probe.spin(timeout, lambda: probe.state(task_id) == state):
        return time.monotonic() - start
    return None


#: what the manager logs when a big tree's start is over: refused by a limit, ended, or canceled while it loaded
OUTCOMES = ("over the limit", "ended failure", "while its tree loaded", "emergency signal: canceling", "cannot start")


def _outcome(manager: Proc, since: int) -> str | None:
    return next((ln for ln in manager.lines[since:] if any(o in ln for o in OUTCOMES)), None)


def _send_big(
    probe: Probe, manager: Proc, xml: str, then: str | None, task_id: int
) -> tuple[float, float, float | None, str]:
    """Send ``xml`` on /task_sequence and, 0.5 s later, ``then`` ("cancel" task_id / "emg"); returns (sent, over,
    seconds until task_id showed CANCELED, the manager's line saying how the big tree's start ended)."""
    from tms_msg.msg import TaskState

    since = len(manager.lines)
    probe.publish("seq", probe.String(data=xml))
    sent = time.monotonic()
    stop_s = None
    if then is not None:
        probe.spin(0.5)
        probe.publish(then, probe.Int32(data=task_id) if then == "cancel" else probe.Bool(data=True))
        stop_s = _wait_state(probe, task_id, TaskState.CANCELED, 60)
    probe.spin(120, lambda: _outcome(manager, since) is not None)
    probe.spin(sent + WINDOW_S - time.monotonic())
    over = time.monotonic()  # the window: at least WINDOW_S, and until the big tree's start was over
    line = _outcome(manager, since) or "(no outcome logged within 120 s)"
    return sent, over, stop_s, line.split("]: ", 1)[-1][:150]


def big_tree_run(label: str, code: str | None) -> list[str]:
    from tms_msg.msg import TaskState

    out = []
    fmt = (lambda s: f"{s * 1e3:.0f} ms" if s is not None else "not within 60 s")  # noqa: E731
    with tempfile.TemporaryDirectory() as tmp, isolated_domain() as domain:
        db, ticks = f"{tmp}/db", f"{tmp}/ticks"
        seed(db)
        manager = start_manager(domain, db, ticks, code)
        probe = Probe(domain)

        def both_running() -> bool:
            return probe.state(1) == TaskState.RUNNING and probe.state(2) == TaskState.RUNNING and \
                sum("task 1 started" in ln or "task 2 started" in ln for ln in manager.lines) >= 2

        try:
            probe.publish("start", probe.TaskIds(task_ids=[1, 2]))
            if not probe.spin(60, both_running):
                raise RuntimeError(f"tasks 1 and 2 did not start:\n{manager.output[-2000:]}")
            probe.spin(3.0)
            t0 = time.monotonic()
            xml = big_tree()
            phases = [("5 MB tree, cancel of task 1 0.5 s after it", *_send_big(probe, manager, xml, "cancel", 1))]
            probe.spin(3.0)
            phases.append(("5 MB tree again, /emergency_signal 0.5 s after it (task 2 -> CANCELED)",
                           *_send_big(probe, manager, big_tree(tag="b"), "emg", 2)))
            probe.spin(3.0)
            probe.status.clear()
            probe.publish("start", probe.TaskIds(task_ids=[1, 2]))
            probe.spin(30, lambda: probe.state(1) == TaskState.RUNNING and probe.state(2) == TaskState.RUNNING)
            probe.spin(3.0)
            small = big_tree(4_990, tag="c")
            phases.append((f"a {len(small) / 1e3:.0f} kB tree of 4,990 nodes (within tms_ts.limits)",
                           *_send_big(probe, manager, small, None, 0)))
            probe.spin(3.0)
            t_end = time.monotonic()
            rss = rss_mb(manager.popen.pid)
        finally:
            probe.close()
            manager.kill()
        times = tick_times(ticks)
    out.append(f"[{label}] tasks 1 and 2 running at {RATE_HZ:g} Hz; trees sent on /task_sequence "
               f"(the 5 MB one: {len(xml) / 1e6:.2f} MB, {BIG_NODES} nodes)")
    for what, sent, over, stop_s, line in phases:
        stop = f"; task CANCELED on /tms_ts/status {fmt(stop_s)} after it was asked" if stop_s is not None or \
            "cancel" in what or "emergency" in what else ""
        out.append(f"[{label}]   {what}: tick lateness over the {over - sent:.1f} s from its sending: "
                   f"{late_summary(lateness_ms(times, sent, over))}{stop}")
        out.append(f"[{label}]     manager: {line}")
    out.append(
        f"[{label}]   tick lateness over the whole run ({t_end - t0:.0f} s): "
        f"{late_summary(lateness_ms(times, t0, t_end))}; "
        f"manager RSS at the end {rss:.0f} MB"
    )
    return out


def rss_run(label: str, code: str | None, seconds: float, *, extra: tuple[str, ...] = ()) -> list[str]:
    from tms_msg.msg import TaskState

    out = []
    n = 100
    with tempfile.TemporaryDirectory() as tmp, isolated_domain() as domain:
        db, ticks = f"{tmp}/db", f"{tmp}/ticks"
        seed(db, finished=n)
        manager = start_manager(domain, db, ticks, code, "-p", "status_rate_hz:=10.0",
                                "-p", "finished_retention_s:=3600.0", *extra)
        probe = Probe(domain)
        samples: list[tuple[float, float]] = []
        try:
            probe.publish("start", probe.TaskIds(task_ids=list(range(100, 100 + n))))
            ok = probe.spin(120, lambda: all(probe.state(100 + i) == TaskState.SUCCESS for i in range(n)))
            if not ok:
                raise RuntimeError(f"the {n} tasks did not all succeed:\n{manager.output[-2000:]}")
            probe.keep_status = False  # from here on only sizes and snapshot counts
            last_tasks = len(probe.status[-1][1])
            probe.ended_at = time.monotonic()
            probe.sizes.clear()
            step = seconds / 10
            t0 = time.monotonic()
            samples.append((0.0, rss_mb(manager.popen.pid)))
            for k in range(1, 11):
                probe.spin(t0 + k * step - time.monotonic())
                samples.append((time.monotonic() - t0, rss_mb(manager.popen.pid)))
        finally:
            probe.close()
            manager.kill()
    rss = ", ".join(f"{t:.0f}s {m:.0f}" for t, m in samples)
    growth = samples[-1][1] - samples[0][1]
    sizes = probe.sizes or [0]
    resent = sum(probe.with_snapshot_after.values())
    out.append(f"[{label}] {n} finished runs (1000 nodes each) in /tms_ts/status at 10 Hz for {seconds:.0f} s; "
               f"{last_tasks} tasks listed; manager RSS [MB]: {rss}; growth {growth:+.1f} MB "
               f"({growth / max(1.0, samples[-1][0]) * 60:+.2f} MB/min)")
    out.append(
        f"[{label}]   status messages received: {len(probe.sizes)}, about {max(sizes) / 1e3:.1f} kB each at most; "
        f"snapshots carried after the runs ended: {resent}"
    )
    return out


def main() -> None:
    olds = [p for p in os.environ.get("TS_LOAD_OLD", "").split(":") if p]
    runs = [] if os.environ.get("TS_LOAD_SKIP_NEW") == "1" else [("new", None)]
    runs += [("old " + old, old) for old in olds]
    for label, code in runs:
        for line in big_tree_run(label, code):
            print(line, flush=True)
    for label, code in runs:
        seconds = RSS_SECONDS if code is None else RSS_OLD_SECONDS
        for line in rss_run(label, code, seconds):
            print(line, flush=True)


if __name__ == "__main__":
    main()
