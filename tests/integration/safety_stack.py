"""The paper stack for the safety tests: every node its own process, started one by one (no launcher).

``tms-launch`` stops the whole stack when one required node dies, so the lost-server test could not
kill a single process under it. Here each node of ``config/launch/paper_experiment.yaml`` (minus the
supervisor, sensing and the IC120 vessel controller, which these tests do not use) runs as its own
:class:`tests.rosproc.Proc` on the test's ROS domain, with the test's own udp_multicast CAN groups /
ports and a fresh embedded DB seeded from ``config/seeds/paper.yaml`` plus the two small tasks below.

:class:`Probe` (in the test process) records simulated truth (``/sim/truth/*``, ``/clock``) and task
states (``/tms_ts/status``) and publishes cancels; :func:`rest_time` and :func:`max_speed` turn the
truth samples into the figures the tests assert.
"""

from __future__ import annotations

import itertools
import math
import os
import random
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from tests.rosproc import VENV, executable, free_can_ports

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "paper_experiment.yaml"
SKIP = {"tms_ur_experiment", "tms_sp_sensing", "ic120_vessel"}

ZX200_TASK, IC120_TASK = 91, 92
#: ZX200: excavations at the seeded target (approach, penetrate, drag, curl, lift), repeated.
ZX200_XML = """<root main_tree_to_execute="Main"><BehaviorTree ID="Main"><Repeat num_cycles="5">
<Action ID="LeafNodeZx200" name="excavate" model_name="zx200" record_name="target_excavate_pose"
        subtask_name="subtask_zx200_excavate_simple"/>
</Repeat></BehaviorTree></root>"""
#: IC120: shuttles P3 -> P1 (reverse) -> P3 on the paper routes, so it is driving whenever the ZX200 digs.
IC120_XML = """<root main_tree_to_execute="Main"><BehaviorTree ID="Main"><Repeat num_cycles="20"><Sequence>
<Action ID="LeafNodeIc120" name="to_loading" model_name="ic120" record_name="LOAD_PATH"
        subtask_name="st_ic120_follow_waypoints"/>
<Action ID="LeafNodeIc120" name="to_turning" model_name="ic120" record_name="RELEASE_PATH"
        subtask_name="st_ic120_follow_waypoints"/>
</Sequence></Repeat></BehaviorTree></root>"""

#: Rest thresholds: every front joint / vessel below REST_JOINT [rad/s], each base below REST_BASE [m/s]
#: (and its yaw rate below REST_JOINT). Truth is noise-free. The bucket drags through the soil at only
#: 0.02-0.05 rad/s, so "at rest" must be well below that: 0.005 rad/s, 0.01 m/s (1 % of the IC120's top speed).
REST_JOINT = 0.005
REST_BASE = 0.01
#: Action servers the tasks need, waited for before a task is started.
SERVERS = {
    "/zx200/subtask_zx200_excavate_simple": "tms_msg_ts.action:LeafNodeBase",
    "/ic120/st_ic120_follow_waypoints": "tms_msg_ts.action:LeafNodeBase",
    "/zx200/tms_rp_zx200_excavate_simple": "tms_msg_rp.action:TmsRpZx200ExcavateSimple",
    "/zx200/arm_controller/move": "tms_msg.action:Zx200ArmMove",
    "/ic120/follow_waypoints": "nav2_msgs.action:FollowWaypoints",
}


def _literal(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def start_stack(procs, domain: int, tmp: Path, speed: float, overrides: dict | None = None,
                skip: set[str] | frozenset[str] = frozenset(), tasks: dict[int, tuple[str, str]] | None = None) -> dict:
    """Seed the DB (paper seed + tasks 91/92) and start every node; returns ``{label: Proc}``.
    ``overrides`` maps a node name of the launch file to parameters replacing its own; ``skip`` names more nodes
    not to start (labels as returned, e.g. ``ic120/com3_bridge``); ``tasks`` adds ``{task_id: (xml, description)}``."""
    db = tmp / "db"
    db.mkdir()
    env = {"TMS_DB_PATH": str(db)}
    seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env={**os.environ, **env},
                            capture_output=True, text=True, timeout=120)
    assert seeded.returncode == 0, seeded.stdout + seeded.stderr
    from tms_db import open_store

    store = open_store(path=str(db))
    try:
        store.add_task(ZX200_XML, ZX200_TASK, "safety test: ZX200 excavate_simple", replace=True)
        store.add_task(IC120_XML, IC120_TASK, "safety test: IC120 shuttle P3 <-> P1", replace=True)
        for task_id, (xml, description) in (tasks or {}).items():
            store.add_task(xml, task_id, description, replace=True)
    finally:
        store.close()

    launch = yaml.safe_load(LAUNCH.read_text())
    common = launch.get("parameters", {})
    rnd = random.Random(domain * 7 + 3)
    groups = {m: f"239.77.{rnd.randrange(1, 250)}.{rnd.randrange(1, 250)}" for m in ("zx200", "ic120")}
    ports = dict(zip(("zx200", "ic120"), free_can_ports(domain, 2, rnd), strict=True))
    out = {}
    for node in launch["nodes"]:
        exe = node["executable"]
        label = f"{node.get('namespace', '').strip('/')}/{node['name']}".strip("/")
        if exe in SKIP or label in skip:
            continue
        params = {**common, **node.get("parameters", {}), **(overrides or {}).get(node["name"], {})}
        if exe == "sim_plant":
            params["speed"] = speed
            params["config"] = str(ROOT / params["config"])
            for m in ("zx200", "ic120"):
                params[f"{m}_can_channel"], params[f"{m}_can_port"] = groups[m], ports[m]
        elif exe == "com3_bridge":
            m = params["machine"]
            params["can_channel"], params["can_port"] = groups[m], ports[m]
        cmd = [executable(node["package"], exe), "--ros-args", "-r", f"__node:={node['name']}"]
        if node.get("namespace"):
            cmd += ["-r", f"__ns:={node['namespace']}"]
        for key, value in params.items():
            cmd += ["-p", f"{key}:={_literal(value)}"]
        out[label] = procs(cmd, name=label, **env)
    return out


