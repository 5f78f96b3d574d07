"""``tms_ts_subtasks``: the subtask action servers of one machine.

For the machine called ``model_name`` it serves every subtask of its kind (:mod:`tms_ts.subtask_specs`
``KIND_SUBTASKS``) at ``/<model_name>/<subtask_name>`` as the original's subtask nodes do:
``tms_msg_ts/action/LeafNodeBase``,
goal ``{model_name, record_name}``, result ``result`` true only when SUCCEEDED (false with ABORTED or
CANCELED), feedback ``status``. Every goal is accepted (unless the server is stopping); a goal that cannot
run ends ABORTED. Its typed outcome goes beside the original's bool: a ``tms_msg/SubtaskOutcome`` (goal id,
``error_code``, ``error_msg`` for people) on ``/<model_name>/subtask_outcome``, published just before the
goal ends, for every goal. On a goal it reads the DB record (model_name, record_name) *at that moment*: a
missing or malformed record ends RECORD_INVALID naming the record and field. A valid goal goes to the
planning action ``/<model_name>/<planning>`` of its row (ZX200: the original's tms_msg_rp actions; a
change_pose that needs ``pass_through`` / ``theta_w_tolerance`` first gives them by goal id to
``<planning>/options``, tms_msg/srv/Zx200ChangePoseOptions), whose feedback is mirrored as ``status`` and
whose result the row's check reads (PLANNING_FAILED when it reports a failure; the ZX200 planner's text
for it comes from ``/<model_name>/tms_rp_zx200_outcome``). A cancel is honoured at once while
the goal still waits for its planning server (nothing was sent); later it is forwarded to planning, which
brings the machine to rest, and the subtask reports CANCELED only after planning confirmed. If planning does
not confirm within ``stop_timeout_s`` the node latches ``/<model_name>/emg_stop`` and aborts STOP_TIMEOUT.
If the planning server disappears while a goal runs (its process died) for ``server_lost_s``, the node
latches ``/<model_name>/emg_stop`` (nothing may keep driving the machine blind) and aborts SERVER_LOST.
The last feedback ``status`` of a failed goal is ``<CODE>: <error_msg>``, so the reason stays readable for
a client that reads only the original's type.

A row whose downstream is a service (the MST release_soil: com3_msgs/srv/DumpUp ``vessel_target_pos``) is
called once the service is there (within ``planning_wait_s``, else PLANNING_UNAVAILABLE); its reply is awaited
for ``service_timeout_s`` (60 s, the original's), else PLANNING_FAILED. A service call cannot be canceled: a
cancel (or a stop) waits for the reply, then the goal ends CANCELED (SERVER_STOPPING). A row that needs the
machine's state (``resolve``: the sample and swing-alignment subtasks) takes the latest
``/<model_name>/joint_states``, waiting up to ``joint_states_wait_s`` (2 s, the original's) for one: none, or
the joint it needs missing, ends PLANNING_UNAVAILABLE.

Goals run as coroutines on one executor thread (:class:`tms_common.ticker.Ticker` paces their checks).
Heartbeat: a thread publishes the model name on ``/tms_ts/subtask_heartbeat`` (std_msgs/String) every
0.05 s of wall time, so the manager notices a dead server process (SIGKILL) in a second instead of
waiting for DDS discovery to drop it (~20 s with the default lease).
ZX200 change_pose / excavate_simple set the record's ``LOCK_FLG`` false when a result arrives (so
sensing may update the excavation target again), as the original subtasks did.

Parameters (read-only, read at start-up): ``machine`` (the kind whose subtasks are served; default the kind of
``model_name`` on the site, config/site.yaml ``machines``), ``model_name`` (the namespace; default = machine),
``planning_wait_s`` (5.0), ``stop_timeout_s`` (5.0), ``server_lost_s`` (3.0), ``service_timeout_s`` (60.0),
``joint_states_wait_s`` (2.0), ``terrain_wait_s`` (20.0), ``base_measure_s`` (1.0), ``db_uri``, ``db_path``.

A row with ``steps`` (ours: ``*_excavate_design``, excavation to a design stored in tms_db's ``design``
collection) runs several planning goals: before each pass it reads the design and the newest dynamic heightmap
(``type: dynamic``, the record's ``terrain_id``; after the first pass a heightmap newer than the one the last pass
was planned on, waiting up to ``terrain_wait_s``), asks :class:`tms_ts.design_excavation.DesignExcavation` for
the pass and runs its excavate, change_pose and release goals through those rows' planning actions (failures as
the single-goal rows', the message naming the design and the pass). It ends SUCCEEDED when the pass planner says
the surface is within tolerance (the record's ``scope`` ``reachable``: also when nothing reachable from the base is
worth a pass), else with PLANNING_FAILED naming the design and the planner's reason; a design
not in the store ends RECORD_INVALID, no terrain PLANNING_UNAVAILABLE. A record with ``base_measured`` takes the
base pose from ``/<model_name>/odom_pose`` in frame ``map`` (the swing centre by RTK GNSS) averaged over
``base_measure_s`` while the machine stands (waiting up to ``joint_states_wait_s`` more for the messages); none, or a
machine that moves, ends PLANNING_UNAVAILABLE naming the topic.
The node is named ``<machine>_subtasks`` when ``-p machine:=<m>`` is on the command line, so the two
machines' servers started by hand do not share a name.
"""

