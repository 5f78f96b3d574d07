"""``tms_ur_experiment``: starts the earthwork tasks, shows progress, ends the run and writes the report.

It is the job node of ``config/launch/paper_experiment.yaml`` (``on_exit: shutdown``):

1. waits until the scheduler and the plant are up, then publishes ``task_ids`` on ``/tms_ts/start``;
2. prints a progress line every ``progress_period_s`` (wall): cycle n, each task's running leaves
   (the phase of each machine), soil moved, simulated time and real-time factor;
3. after ``cycles`` haul cycles (soil reached the dump site that many times) it clears
   ``CONTINUE_FLG`` in the global-blackboard record ``blackboard_record`` so both tasks finish their
   current cycle and end; it also ends when every task has ended on its own (mound depleted);
   when a task FAILS it cancels the others on ``/tms_ts/cancel`` (the partner would wait for a flag
   that never comes) and ends with the failure's message;
4. writes ``runs/<timestamp>/`` (metrics.json, PNG plots, index.html) and exits 0 when every task
   ended SUCCESS, 1 otherwise (or on ``timeout_s`` of simulated time).

Several carriers (the fleet experiment, ``config/launch/fleet.yaml``): ``carriers`` names them; each one's soil
comes from ``/sim/truth/<name>/soil`` and its pose from ``/sim/truth/<name>/pose``; the report gives per
carrier the soil it moved (load passes: rises of the carriers' landed totals; localisation error: each carrier's
``/<name>/odometry/global`` against its truth), the smallest distance between two carriers near the loading point
(``loading_point``, a site point, and ``near_radius_m``) and each task's machine and end state. ``loads`` > 0
ends the work after that many vessel loads (the excavator's tree counts them in the record's ``LOAD_COUNT``)
instead of ``cycles`` dumps: a carrier queues again as soon as it has dumped, so counting dumps would let one more
in.

Any list of machines (``machines``, names; default the site's list, ``machines`` of config/site.yaml): per machine
``/sim/truth/<name>/pose`` (its path) and ``/<name>/odometry/global`` (the estimate, for the localisation error of
every machine that has one); per excavator (the type of its description) ``/sim/truth/<name>/bucket_tip`` and
``/<name>/joint_states`` (measured, its forward kinematics for the end-effector error). The tasks start once every
action server their trees call is up (``wait_for_actions``; default read from the tasks' trees in tms_db:
:func:`tms_ur.experiment_core.tree_actions`).

Inputs besides: ``/clock`` (as the node clock: ``use_sim_time`` must be true), ``/tms_ts/status``,
``/sim/truth/soil``, and the flags of ``blackboard_record`` from tms_db.
"""

from __future__ import annotations

import math
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Int32

from tms_common.config import repo_root
from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import startup_parameters
from tms_db import open_store
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.fleet import load_named
from tms_model.geometry import yaw_from_quaternion
from tms_model.machines import EXCAVATOR
from tms_model.site import load_site
from tms_msg.msg import TaskIds, TaskStatus
from tms_ur.experiment_core import TASK_DONE, ExperimentRecorder, tasks_to_cancel_after_failure, tree_actions

STATE_NAMES = {0: "IDLE", 1: "RUNNING", 2: "SUCCESS", 3: "FAILURE", 4: "CANCELED"}
DONE = TASK_DONE


class ExperimentNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_experiment", **kwargs)
        d = startup_parameters(self)
        self.task_ids = [int(i) for i in d("task_ids", [1, 2]).value]
        self.cycles_target = int(d("cycles", 3).value)
        self.record = d("blackboard_record", "PAPER_BLACKBOARD").value
        self.timeout = float(d("timeout_s", 3600.0).value)
        self.progress_period = float(d("progress_period_s", 2.0).value)
        # The flags are polled from the DB (no change stream in the embedded store): fast enough to see
        # MOVING_FLG's short true phase, which a 5 Hz poll missed.
        flags_period = float(d("flags_period_s", 0.05).value)
        # Tasks start only once every planning and subtask action server is on the graph: with the
        # launcher's parallel start-up a leaf sent before its server exists fails the task at once.
        # Empty: the servers the tasks' trees call, read from tms_db before the start.
        waits = [str(a) for a in d("wait_for_actions", [""]).value if str(a)]
        self.wait_for_actions: list[str] | None = waits or None
        runs = Path(d("runs_dir", "runs").value)
        # run_dir: the report's directory exactly (scripts/demo.sh picks it so the recording lands in its bag/);
        # empty: a new <runs_dir>/<timestamp>
        chosen = str(d("run_dir", "").value)
        if chosen:
            self.run_dir = Path(chosen) if Path(chosen).is_absolute() else repo_root() / chosen
        else:
            self.run_dir = ((runs if runs.is_absolute() else repo_root() / runs)
                            / datetime.now().strftime("%Y%m%d-%H%M%S"))
        self.db_uri, self.db_path = d("db_uri", "").value, d("db_path", "").value
        self.carriers = [str(c) for c in d("carriers", [""]).value if str(c)]
        self.loads_target = int(d("loads", 0).value)
        self.loading_point = loading_point = str(d("loading_point", "P1").value)
        near_radius = float(d("near_radius_m", 12.0).value)
        self.title = str(d("title", "Paper experiment: two-machine earthwork").value)
        self.rec = ExperimentRecorder(carriers=self.carriers, near_radius=near_radius)
        self.rec.wall_start = time.monotonic()
        if not self.get_parameter("use_sim_time").value:
            raise ConfigError("tms_ur_experiment measures simulated time: run it with use_sim_time:=true "
                              "(sim_plant publishes /clock)")
        self.tasks: dict[int, dict] = {}
        self.started = False
        self.stopping = False
        self.exit_code: int | None = None
        self._last_progress = 0.0
        self._t0 = (time.monotonic(), 0.0)  # (wall, sim) when the tasks were started
        self.site = load_site()
        # the machines watched, by name; what is watched of each follows its description's type
        self.machines = [str(m) for m in d("machines", [""]).value if str(m)] or list(self.site.machines)
        descriptions = {name: load_named(name, site=self.site) for name in self.machines}
        self._kin = {name: ExcavatorKinematics(m) for name, m in descriptions.items() if m.type == EXCAVATOR}
        self._base: dict[str, tuple[float, float, float]] = {}  # excavator -> its truth base pose (x, y, yaw)
        if self.carriers:
            lp = self.site.point(loading_point)
            self.rec.loading_point = (lp.x, lp.y)
        self._store = None
        self._loads = 0
        self.pub_start = self.create_publisher(TaskIds, "/tms_ts/start", 10)
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_cancel = self.create_publisher(Int32, "/tms_ts/cancel", reliable)
        self.create_subscription(TaskStatus, "/tms_ts/status", self._on_status, 10)
        self.create_subscription(Float64MultiArray, "/sim/truth/soil", self._on_soil, 10)
        for m in dict.fromkeys(self.machines + self.carriers):
            self.create_subscription(PoseStamped, f"/sim/truth/{m}/pose", lambda msg, m=m: self._on_pose(m, msg), 10)
            # each machine's localisation estimate, against its truth pose (a machine without one sends none)
            self.create_subscription(Odometry, f"/{m}/odometry/global", lambda msg, m=m: self._on_estimate(m, msg), 10)
        for m in self.carriers:
            self.create_subscription(Float64MultiArray, f"/sim/truth/{m}/soil",
                                     lambda msg, m=m: self._on_carrier_soil(m, msg), 10)
        for m in self._kin:
            self.create_subscription(
                PointStamped, f"/sim/truth/{m}/bucket_tip", lambda msg, m=m: self._on_tip(m, msg), 10
            )
            self.create_subscription(JointState, f"/{m}/joint_states", lambda msg, m=m: self._on_joints(m, msg), 10)
            self.create_subscription(Float64MultiArray, f"/sim/truth/{m}/hydraulics",
                                     lambda msg, m=m: self._on_hydraulics(m, msg), 10)
        self.create_timer(flags_period, self._sample_flags)
        self.create_timer(0.2, self._tick)

    # -- inputs ---------------------------------------------------------------------------
    @property
    def sim_t(self) -> float:
        """Simulated time [s] (the node clock follows /clock; 0 until the first one arrives). Not a /clock
        subscription of our own: the time source already has one, and every callback costs on 2 cores."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_status(self, msg: TaskStatus) -> None:
        for t in msg.tasks:
            if t.task_id in self.task_ids:
                state = STATE_NAMES.get(t.state, str(t.state))
                self.tasks[t.task_id] = {"state": state, "running": list(t.running_leaves), "message": t.message}
                self.rec.on_task_state(self.sim_t, t.task_id, state)
                self.rec.on_running_leaves(self.sim_t, t.task_id, list(t.running_leaves))

    def _on_soil(self, msg: Float64MultiArray) -> None:
        labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        v = dict(zip(labels, msg.data, strict=False))
        if {"mound", "bucket", "vessel", "dumped"} <= v.keys():
            self.rec.on_soil(self.sim_t, v["mound"], v["bucket"], v["vessel"], v["dumped"])

    def _on_carrier_soil(self, machine: str, msg: Float64MultiArray) -> None:
        labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        v = dict(zip(labels, msg.data, strict=False))
        if {"vessel", "loaded", "dumped"} <= v.keys():
            self.rec.on_carrier_soil(self.sim_t, machine, v["vessel"], v["loaded"], v["dumped"])

    def _on_hydraulics(self, machine: str, msg: Float64MultiArray) -> None:
        labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        if labels and len(labels) == len(msg.data):
            self.rec.on_hydraulics(self.sim_t, machine, dict(zip(labels, msg.data, strict=True)))

    def _stamp(self, header) -> float:
        """A message's stamp [s of simulated time]; this node's clock when it is unset."""
        if header.stamp.sec or header.stamp.nanosec:
            return header.stamp.sec + header.stamp.nanosec * 1e-9
        return self.sim_t

    def _on_pose(self, machine: str, msg: PoseStamped) -> None:
        p = msg.pose.position
        yaw = yaw_from_quaternion(msg.pose.orientation)
        self.rec.on_truth_pose(self._stamp(msg.header), machine, p.x, p.y, yaw)
        if machine in self._kin:
            self._base[machine] = (p.x, p.y, yaw)

    def _on_estimate(self, machine: str, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.rec.on_estimated_pose(self._stamp(msg.header), machine, p.x, p.y)

    def _on_joints(self, machine: str, msg: JointState) -> None:
        """End-effector estimate of excavator ``machine``: FK of the joint angles measured over CAN, at their stamp.

        Only a message carrying every front joint counts: the converter publishes its joint sets
        separately, and another set's stamp is not the time of the front angles."""
        joints = dict(zip(msg.name, msg.position, strict=False))
        base = self._base.get(machine)
        if base is None or not all(j in joints for j in JOINTS):
            return
        local = self._kin[machine].tip_position(np.array([joints[j] for j in JOINTS]))
        bx, by, byaw = base
        c, s = math.cos(byaw), math.sin(byaw)
        self.rec.on_estimated_tip(self._stamp(msg.header), bx + c * local[0] - s * local[1],
                                  by + s * local[0] + c * local[1], machine)

    def _on_tip(self, machine: str, msg: PointStamped) -> None:
        self.rec.on_truth_tip(self._stamp(msg.header), msg.point.x, msg.point.y, machine)

    # -- supervision ----------------------------------------------------------------------
    def _db(self):
        if self._store is None:
            self._store = open_store(uri=self.db_uri or None, path=self.db_path or None)
        return self._store

    def _sample_flags(self) -> None:
        if self.exit_code is not None:
            return
        try:
            doc = self._db().get_record(self.record)
        except KeyError:
            return  # not seeded yet: the tasks cannot start either
        flags = {k: v for k, v in doc.items() if (k.endswith("_FLG") or k == "LOADAREA") and isinstance(v, bool)}
        if self.carriers and isinstance(doc.get("LOADAREA_MACHINE"), str):
            flags["LOADAREA_MACHINE"] = doc["LOADAREA_MACHINE"] or "-"
        self.rec.on_flags(self.sim_t, flags)
        if isinstance(doc.get("LOAD_COUNT"), int) and not isinstance(doc.get("LOAD_COUNT"), bool):
            self._loads = doc["LOAD_COUNT"]

    def _tick(self) -> None:
        if self.exit_code is not None:
            return
        if not self.started:
            if self.count_subscribers("/tms_ts/start") > 0 and self.sim_t > 0.0 and not self._missing_actions():
                self._task_machines()
                self.pub_start.publish(TaskIds(task_ids=self.task_ids))
                self.started = True
                self._t0 = (time.monotonic(), self.sim_t)
                self.get_logger().info(f"started tasks {self.task_ids}")
                print(f"[experiment] started tasks {self.task_ids}", flush=True)
            return
        now = time.monotonic()
        if now - self._last_progress >= self.progress_period:
            self._last_progress = now
            self._progress()
        ended = [tid for tid in self.task_ids if self.tasks.get(tid, {}).get("state") in DONE]
        enough = self._loads >= self.loads_target if self.loads_target > 0 else self.rec.cycles >= self.cycles_target
        if not self.stopping and (enough or self._failed()):
            self.stopping = True
            done = f"{self._loads} load(s)" if self.loads_target > 0 else f"{self.rec.cycles} cycle(s)"
            reason = "a task failed" if self._failed() else f"{done} done"
            if self._failed():
                for tid, info in sorted(self.tasks.items()):
                    if info.get("state") == "FAILURE":
                        print(f"[experiment] task {tid} FAILED: {info.get('message', '')}", flush=True)
                states = {tid: info.get("state", "") for tid, info in self.tasks.items()}
                for tid in tasks_to_cancel_after_failure(self.task_ids, states):
                    print(f"[experiment] canceling task {tid}: its partner failed", flush=True)
                    self.pub_cancel.publish(Int32(data=tid))
            print(f"[experiment] {reason}: clearing CONTINUE_FLG", flush=True)
            self._db().set_fields(self.record, {"CONTINUE_FLG": False})
        if len(ended) == len(self.task_ids):
            self._finish()
        elif self.sim_t - (self.rec.sim_start or self.sim_t) > self.timeout:
            print(f"[experiment] timeout: {self.timeout:g} s of simulated time", flush=True)
            self._finish(timed_out=True)

    def _task_machines(self) -> None:
        """Task id -> its machine (the task's parameter ``machine``, else its model_name) for the report."""
        for tid in self.task_ids:
            try:
                doc = self._db().get_task(tid)
            except KeyError:
                continue
            self.rec.task_machines[tid] = str((doc.get("blackboard") or {}).get("machine") or doc.get("model_name", ""))

    def _tree_actions(self) -> list[str]:
        """The action servers the tasks' trees call (from tms_db); a task not in the DB adds none."""
        actions: list[str] = []
        for tid in self.task_ids:
            try:
                doc = self._db().get_task(tid)
            except KeyError:
                continue
            actions += [a for a in tree_actions(str(doc.get("task_sequence", "")), doc.get("blackboard"))
                        if a not in actions]
        return actions

    def _missing_actions(self) -> list[str]:
        if self.wait_for_actions is None:
            self.wait_for_actions = self._tree_actions()
        # the server publishes <action>/_action/status (clients only subscribe to it)
        missing = [a for a in self.wait_for_actions if self.count_publishers(f"{a}/_action/status") == 0]
        if missing and time.monotonic() - self._last_progress >= self.progress_period:
            self._last_progress = time.monotonic()
            print(f"[experiment] waiting for action server(s): {', '.join(missing)}", flush=True)
        return missing

    def _failed(self) -> bool:
        return any(t.get("state") == "FAILURE" for t in self.tasks.values())

    def _progress(self) -> None:
        wall = time.monotonic() - self._t0[0]
        rtf = (self.sim_t - self._t0[1]) / wall if wall > 0 else 0.0
        phases = "; ".join(
            f"task {tid} {info['state']}: {', '.join(info['running']) or '-'}"
            for tid, info in sorted(self.tasks.items())
        )
        per = ""
        if self.carriers:
            moved = {m: (self.rec.carrier_soil.get(m) or [(0, 0, 0, 0)])[-1][3] for m in self.carriers}
            d = self.rec.min_carrier_distance
            per = (f" ({', '.join(f'{m} {v:.2f}' for m, v in moved.items())}) | load {self._loads}/{self.loads_target}"
                   f" | min carrier distance near {self.rec.near_radius:g} m of loading {d:.1f} m")
        # the fleet ends after its loads (per above); its carriers' dumps are not the paper's cycles
        head = f"dumps {self.rec.cycles}" if self.carriers else f"cycle {self.rec.cycles}/{self.cycles_target}"
        print(
            f"[experiment] {head} | passes {len(self.rec.pass_events)} | "
            f"soil moved {self.rec.soil_moved():.2f} m3{per} | t_sim {self.sim_t:.0f} s ({rtf:.1f}x) | {phases}",
            flush=True,
        )

    def _finish(self, timed_out: bool = False, stopped: bool = False) -> None:
        # Real-time factor over the run itself (from the start command), not the nodes' start-up.
        self.rec.wall_start, self.rec.sim_start = self._t0
        self.rec.wall_end, self.rec.sim_end = time.monotonic(), self.sim_t
        self.rec.ended = "stopped" if stopped else "timeout" if timed_out else "done"
        title = self.title + (" (stopped before the end)" if stopped else "")
        index = self.rec.report(self.run_dir, site=self.site, loading_point=self.loading_point, title=title)
        metrics = self.rec.metrics()
        if stopped:
            self.exit_code = 0
            print(f"[experiment] STOPPED before the end: {metrics['cycles']} cycle(s), {metrics['soil_moved_m3']} m3 "
                  f"moved, real-time factor {metrics['real_time_factor']}, report {index}", flush=True)
            return
        ok = not timed_out and all(self.tasks.get(t, {}).get("state") == "SUCCESS" for t in self.task_ids)
        for tid in self.task_ids:
            info = self.tasks.get(tid, {})
            machine = self.rec.task_machines.get(tid) if self.carriers else None
            print(f"[experiment] task {tid}: {info.get('state')} {info.get('message', '')}"
                  + (f" (machine {machine})" if machine else ""), flush=True)
        for name, figures in metrics.get("carriers", {}).items():
            print(f"[experiment] {name}: soil moved {figures['soil_moved_m3']} m3, loaded {figures['loaded_m3']} m3",
                  flush=True)
        if self.carriers:
            print(f"[experiment] min distance between two carriers within {self.rec.near_radius:g} m of the loading "
                  f"point: {metrics['min_carrier_distance_near_loading_point_m']} m "
                  f"({metrics['min_carrier_distance_at']})", flush=True)
        print(
            f"[experiment] {'DONE' if ok else 'FAILED'}: {metrics['cycles']} cycle(s), "
            f"{metrics['soil_moved_m3']} m3 moved, "
            f"real-time factor {metrics['real_time_factor']}, load pass {metrics['load_pass_time_s']}, report {index}",
            flush=True,
        )
        self.exit_code = 0 if ok else 1
        raise SystemExit(self.exit_code)

    def destroy_node(self) -> None:
        """Stopped (SIGINT/SIGTERM) during a run: write the report of what was recorded so far."""
        if self.started and self.exit_code is None:
            try:
                self._finish(stopped=True)
            except Exception as exc:  # noqa: BLE001 - say what was lost, then shut down anyway
                print(f"[experiment] report of the stopped run not written: {type(exc).__name__}: {exc}", flush=True)
        super().destroy_node()


def main() -> int:
    # stop_in_context: a stop mid-run still writes the report (destroy_node), with the node clock's last time
    return run_node(ExperimentNode, stop_in_context=True)


if __name__ == "__main__":
    sys.exit(main())