@dataclass
class Sample:
    """One /sim/truth instant (simulated time ``t``)."""

    t: float
    wall: float = 0.0  # time.monotonic() when the first message of this instant arrived
    zx_dq: tuple[float, ...] = ()
    ic_dq: tuple[float, ...] = ()
    zx_pose: tuple[float, float, float] | None = None  # x, y, yaw
    ic_pose: tuple[float, float, float] | None = None


@dataclass
class Probe:
    """Recorder / publisher in the test process (``ros_node`` fixture) spun by a background thread."""

    node: object
    samples: dict[float, Sample] = field(default_factory=dict)
    clock: float = 0.0
    bucket: float = 0.0
    bucket_log: list[tuple[float, float]] = field(default_factory=list)
    tasks: dict[int, tuple[int, str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Bool, Float64MultiArray, Int32

        from tms_msg.msg import TaskIds, TaskStatus

        n = self.node
        self._lock = threading.Lock()
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        n.create_subscription(Clock, "/clock", self._on_clock, 10)
        for m in ("zx200", "ic120"):
            n.create_subscription(JointState, f"/sim/truth/{m}/joint_states", lambda msg, m=m: self._on_js(m, msg), 50)
            n.create_subscription(PoseStamped, f"/sim/truth/{m}/pose", lambda msg, m=m: self._on_pose(m, msg), 50)
        n.create_subscription(Float64MultiArray, "/sim/truth/soil", self._on_soil, 10)
        n.create_subscription(TaskStatus, "/tms_ts/status", self._on_status, reliable)
        self.start_pub = n.create_publisher(TaskIds, "/tms_ts/start", reliable)
        self.cancel_pub = n.create_publisher(Int32, "/tms_ts/cancel", reliable)
        self.emg_clear = {m: n.create_publisher(Bool, f"/{m}/emg_stop", reliable) for m in ("zx200", "ic120")}
        self._TaskIds, self._Int32 = TaskIds, Int32
        self._stop = threading.Event()
        self._spin_error: BaseException | None = None
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        ex = self.node.executor_for_test
        try:
            while not self._stop.is_set():
                ex.spin_once(timeout_sec=0.05)
        except BaseException as exc:  # the probe is blind from here on: wait() reports it
            self._spin_error = exc
            raise

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    # -- callbacks ---------------------------------------------------------------------------------
    def _sample(self, stamp) -> Sample:
        t = round(stamp.sec + stamp.nanosec * 1e-9, 4)
        s = self.samples.get(t)
        if s is None:
            s = self.samples[t] = Sample(t, time.monotonic())
        return s

    def _on_clock(self, msg) -> None:
        self.clock = msg.clock.sec + msg.clock.nanosec * 1e-9

    def _on_js(self, machine: str, msg) -> None:
        with self._lock:
            s = self._sample(msg.header.stamp)
            if machine == "zx200":
                s.zx_dq = tuple(msg.velocity)
            else:
                s.ic_dq = tuple(msg.velocity)

    def _on_pose(self, machine: str, msg) -> None:
        q = msg.pose.orientation
        yaw = 2.0 * math.atan2(q.z, q.w)
        with self._lock:
            s = self._sample(msg.header.stamp)
            pose = (msg.pose.position.x, msg.pose.position.y, yaw)
            if machine == "zx200":
                s.zx_pose = pose
            else:
                s.ic_pose = pose

    def _on_soil(self, msg) -> None:
        with self._lock:
            self.bucket = float(msg.data[1])
            self.bucket_log.append((self.clock, self.bucket))
            del self.bucket_log[:-200]

    def digging(self, window: float = 0.3) -> bool:
        """The bucket took soil in over the last ``window`` s of simulated time (it is cutting)."""
        with self._lock:
            log = list(self.bucket_log)
        if not log:
            return False
        t, v = log[-1]
        old = [b for s, b in log if s <= t - window]
        return bool(old) and v - old[-1] > 1e-4

    def _on_status(self, msg) -> None:
        with self._lock:
            for st in msg.tasks:
                self.tasks[int(st.task_id)] = (int(st.state), st.message)

    # -- commands / queries --------------------------------------------------------------------------
    def start(self, *task_ids: int) -> None:
        self._matched(self.start_pub, "/tms_ts/start")
        self.start_pub.publish(self._TaskIds(task_ids=list(task_ids)))

    def cancel(self, task_id: int) -> None:
        self._matched(self.cancel_pub, "/tms_ts/cancel")
        self.cancel_pub.publish(self._Int32(data=task_id))

    @staticmethod
    def _matched(pub, topic: str, timeout: float = 60.0) -> None:
        """Wait until this publisher has matched the manager's subscription: a message published before is lost
        (a rehearsal's partition test saw the servers on the graph, published the start, and no task ever ran)."""
        end = time.monotonic() + timeout
        while pub.get_subscription_count() == 0:
            if time.monotonic() > end:
                raise AssertionError(f"no subscriber of {topic} matched this test's publisher within {timeout:g} s")
            time.sleep(0.05)

    def task(self, task_id: int) -> tuple[int, str] | None:
        with self._lock:
            return self.tasks.get(task_id)

    def series(self) -> list[Sample]:
        """Complete samples (both machines' joints and poses), in time order."""
        with self._lock:
            return [s for _, s in sorted(self.samples.items())
                    if s.zx_dq and s.ic_dq and s.zx_pose is not None and s.ic_pose is not None]

    def wait(self, cond, timeout: float, step: float = 0.05) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if cond():
                return True
            if self._spin_error is not None:
                raise RuntimeError(f"the probe's spin thread died, it receives nothing: {self._spin_error!r}")
            time.sleep(step)
        return cond()


def wait_servers(node, timeout: float, servers: dict[str, str] | None = None) -> list[str]:
    """Wait until every action server of ``servers`` (default :data:`SERVERS`) is available; returns the missing
    ones."""
    import importlib

    from rclpy.action import ActionClient

    def action_type(spec: str):  # "package.action:Type"
        module, name = spec.split(":")
        return getattr(importlib.import_module(module), name)

    # The clients live on a node of their own that no executor holds: the caller's node may be spun by a
    # Probe's thread, and destroying a client there while that thread builds its wait set invalidates it
    # (RCLError "action client pointer is invalid"). server_is_ready() reads the graph and needs no spinning.
    import rclpy

    checker = rclpy.create_node(f"wait_servers_{os.getpid()}_{next(_CHECKERS)}", context=node.context)
    try:
        clients = {name: ActionClient(checker, action_type(t), name) for name, t in (servers or SERVERS).items()}
        end = time.monotonic() + timeout
        missing = list(clients)
        while time.monotonic() < end:
            missing = [n for n, c in clients.items() if not c.server_is_ready()]
            if not missing:
                break
            time.sleep(0.2)
        for c in clients.values():
            c.destroy()
    finally:
        checker.destroy_node()
    return missing


_CHECKERS = itertools.count()


def speeds(prev: Sample, cur: Sample) -> dict[str, float]:
    """Largest speeds between two samples: ``zx_joint``, ``ic_joint`` [rad/s] (reported velocities),
    ``zx_base``, ``ic_base`` [m/s] and ``zx_yaw``, ``ic_yaw`` [rad/s] (from the pose difference)."""
    dt = cur.t - prev.t
    out = {"zx_joint": max(abs(v) for v in cur.zx_dq), "ic_joint": max(abs(v) for v in cur.ic_dq)}
    for key, a, b in (("zx", prev.zx_pose, cur.zx_pose), ("ic", prev.ic_pose, cur.ic_pose)):
        out[f"{key}_base"] = math.hypot(b[0] - a[0], b[1] - a[1]) / dt
        dyaw = math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))
        out[f"{key}_yaw"] = abs(dyaw) / dt
    return out


def at_rest(sp: dict[str, float]) -> bool:
    return (sp["zx_joint"] < REST_JOINT and sp["ic_joint"] < REST_JOINT and sp["zx_base"] < REST_BASE
            and sp["ic_base"] < REST_BASE and sp["zx_yaw"] < REST_JOINT and sp["ic_yaw"] < REST_JOINT)


def rest_time(series: list[Sample], since: float) -> float | None:
    """Simulated time from ``since`` to the first sample after which both machines stay at rest."""
    pairs = [(b.t, at_rest(speeds(a, b))) for a, b in zip(series, series[1:], strict=False) if b.t > since]
    for i, (t, ok) in enumerate(pairs):
        if ok and all(r for _, r in pairs[i:]):
            return t - since
    return None


def max_speed(series: list[Sample], since: float, until: float = math.inf) -> dict[str, float]:
    """Largest of each speed over the samples in (since, until]."""
    best: dict[str, float] = {}
    for a, b in zip(series, series[1:], strict=False):
        if since < b.t <= until and b.t - a.t > 1e-6:
            for k, v in speeds(a, b).items():
                best[k] = max(best.get(k, 0.0), v)
    return best