from __future__ import annotations

import functools
import sys
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

from action_msgs.msg import GoalStatus
from nav_msgs.msg import Odometry
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, String
from unique_identifier_msgs.msg import UUID

from tms_common.action_client import RaceFreeActionClient
from tms_common.errors import ConfigError, TmsError
from tms_common.goals import OUTCOME_QOS, RunningGoals
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import StartupParams
from tms_common.ticker import Ticker
from tms_db import RecordNotFound, StoreError, get_design, open_store
from tms_if_opera.interface import OUTCOME_GRACE_S as PLANNING_OUTCOME_GRACE_S
from tms_if_opera.interface import PLANNING_OUTCOME
from tms_model.fleet import load_named
from tms_model.geometry import yaw_from_quaternion
from tms_msg.msg import SubtaskOutcome, Zx200PlanningOutcome
from tms_msg.srv import Zx200ChangePoseOptions
from tms_msg_ts.action import LeafNodeBase
from tms_rp.excavation.design import DesignError
from tms_rp.excavation.planner import BasePose
from tms_sp.terrain import TerrainError, heightmap_from_blob, latest_heightmap, latest_heightmap_doc
from tms_ts.design_excavation import DesignExcavation, Done, base_from_swing_centre, standing_pose
from tms_ts.errors import SubtaskRecordError, SubtaskStateError
from tms_ts.nodes.ros_port import HEARTBEAT_PERIOD_S, HEARTBEAT_TOPIC
from tms_ts.outcomes import SUBTASK_OUTCOME_TOPIC, code_name
from tms_ts.plans import DesignPlan, Plan
from tms_ts.subtask_specs import SubtaskSpec, planning_verdict, subtasks_for

__all__ = ["SubtaskServers", "main", "node_name_from_args"]

R = SubtaskOutcome
TICK_S = 0.05  # [s wall] how often a running goal looks at cancel, stop, deadlines
SERVER_CHECK_S = 0.2  # [s wall] how often a running goal looks for its planning server on the graph


def node_name_from_args(argv: Sequence[str]) -> str:
    """``<machine>_subtasks`` for a ``-p machine:=<machine>`` among the ROS arguments, else ``tms_ts_subtasks``.

    A node's name is fixed before its parameters can be read, so the default name is taken from the command
    line; the ``machine`` parameter stays the authority for what is served (a launch names the node itself).
    """
    args = list(argv)
    for i, arg in enumerate(args[:-1]):
        if arg in ("-p", "--param") and args[i + 1].startswith("machine:="):
            machine = args[i + 1].split(":=", 1)[1].strip()
            if machine.isidentifier():
                return f"{machine}_subtasks"
    return "tms_ts_subtasks"


def _uuid_key(goal_id) -> bytes:  # unique_identifier_msgs/UUID
    return bytes(goal_id.uuid)


def _feedback_text(fb) -> str:
    for field in ("state", "current_waypoint", "distance_remaining", "current_error"):
        if hasattr(fb, field):
            return f"{field}={getattr(fb, field)}"
    return ""


class SubtaskServers(Node):
    """All subtask action servers of one machine (see the module docstring)."""

    def __init__(self, node_name: str = "tms_ts_subtasks", **kwargs) -> None:  # rclpy Node kwargs
        super().__init__(node_name, **kwargs)

        p = StartupParams(self)
        machine = p.text("machine")  # the kind whose rows to serve; default: the kind of model_name
        self.model_name = p.text("model_name", machine) or machine
        self.description = None  # the machine's description, for rows that resolve against it
        if self.model_name:
            try:
                self.description = load_named(self.model_name)
            except ConfigError as exc:  # a name not on the site: rows resolve without it, its kind must be given
                if not machine:
                    raise
                self.get_logger().debug(f"no description of {self.model_name}: {exc}")
        if not machine and self.description is not None:  # ic120_1 serves its kind's subtasks
            machine = self.description.kind
        self.planning_wait_s = p.number("planning_wait_s", 5.0, lo=0.0)
        self.stop_timeout_s = p.number("stop_timeout_s", 5.0, lo=0.0)
        self.server_lost_s = p.number("server_lost_s", 3.0, lo=0.0)
        self.service_timeout_s = p.number("service_timeout_s", 60.0, lo=0.0)
        self.joint_states_wait_s = p.number("joint_states_wait_s", 2.0, lo=0.0)
        self.terrain_wait_s = p.number("terrain_wait_s", 20.0, lo=0.0)
        self.base_measure_s = p.number("base_measure_s", 1.0, lo=0.0)
        db_uri = p.text("db_uri")
        db_path = p.text("db_path")
        specs = subtasks_for(machine)  # ConfigError naming the known kinds
        self.store = open_store(uri=db_uri or None, path=db_path or None)
        group = ReentrantCallbackGroup()
        self._ticker = Ticker(self, TICK_S, callback_group=group)
        self.emg = self.create_publisher(Bool, f"/{self.model_name}/emg_stop", 10)
        self.outcomes = self.create_publisher(
            SubtaskOutcome, f"/{self.model_name}/{SUBTASK_OUTCOME_TOPIC}", OUTCOME_QOS
        )
        self.planners: dict[str, RaceFreeActionClient] = {}
        self.service_clients: dict[str, object] = {}  # rows whose downstream is a service
        # joint_states only while a row that resolves against them waits for one (as the original's align
        # subtask subscribes): a standing subscription would deliver the machine's 50 Hz state to the site server
        self._joints: dict[str, float] | None = None
        self._joints_t = -1.0
        self._group = group
        self.options_clients: dict[str, object] = {}
        #: planning goal id -> Zx200PlanningOutcome (the ZX200 planner's text for its code), newest last
        self.planning_outcomes: OrderedDict[bytes, Zx200PlanningOutcome] = OrderedDict()
        if any(spec.outcome_topic for spec in specs):
            self.create_subscription(Zx200PlanningOutcome, f"/{self.model_name}/{PLANNING_OUTCOME}",
                                     self._on_planning_outcome, OUTCOME_QOS, callback_group=group)
        self.action_servers = []
        for spec in specs:
            for step in (spec.steps or {}).values():  # the planning actions a multi-goal row runs
                planning = f"/{self.model_name}/{step.planning_action}"
                if planning not in self.planners:
                    self.planners[planning] = RaceFreeActionClient(self, step.action_type, planning,
                                                                   callback_group=group)
            planning = f"/{self.model_name}/{spec.planning_action}"
            if spec.downstream == "service":
                if planning not in self.service_clients:
                    self.service_clients[planning] = self.create_client(
                        spec.action_type, planning, callback_group=group
                    )
            elif planning not in self.planners:
                self.planners[planning] = RaceFreeActionClient(self, spec.action_type, planning, callback_group=group)
            if spec.options is not None and planning not in self.options_clients:
                self.options_clients[planning] = self.create_client(
                    Zx200ChangePoseOptions, f"{planning}/options", callback_group=group)
            self.action_servers.append(ActionServer(
                self, LeafNodeBase, f"/{self.model_name}/{spec.name}",
                execute_callback=functools.partial(self._execute, spec),  # a partial stays a coroutine function
                goal_callback=lambda _goal, s=spec: self._on_goal(s),
                cancel_callback=self._on_cancel,
                callback_group=group,
                result_timeout=ACTION_RESULT_TIMEOUT_S,
            ))
        self.heartbeat = self.create_publisher(String, HEARTBEAT_TOPIC, 10)
        self._goals = RunningGoals()  # SIGINT/SIGTERM: every running goal cancels downstream, then aborts
        self._beat_stop = threading.Event()
        threading.Thread(target=self._beat, name="subtask_heartbeat", daemon=True).start()
        self.get_logger().info(f"subtask servers for /{self.model_name}: {', '.join(s.name for s in specs)}")

    def _beat(self) -> None:
        msg = String(data=self.model_name)
        while not self._beat_stop.wait(HEARTBEAT_PERIOD_S):
            try:
                self.heartbeat.publish(msg)
            except Exception:  # noqa: BLE001 - context shut down at exit
                return

    def _on_joints(self, msg: JointState) -> None:
        joints = dict(self._joints or {})
        joints.update(zip(msg.name, (float(p) for p in msg.position), strict=False))
        self._joints, self._joints_t = joints, time.monotonic()

    async def _resolve(self, gh, spec: SubtaskSpec, plan: Plan) -> Plan:
        """The plan finished against the machine's state (a fresh joint_states); SubtaskStateError when none."""
        asked = time.monotonic()
        deadline = asked + self.joint_states_wait_s
        sub = self.create_subscription(JointState, f"/{self.model_name}/joint_states", self._on_joints, 10,
                                       callback_group=self._group)
        try:
            while self._joints is None or self._joints_t < asked:
                if time.monotonic() > deadline or gh.is_cancel_requested or self._goals.stopping.is_set():
                    raise SubtaskStateError(f"no /{self.model_name}/joint_states within {self.joint_states_wait_s:g} s")
                await self._ticker.next()
        finally:
            self.destroy_subscription(sub)
        return spec.resolve(plan, dict(self._joints), self.description)

    def _on_planning_outcome(self, msg: Zx200PlanningOutcome) -> None:
        self.planning_outcomes[_uuid_key(msg.goal_id)] = msg
        while len(self.planning_outcomes) > 100:
            self.planning_outcomes.popitem(last=False)
        self._ticker.wake()

    def _plan(self, goal: LeafNodeBase.Goal, spec: SubtaskSpec) -> Plan:
        if not spec.reads_record:
            return spec.build({}, goal.record_name)
        model = goal.model_name or self.model_name
        try:
            doc = self.store.get_parameter(model, goal.record_name)
        except RecordNotFound:
            raise SubtaskRecordError(goal.record_name, None, f"not found in parameter (model_name '{model}')") from None
        return spec.build(doc, goal.record_name)

    def _on_goal(self, spec: SubtaskSpec) -> GoalResponse:
        if self._goals.stopping.is_set():
            self.get_logger().error(f"/{self.model_name}/{spec.name}: goal rejected: the server is stopping")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, _gh) -> CancelResponse:
        self._ticker.wake()  # the goal looks at its cancel request now, not at the next tick
        return CancelResponse.ACCEPT

    def _finish(self, gh, spec: SubtaskSpec, code: int, message: str) -> LeafNodeBase.Result:
        record = gh.request.record_name
        if spec.clears_lock_flg and code != R.RECORD_INVALID:
            try:
                self.store.set_fields(record, {"LOCK_FLG": False}, model_name=gh.request.model_name or self.model_name)
            except Exception as exc:  # noqa: BLE001 - a bookkeeping write must not hide the result
                self.get_logger().warning(f"LOCK_FLG of '{record}' not cleared: {exc}")
        action = f"/{self.model_name}/{spec.name}"
        # the typed outcome first: a client that has the result then finds it already (or within its grace)
        self.outcomes.publish(SubtaskOutcome(action=action, goal_id=gh.goal_id, record_name=record,
                                             error_code=code, error_msg=message))
        if code == R.NONE:
            gh.succeed()
            self.get_logger().info(f"{action} '{record}' succeeded: {message}")
        else:
            # the reason for people, also where a client reading only the original's type can show it
            gh.publish_feedback(LeafNodeBase.Feedback(status=f"{code_name(code)}: {message}"))
            if code == R.CANCELED:
                gh.canceled()
            else:
                gh.abort()
            self.get_logger().warning(f"{action} '{record}' {code_name(code)}: {message}")
        return LeafNodeBase.Result(result=code == R.NONE)

    def on_stop_requested(self) -> bool:
        """run_node's stop hook: cancel the running goals downstream; True while any is still running."""
        return self._goals.wind_down(self.stop_timeout_s + 1.0, lambda n: self.get_logger().warning(
            f"stopping: canceling {n} running goal(s) downstream"))

    async def _execute(self, spec: SubtaskSpec, gh) -> LeafNodeBase.Result:
        with self._goals.running():
            return await self._execute_goal(gh, spec)

    async def _send_options(self, gh, planning: str, options: dict, goal_id: UUID,
                            deadline: float) -> tuple[int, str] | None:
        """Give the goal's options to ``<planning>/options`` by goal id; (code, reason) when that fails."""
        client = self.options_clients[planning]
        while not client.service_is_ready():
            if gh.is_cancel_requested:
                return R.CANCELED, f"canceled while waiting for {planning}/options (nothing was sent)"
            if self._goals.stopping.is_set():
                return R.SERVER_STOPPING, f"subtask server stopping while waiting for {planning}/options"
            if time.monotonic() > deadline:
                return R.PLANNING_UNAVAILABLE, (f"planning server offers no {planning}/options within "
                                                f"{self.planning_wait_s:g} s (the goal needs {options})")
            await self._ticker.next()
        reply = await self._ticker.wake_on(
            client.call_async(Zx200ChangePoseOptions.Request(goal_id=goal_id, **options))
        )
        if reply is None or not reply.accepted:
            why = reply.message if reply is not None else "no reply"
            return R.PLANNING_REJECTED, f"{planning}/options rejected {options}: {why}"
        return None

    async def _planning_text(self, goal_id: UUID) -> str:
        """The ZX200 planner's text for a failed goal (waits briefly: it may trail the result)."""
        key = _uuid_key(goal_id)
        deadline = time.monotonic() + PLANNING_OUTCOME_GRACE_S
        while key not in self.planning_outcomes and time.monotonic() < deadline:
            await self._ticker.next()
        outcome = self.planning_outcomes.pop(key, None)
        return outcome.message if outcome is not None else "(no outcome text from the planner)"

    async def _execute_goal(self, gh, spec: SubtaskSpec) -> LeafNodeBase.Result:
        record = gh.request.record_name
        try:
            plan = self._plan(gh.request, spec)
        except SubtaskRecordError as exc:
            return self._finish(gh, spec, R.RECORD_INVALID, str(exc))
        if spec.resolve is not None:
            try:
                plan = await self._resolve(gh, spec, plan)
            except SubtaskRecordError as exc:
                return self._finish(gh, spec, R.RECORD_INVALID, str(exc))
            except SubtaskStateError as exc:
                return self._finish(gh, spec, R.PLANNING_UNAVAILABLE, str(exc))
        planning = f"/{self.model_name}/{spec.planning_action}"
        if spec.downstream == "service":
            return await self._call_service(gh, spec, plan, planning)
        if spec.steps is not None:
            return await self._execute_steps(gh, spec, plan)
        return self._finish(gh, spec, *await self._run_planning(gh, spec, plan, record))

    async def _run_planning(self, gh, spec: SubtaskSpec, plan: Plan, record: str) -> tuple[int, str]:
        """One goal to the planning action of ``spec`` built from ``plan``, followed to its end: (code, message)."""
        planning = f"/{self.model_name}/{spec.planning_action}"
        client = self.planners[planning]
        deadline = time.monotonic() + self.planning_wait_s
        while not client.server_is_ready():
            if gh.is_cancel_requested:
                return (R.CANCELED, f"canceled while waiting for planning server {planning} "
                                    "(nothing was sent)")
            if self._goals.stopping.is_set():
                return (R.SERVER_STOPPING, f"subtask server stopping while waiting for "
                                    f"planning server {planning} (nothing was sent)")
            if time.monotonic() > deadline:
                return (R.PLANNING_UNAVAILABLE,
                                    f"planning server {planning} not available within {self.planning_wait_s:g} s")
            await self._ticker.next()

        # our own goal id: options go to the planner under it before the goal, its outcome text comes back under it
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        options = spec.options(plan) if spec.options is not None else None
        if options is not None:
            failed = await self._send_options(gh, planning, options, goal_id, deadline)
            if failed is not None:
                return failed

        def on_feedback(msg) -> None:
            gh.publish_feedback(LeafNodeBase.Feedback(status=_feedback_text(msg.feedback)))

        # the goal response is awaited even when a cancel comes meanwhile: its handle is what cancels planning
        handle = await client.send_goal_async(spec.goal(plan), feedback_callback=on_feedback, goal_uuid=goal_id)
        if handle is None or not handle.accepted:
            return (R.PLANNING_REJECTED, f"planning {planning} rejected the goal for record "
                                f"'{record}'")
        result_future = self._ticker.wake_on(handle.get_result_async())
        cancel_deadline = None
        lost_since = None
        next_check = time.monotonic() + SERVER_CHECK_S
        while not result_future.done():
            await self._ticker.next()
            if result_future.done():
                break
            now = time.monotonic()
            if now >= next_check:  # the planning process may have died: its goal would never end
                next_check = now + SERVER_CHECK_S
                if client.server_is_ready():
                    lost_since = None
                elif lost_since is None:
                    lost_since = now
                elif now - lost_since >= self.server_lost_s:
                    self.emg.publish(Bool(data=True))
                    return (R.SERVER_LOST, f"planning server {planning} lost while running "
                                        f"record '{record}' (unavailable for {now - lost_since:.1f} s): "
                                        f"/{self.model_name}/emg_stop latched")
            if (gh.is_cancel_requested or self._goals.stopping.is_set()) and cancel_deadline is None:
                handle.cancel_goal_async()
                cancel_deadline = now + self.stop_timeout_s
            if cancel_deadline is not None and now > cancel_deadline:
                self.emg.publish(Bool(data=True))
                return (R.STOP_TIMEOUT, f"planning {planning} did not confirm the stop within "
                                    f"{self.stop_timeout_s:g} s: /{self.model_name}/emg_stop latched")
        res = result_future.result()
        # the status and the result together: an aborted goal's (empty) result never passes for a success code
        ok, detail = planning_verdict(spec.check, res.result, res.status)
        status = {GoalStatus.STATUS_CANCELED: "CANCELED", GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED"}.get(
            res.status, "ABORTED")
        if gh.is_cancel_requested:
            return (R.CANCELED, f"canceled; planning {planning} confirmed stop ({status})")
        if self._goals.stopping.is_set():
            return (R.SERVER_STOPPING, f"subtask server stopping (SIGINT/SIGTERM): planning "
                                f"{planning} canceled ({status})")
        if ok:
            return (R.NONE, f"{spec.name} '{record}' done")
        if spec.outcome_topic:
            detail = f"{detail}: {await self._planning_text(goal_id)}"
        return (R.PLANNING_FAILED, f"planning {planning} failed for record '{record}': {detail}")

    async def _fresh_terrain(self, gh, plan: DesignPlan, last_id: str | None) -> tuple[str, Any]:
        """The newest dynamic heightmap once it is not ``last_id`` (a scan after the last pass), within
        ``terrain_wait_s``; SubtaskStateError naming the design and the terrain id when none comes."""
        deadline = time.monotonic() + self.terrain_wait_s
        why = "none stored"
        while True:
            try:
                # the document alone each tick; the heightmap's bytes only once a new one is there
                doc = latest_heightmap_doc(self.store, "dynamic", ident=plan.terrain_id)
                if str(doc["_id"]) != last_id:
                    doc, data = latest_heightmap(self.store, "dynamic", ident=plan.terrain_id)
                    return str(doc["_id"]), heightmap_from_blob(data, doc, source=f"dynamic terrain {doc['_id']}")
                why = f"the newest ({doc.get('time')}) is the one the last pass was planned on"
            except TerrainError as exc:
                why = str(exc)
            if time.monotonic() > deadline or gh.is_cancel_requested or self._goals.stopping.is_set():
                raise SubtaskStateError(f"design {plan.design!r}: no new dynamic terrain (id {plan.terrain_id}) within "
                                        f"terrain_wait_s = {self.terrain_wait_s:g} s: {why}")
            await self._ticker.next()

    async def _measured_base(self, gh, plan: DesignPlan) -> BasePose:
        """The base pose of a machine standing still: ``/<model_name>/odom_pose`` (its swing centre by RTK GNSS and
        its azimuth, in map) averaged over ``base_measure_s``; DesignError naming the design and the topic when
        none comes within ``joint_states_wait_s`` plus that, or the machine moves."""
        topic = f"/{self.model_name}/odom_pose"
        samples: list[tuple[float, float, float]] = []

        frames: set[str] = set()

        def on_pose(msg: Odometry) -> None:
            if msg.header.frame_id != "map":  # a converter's dead-reckoned odom is no base pose on the map
                frames.add(msg.header.frame_id)
                return
            p = msg.pose.pose
            samples.append((p.position.x, p.position.y, yaw_from_quaternion(p.orientation)))

        who = f"design {plan.design!r}: base pose from {topic}"
        started = time.monotonic()
        deadline = started + self.joint_states_wait_s + self.base_measure_s
        sub = self.create_subscription(Odometry, topic, on_pose, 50, callback_group=self._group)
        try:
            while time.monotonic() - started < self.base_measure_s or len(samples) < 3:
                if time.monotonic() > deadline or gh.is_cancel_requested or self._goals.stopping.is_set():
                    other = f" (and some in frame(s) {sorted(frames)}, not 'map')" if frames else ""
                    raise DesignError(f"{who}: {len(samples)} message(s) in frame 'map' within "
                                      f"{self.joint_states_wait_s + self.base_measure_s:g} s{other}")
                await self._ticker.next()
        finally:
            self.destroy_subscription(sub)
        x, y, yaw = standing_pose(samples, who)
        return base_from_swing_centre(self.description, x, y, yaw, float(plan.base.get("z", 0.0)))

    async def _execute_steps(self, gh, spec: SubtaskSpec, plan: Plan) -> LeafNodeBase.Result:
        """The design subtask: per pass the newest design and terrain -> the pass planner -> its goals through the
        planning actions of the row's ``steps`` (tms_ts.design_excavation), until the planner stops."""
        record = gh.request.record_name
        assert isinstance(plan, DesignPlan) and spec.steps is not None
        if self.description is None:
            return self._finish(gh, spec, R.PLANNING_UNAVAILABLE, f"design {plan.design!r}: no description of "
                                f"{self.model_name} on the site (the pass planner needs its bucket and reach)")
        try:
            base = await self._measured_base(gh, plan) if plan.base_measured else None
            run = DesignExcavation(plan, self.description, base=base)
        except TmsError as exc:
            return self._finish(gh, spec, R.PLANNING_UNAVAILABLE, str(exc))
        if base is not None:
            self.get_logger().info(f"design {plan.design!r}: record '{record}': measured base pose x {base.x:.3f} "
                                   f"y {base.y:.3f} yaw {base.yaw:.4f} (z {base.z:g} from the record)")
        started = time.monotonic()
        terrain_id = None
        while True:
            if gh.is_cancel_requested:
                return self._finish(gh, spec, R.CANCELED, f"design {plan.design!r} canceled after {run.summary()}")
            if self._goals.stopping.is_set():
                return self._finish(gh, spec, R.SERVER_STOPPING, f"design {plan.design!r}: subtask server stopping "
                                    f"after {run.summary()}")
            try:
                design_doc = get_design(self.store, plan.design)
            except StoreError as exc:
                return self._finish(gh, spec, R.RECORD_INVALID, f"record '{record}': {exc}")
            try:
                terrain_id, terrain = await self._fresh_terrain(gh, plan, terrain_id)
            except SubtaskStateError as exc:
                return self._finish(gh, spec, R.PLANNING_UNAVAILABLE, f"{exc} ({run.summary()})")
            step = run.step(design_doc, terrain)
            if isinstance(step, Done):
                took = f"; {time.monotonic() - started:.1f} s"
                return self._finish(gh, spec, R.NONE if step.ok else R.PLANNING_FAILED, step.message + took)
            cut = step.cut
            status = (f"design {plan.design!r} pass {step.number}: cut {cut.volume:.3f} m3 depth {cut.depth:.2f} m "
                      f"length {cut.length:.2f} m from ({cut.start[0]:.2f}, {cut.start[1]:.2f}, {cut.start[2]:.2f}), "
                      f"edge aimed {run.edge_offset * 100:.1f} cm higher, dump to {cut.dump_kind}; "
                      f"MAE {step.error.mae * 100:.2f} cm")
            self.get_logger().info(status)  # the run's log tells each pass as the feedback does
            gh.publish_feedback(LeafNodeBase.Feedback(status=status))
            for what, goal_plan in step.goals:
                code, message = await self._run_planning(gh, spec.steps[what], goal_plan, record)
                if code != R.NONE:
                    return self._finish(gh, spec, code, f"design {plan.design!r} pass {step.number} ({what}): "
                                        f"{message} ({run.summary()})")

    async def _call_service(self, gh, spec: SubtaskSpec, plan: Plan, service: str) -> LeafNodeBase.Result:
        """A row whose downstream is a service: wait for it, call it, read its reply (cannot be canceled)."""
        record = gh.request.record_name
        client = self.service_clients[service]
        deadline = time.monotonic() + self.planning_wait_s
        while not client.service_is_ready():
            if gh.is_cancel_requested:
                return self._finish(
                    gh, spec, R.CANCELED, f"canceled while waiting for service {service} (nothing was sent)"
                )
            if self._goals.stopping.is_set():
                return self._finish(gh, spec, R.SERVER_STOPPING, f"subtask server stopping while waiting for "
                                    f"service {service} (nothing was sent)")
            if time.monotonic() > deadline:
                return self._finish(gh, spec, R.PLANNING_UNAVAILABLE,
                                    f"service {service} not available within {self.planning_wait_s:g} s")
            await self._ticker.next()
        future = self._ticker.wake_on(client.call_async(spec.goal(plan)))
        deadline = time.monotonic() + self.service_timeout_s
        told = False
        while not future.done():
            if time.monotonic() > deadline:
                return self._finish(gh, spec, R.PLANNING_FAILED, f"service {service} gave no reply within "
                                    f"{self.service_timeout_s:g} s for record '{record}'")
            if (gh.is_cancel_requested or self._goals.stopping.is_set()) and not told:
                told = True
                gh.publish_feedback(
                    LeafNodeBase.Feedback(status=f"a {service} call cannot be canceled: waiting for its reply")
                )
            await self._ticker.next()
        if gh.is_cancel_requested:
            return self._finish(
                gh, spec, R.CANCELED, f"canceled; service {service} replied (its call cannot be stopped)"
            )
        if self._goals.stopping.is_set():
            return self._finish(gh, spec, R.SERVER_STOPPING, f"subtask server stopping; service {service} replied")
        ok, detail = spec.check(future.result())
        if ok:
            return self._finish(gh, spec, R.NONE, f"{spec.name} '{record}' done")
        return self._finish(gh, spec, R.PLANNING_FAILED, f"service {service} failed for record '{record}': {detail}")

    def destroy_node(self) -> None:
        self._beat_stop.set()
        self.store.close()
        super().destroy_node()


def main() -> int:
    # stop_in_context: on SIGINT/SIGTERM running goals cancel their planning goals and end (on_stop_requested)
    return run_node(lambda: SubtaskServers(node_name_from_args(sys.argv)), executor="single", stop_in_context=True)
