"""``zx200_planner``: the ZX200 planning actions, in the ``/zx200`` namespace, as the original names and types them.

Serves ``tms_rp_zx200_change_pose`` (tms_msg_rp/action/TmsRpZx200ChangePose), ``tms_rp_zx200_excavate_simple``
(TmsRpZx200ExcavateSimple) and ``tms_rp_zx200_release_simple`` (TmsRpZx200ReleaseSimple); names in
:mod:`tms_if_opera.interface`. Beside them, ours: ``tms_rp_zx200_change_pose/options``
(tms_msg/srv/Zx200ChangePoseOptions: a change_pose goal's ``pass_through`` and ``theta_w_tolerance``, by goal
id, before the goal; a goal without options runs with the defaults) and ``tms_rp_zx200_outcome``
(tms_msg/msg/Zx200PlanningOutcome: every goal's code and its text for people, published just before the
goal ends; the original's result carries only ``error_code``). Each goal is planned
and validated by :class:`tms_rp.arm.planner.ArmPlanner` first: a NaN/empty/unreachable/out-of-limit
goal ends at once (no motion) with ``error_code.val`` INVALID_GOAL / OUT_OF_REACH / JOINT_LIMIT
(Zx200PlanningOutcome classes) and an outcome ``message`` naming the joint or distance. A valid goal's phases go to the
arm controller's action
``arm_controller/move`` (node ``excavator_arm_controller``, tms_msg/action/Zx200ArmMove) as one goal of
segments, so the arm passes the via phases without stopping; feedback ``state`` is the running phase
(approach, penetrate, drag, curl, lift / swing, open / ...), forwarded from the controller. Cancel is
forwarded; the goal ends CANCELED once the controller reports the arm at rest.

Stopped (SIGINT/SIGTERM), the node cancels its running controller goals, waits until the controller reports
them ended (the arm at rest; at most ``STOP_TIMEOUT_S``), aborts them with "zx200_planner stopping
(SIGINT/SIGTERM): ..." and rejects new goals meanwhile; only then does it leave, with its context valid.

Goals run as coroutines on one executor thread (:class:`tms_common.ticker.Ticker` paces their checks). The
arm's joints are read when a goal needs them: a ``joint_states`` subscription exists only while a goal waits
for one (subscribed all the time, the 50 Hz stream cost ~16 % of a core in executor overhead alone).

The original's collision-aware variants, same types: ``tms_rp_zx200_change_pose_plan`` (with its
``/options``) and ``tms_rp_zx200_excavate_simple_plan``. Each goal reads the collision-object record named by
``collision_object_record_name`` from the DB when it arrives and plans with
:class:`tms_rp.arm.collision_planner.CollisionPlanner` (dense path checks, detours over objects); a target or
path it cannot clear ends with ``TmsRpErrorCodes.FAILURE`` and a message naming the object and its record.

Parameters (read-only, read at start-up, :class:`tms_common.params.StartupParams`): ``machine`` (the excavator
on the site; default the namespace's last segment), ``machine_config``, ``planner_config``, ``controller_config``,
``collision_config`` (YAML paths; defaults in config/: the kind's description, config/tms_rp/<kind>_planner.yaml,
config/tms_rc/excavator_arm_controller.yaml, config/tms_rp/<kind>_collision.yaml), ``collision_object_record_name`` (the
original's; "" = no
objects), ``collision_object_dump_record_name`` (the original's mesh records: not supported, goals of the _plan
actions are refused while it is set), ``db_uri`` / ``db_path`` (the store, ``tms_db.open_store``).
"""

from __future__ import annotations

import functools
import math
import time
import traceback
import uuid

import numpy as np
from action_msgs.msg import GoalStatus
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState
from unique_identifier_msgs.msg import UUID

from tms_common.action_client import RaceFreeActionClient
from tms_common.goals import OUTCOME_QOS, RunningGoals
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import StartupParams
from tms_common.ticker import Ticker
from tms_db import RecordNotFound, StoreError, open_store
from tms_if_opera.interface import (
    CHANGE_POSE,
    CHANGE_POSE_OPTIONS,
    CHANGE_POSE_PLAN,
    CHANGE_POSE_PLAN_OPTIONS,
    EXCAVATE_SIMPLE,
    EXCAVATE_SIMPLE_PLAN,
    OPTIONS_TTL_S,
    PLANNER_NODE,
    PLANNING_OUTCOME,
    RELEASE_SIMPLE,
)
from tms_model.excavator import codes
from tms_model.excavator.codes import PlanningError
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.excavator.targets import JointTarget
from tms_model.fleet import load_named, machine_name
from tms_model.machines import EXCAVATOR
from tms_msg.action import Zx200ArmMove
from tms_msg.msg import Zx200ArmSegment, Zx200PlanningOutcome
from tms_msg.srv import Zx200ChangePoseOptions
from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple
from tms_rc.excavator.controller import load_controller_settings
from tms_rp.arm.collision import (
    ArmCollisionModel,
    CollisionRecordError,
    load_collision_config,
    objects_from_record,
)
from tms_rp.arm.collision_planner import CollisionPlanner, Scene
from tms_rp.arm.planner import ArmPlanner, load_planner_config

__all__ = ["ArmPlannerNode", "main"]

JOINT_STATES_WAIT_S = 2.0  # [s wall] a goal waits this long for a joint_states to plan from
GOAL_RESPONSE_TIMEOUT_S = 20.0  # [s wall] the controller answers at once (or after its <= 15 s joint_states wait)
RESULT_GRACE_S = 3.0            # [s wall] after the goal status says it ended, wait this long for the result
SERVER_GONE_S = 5.0             # [s wall] the controller's action server absent this long: the segment fails
STOP_TIMEOUT_S = 15.0           # [s wall] stopped mid-goal: wait this long for the controller to end the goal
TICK_S = 0.02                   # [s wall] how often a waiting goal looks at cancel, stop, deadlines, the server
_STATUS_NAMES = {GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED", GoalStatus.STATUS_CANCELED: "CANCELED",
                 GoalStatus.STATUS_ABORTED: "ABORTED"}


class ArmPlannerNode(Node):
    """Validates and sequences an excavator's arm goals; motion is delegated to ``arm_controller/move``."""

    def __init__(self, node_name: str = PLANNER_NODE, **kwargs) -> None:  # rclpy Node kwargs
        super().__init__(node_name, **kwargs)
        params = StartupParams(self)

        def path(name: str) -> str | None:
            return params.text(name) or None

        # the excavator the node plans for: the machine parameter, else the namespace; its kind's description
        # and planning files
        self.machine = machine_name(params.text("machine"), self.get_namespace())
        description = load_named(self.machine, path("machine_config")).require(EXCAVATOR)
        kin = ExcavatorKinematics(description)
        pcfg = load_planner_config(description.kind, path("planner_config"))
        ccfg = load_controller_settings(path("controller_config"))
        self.planner = ArmPlanner(kin, pcfg, ground_min_z=ccfg.collision.ground_min_z)
        # the _plan actions: collision objects from the DB, as the original's planning servers read them
        self.collision = CollisionPlanner(self.planner, ArmCollisionModel(kin, load_collision_config(
            description.kind, path("collision_config"))), via_tolerance_rad=ccfg.via_tolerance_rad)
        self._collision_record = params.text("collision_object_record_name")
        dump = params.text("collision_object_dump_record_name")
        self._dump_records = [r.strip() for r in dump.split(",") if r.strip()]
        db_uri, db_path = path("db_uri"), path("db_path")
        self._store = None
        if self._collision_record:  # the original's planning servers read the DB themselves (mongocxx)
            self._store = open_store(uri=db_uri, path=db_path)
        self._group = ReentrantCallbackGroup()
        self._ticker = Ticker(self, TICK_S, callback_group=self._group)
        self._q_waiters: list[Future] = []
        self._q_sub = None  # the joint_states subscription, only while a goal waits for one
        # where the last goal left the arm when it ended at a pass-through point (None otherwise): the
        # next plan starts there while the arm is still on its way (ArmPlanner.start_state)
        self._pass_through_end: np.ndarray | None = None
        self._ctl = RaceFreeActionClient(self, Zx200ArmMove, "arm_controller/move", callback_group=self._group)
        self._goals = RunningGoals()  # SIGINT/SIGTERM: running goals cancel their controller goal, then abort
        self._action_names = {TmsRpZx200ChangePose: CHANGE_POSE, TmsRpZx200ExcavateSimple: EXCAVATE_SIMPLE,
                              TmsRpZx200ReleaseSimple: RELEASE_SIMPLE}
        self._servers = [
            ActionServer(self, action_type, name,
                         execute_callback=functools.partial(self._execute, execute, action_type, name),
                         goal_callback=self._on_goal, cancel_callback=self._on_cancel, callback_group=self._group,
                         result_timeout=ACTION_RESULT_TIMEOUT_S)
            for action_type, name, execute in (
                (TmsRpZx200ChangePose, CHANGE_POSE, self._change_pose),
                (TmsRpZx200ExcavateSimple, EXCAVATE_SIMPLE, self._excavate),
                (TmsRpZx200ReleaseSimple, RELEASE_SIMPLE, self._release),
                (TmsRpZx200ChangePose, CHANGE_POSE_PLAN, self._change_pose_plan),
                (TmsRpZx200ExcavateSimple, EXCAVATE_SIMPLE_PLAN, self._excavate_plan),
            )
        ]
        #: goal id bytes -> (pass_through, theta_w_tolerance, expiry [monotonic s]) given before the goal
        self._options: dict[bytes, tuple[bool, float, float]] = {}
        self._options_srv = self.create_service(Zx200ChangePoseOptions, CHANGE_POSE_OPTIONS, self._on_options,
                                                callback_group=self._group)
        self._plan_options_srv = self.create_service(Zx200ChangePoseOptions, CHANGE_POSE_PLAN_OPTIONS,
                                                     self._on_options, callback_group=self._group)
        self._outcome_pub = self.create_publisher(Zx200PlanningOutcome, PLANNING_OUTCOME, OUTCOME_QOS)
        self.get_logger().info(f"{self.get_name()} ready")

    # -------------------------------------------------------------- joint_states, read when a goal needs them
    def _on_state(self, msg: JointState) -> None:
        idx = {n: i for i, n in enumerate(msg.name)}
        if not all(n in idx for n in JOINTS):
            return
        q = np.array([msg.position[idx[n]] for n in JOINTS])
        waiters, self._q_waiters = self._q_waiters, []
        for future in waiters:
            if not future.done():
                future.set_result(q)

    async def _current_q(self) -> np.ndarray | None:
        """The four front joints of the next joint_states naming them all (None when none comes in time)."""
        future = self._ticker.wake_on(Future())
        self._q_waiters.append(future)
        if self._q_sub is None:
            self._q_sub = self.create_subscription(JointState, "joint_states", self._on_state, 1,
                                                   callback_group=self._group)
        deadline = time.monotonic() + JOINT_STATES_WAIT_S
        while not future.done() and time.monotonic() < deadline:
            await self._ticker.next()
        if future in self._q_waiters:
            self._q_waiters.remove(future)
        if not self._q_waiters and self._q_sub is not None:
            self.destroy_subscription(self._q_sub)
            self._q_sub = None
        return future.result() if future.done() else None

    # -------------------------------------------------------------- goals, cancel, stop (run_node's hook)
    def _on_goal(self, _request) -> GoalResponse:
        if self._goals.stopping.is_set():
            self.get_logger().error(f"goal rejected: {self.get_name()} is stopping")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_cancel(self, _handle) -> CancelResponse:
        self._ticker.wake()  # forwarded to the controller now, not at the next tick
        return CancelResponse.ACCEPT

    async def _execute(self, execute, action_type, name, handle):
        with self._goals.running():
            try:
                return await execute(handle)
            except Exception as exc:  # the goal ends with a failure code, never rclpy's empty result
                self.get_logger().error(f"{name} goal failed inside the planner: {traceback.format_exc()}")
                if not handle.is_active:
                    raise
                return self._end(handle, action_type, codes.FAILURE, f"{self.get_name()} error: {exc!r}", name)

    def on_stop_requested(self) -> bool:
        """Cancel the running controller goals (the waits below see ``stopping``); True while any runs."""
        return self._goals.wind_down(STOP_TIMEOUT_S, lambda n: self.get_logger().warning(
            f"stopping: canceling {n} running goal(s) at the controller"))

    # -------------------------------------------------------------- change_pose options (ours, beside the action)
    def _on_options(self, request, response):
        tol = float(request.theta_w_tolerance)
        if not math.isfinite(tol) or tol < 0:
            response.accepted = False
            response.message = f"theta_w_tolerance must be a finite number >= 0 rad, got {tol}"
            return response
        now = time.monotonic()
        self._options = {k: v for k, v in self._options.items() if v[2] > now}  # unclaimed ones expire
        self._options[bytes(request.goal_id.uuid)] = (bool(request.pass_through), tol, now + OPTIONS_TTL_S)
        response.accepted = True
        return response

    def _take_options(self, handle) -> tuple[bool, float]:
        """The options given for this goal's id (pass_through, theta_w_tolerance); the defaults without."""
        pass_through, tol, _ = self._options.pop(bytes(handle.goal_id.uuid), (False, 0.0, 0.0))
        return pass_through, tol

    # -------------------------------------------------------------- common execution
    def _end(self, handle, action_type, code: int, message: str, name: str | None = None) -> object:
        """Publish the goal's outcome (code and text), then end it: SUCCEEDED, CANCELED or ABORTED by ``code``."""
        self._outcome_pub.publish(
            Zx200PlanningOutcome(
                action=f"{self.get_namespace().rstrip('/')}/{name or self._action_names[action_type]}",
                goal_id=handle.goal_id,
                error_code=int(code),
                message=message,
            )
        )
        result = action_type.Result()
        result.error_code.val = int(code)
        if code == codes.SUCCESS:
            handle.succeed()
        elif code == codes.CANCELED and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result

    async def _run(self, handle, action_type, plan, needs_q: bool = True, name: str | None = None,
                   report=None) -> object:
        t0 = time.monotonic()
        pass_through_end, self._pass_through_end = self._pass_through_end, None
        try:
            q = await self._current_q() if needs_q else None
            q_plan = self.planner.start_state(q, pass_through_end)
            if q_plan is not q:
                self.get_logger().info(
                    f"{action_type.__name__}: planned from the previous goal's pass-through end "
                    f"{np.round(q_plan, 3).tolist()} (measured {np.round(q, 3).tolist()})")
            t_state = time.monotonic()
            targets = plan(q_plan)
        except PlanningError as exc:
            self.get_logger().warning(f"goal rejected before motion: {exc}")
            return self._end(handle, action_type, exc.code, str(exc), name)
        deadline = time.monotonic() + 5.0
        while not self._ctl.server_is_ready():
            if time.monotonic() > deadline:
                return self._end(handle, action_type, codes.NO_VALID_CONTROL,
                                 "arm controller action arm_controller/move is not available", name)
            await self._ticker.next()
        t_plan = time.monotonic()
        code, message = await self._move(handle, action_type, targets, lambda: self.get_logger().info(
            f"{action_type.__name__}: {len(targets)} segment(s); joint_states {1e3 * (t_state - t0):.0f} ms, "
            f"plan {1e3 * (t_plan - t_state):.0f} ms, controller accepted {1e3 * (time.monotonic() - t_plan):.0f} ms "
            "later (wall)"))
        if code != codes.SUCCESS:
            if self._goals.stopping.is_set() and not handle.is_cancel_requested:  # ended by our stop
                return self._end(
                    handle, action_type, codes.FAILURE, f"{self.get_name()} stopping (SIGINT/SIGTERM): {message}", name
                )
            return self._end(handle, action_type, code, message, name)
        self._pass_through_end = self.planner.pass_through_end(targets)
        return self._end(handle, action_type, codes.SUCCESS, report() if report is not None else "done", name)

    @staticmethod
    def _segments(targets) -> list:
        """The plan as controller segments. Every segment but the last is a via point (approach,
        carry, ...: via_tolerance_*); so is a last one the planner marks (excavate's lift, release's
        open: the next goal goes on from it)."""
        out = []
        for k, target in enumerate(targets):
            seg = Zx200ArmSegment(label=target.label, speed_scale=float(target.speed_scale),
                                  via=bool(target.via or k < len(targets) - 1), measured=bool(target.measured))
            if isinstance(target, JointTarget):
                seg.kind = Zx200ArmSegment.JOINT
                seg.joint_positions = [float(v) for v in target.q]
            else:
                seg.kind = Zx200ArmSegment.CARTESIAN
                seg.position.x, seg.position.y, seg.position.z = (float(v) for v in target.position)
                seg.theta_w = float(target.theta_w)
            out.append(seg)
        return out

    async def _move(self, handle, action_type, targets, on_accepted) -> tuple[int, str]:
        """Run the plan as one controller goal; the controller's phase feedback is forwarded."""
        goal = Zx200ArmMove.Goal(segments=self._segments(targets))
        fb = action_type.Feedback()
        fb.state = targets[0].label
        handle.publish_feedback(fb)
        last_label = [fb.state]

        def forward(msg) -> None:
            label = msg.feedback.label
            if label and label != last_label[0]:
                last_label[0] = label
                out = action_type.Feedback()
                out.state = label
                handle.publish_feedback(out)

        # Every wait below is bounded: a goal always ends, and never leaves the arm driving blind.
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        send = self._ticker.wake_on(self._ctl.send_goal_async(goal, feedback_callback=forward, goal_uuid=goal_id))
        deadline = time.monotonic() + GOAL_RESPONSE_TIMEOUT_S
        while not send.done():
            stopping = self._goals.stopping.is_set()
            if stopping or time.monotonic() > deadline:
                # The goal may run on the controller without us knowing: cancel it by its id.
                self._ctl.cancel_goal_by_id(goal_id)
                if stopping:
                    return codes.CANCELED, "goal sent to the arm controller canceled before its answer"
                return codes.NO_VALID_CONTROL, (
                    f"arm controller did not answer the goal within {GOAL_RESPONSE_TIMEOUT_S:g} s (cancel sent)")
            await self._ticker.next()
        gh = send.result()
        if not gh.accepted:
            return codes.NO_VALID_CONTROL, "arm controller rejected the goal"
        on_accepted()
        code, message = await self._await_result(handle, gh)
        if code not in (codes.SUCCESS, codes.CANCELED) and last_label[0] not in message:
            message = f"{last_label[0]}: {message}"
        return code, message

    async def _await_result(self, handle, gh) -> tuple[int, str]:
        """Wait for the controller's result; recover a lost result from the goal status topic."""
        res_future = self._ticker.wake_on(gh.get_result_async())
        cancel_sent = False
        ended_at: float | None = None
        asked_again = False
        server_seen = time.monotonic()
        terminal = {GoalStatus.STATUS_SUCCEEDED: codes.SUCCESS, GoalStatus.STATUS_CANCELED: codes.CANCELED,
                    GoalStatus.STATUS_ABORTED: codes.FAILURE}
        while not res_future.done():
            now = time.monotonic()
            if (handle.is_cancel_requested or self._goals.stopping.is_set()) and not cancel_sent:
                gh.cancel_goal_async()
                cancel_sent = True
            if gh.status in terminal:
                ended_at = ended_at or now
                if now - ended_at > RESULT_GRACE_S:
                    if not asked_again:  # the result server keeps results (result_timeout): ask again
                        self.get_logger().warning("controller goal ended but its result did not arrive: asking again")
                        res_future = self._ticker.wake_on(gh.get_result_async())
                        asked_again, ended_at = True, now
                        continue
                    code = terminal[gh.status]
                    return code, f"controller goal ended with status {gh.status} (result message lost)"
            if self._ctl.server_is_ready():
                server_seen = now
            elif now - server_seen > SERVER_GONE_S:
                return codes.NO_VALID_CONTROL, f"arm controller action server gone for {SERVER_GONE_S:g} s"
            await self._ticker.next()
        outcome = res_future.result()
        res = outcome.result
        if cancel_sent and outcome.status == GoalStatus.STATUS_CANCELED:  # the controller's CANCELED means at rest
            return codes.CANCELED, f"canceled, arm at rest (controller: {res.message or 'no message'})"
        # a controller goal that did not succeed never passes on SUCCESS or the empty result's 0
        code, message = codes.reported(
            outcome.status == GoalStatus.STATUS_SUCCEEDED,
            res.error_code.val,
            res.message,
            f"{_STATUS_NAMES.get(outcome.status, f'status {outcome.status}')} at the arm controller",
        )
        if cancel_sent:
            return code, f"cancel sent, but the controller ended the goal with status {outcome.status}: {message}"
        return code, message

    # -------------------------------------------------------------- the three actions
    async def _change_pose(self, handle):
        g = handle.request
        pass_through, theta_w_tolerance = self._take_options(handle)

        def plan(q_plan):
            return self.planner.change_pose(
                joint_names=list(g.trajectory.joint_names),
                joint_points=[list(p.positions) for p in g.trajectory.points],
                poses=[([p.position.x, p.position.y, p.position.z],
                        [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]) for p in g.pose_sequence],
                positions_with_angle=[([p.position.x, p.position.y, p.position.z], p.theta_w)
                                      for p in g.position_with_angle_sequence],
                current_q=q_plan,
                pass_through=pass_through,
                theta_w_tolerance=theta_w_tolerance,
            )

        return await self._run(handle, TmsRpZx200ChangePose, plan)

    async def _excavate(self, handle):
        p = handle.request.position_with_angle
        return await self._run(handle, TmsRpZx200ExcavateSimple, lambda _q_plan: self.planner.excavate(
            [p.position.x, p.position.y, p.position.z], p.theta_w, p.offset), needs_q=False)

    async def _release(self, handle):
        def plan(q_plan):
            if q_plan is None:
                raise PlanningError(f"no joint_states received within {JOINT_STATES_WAIT_S:g} s")
            return self.planner.release(handle.request.target_angle, q_plan)

        return await self._run(handle, TmsRpZx200ReleaseSimple, plan)

    def destroy_node(self) -> None:
        if self._store is not None:
            self._store.close()
        super().destroy_node()

    # -------------------------------------------------------------- the _plan actions (collision objects)
    def _scene(self) -> Scene:
        """The collision objects and link padding for one goal, read from the DB now (the carrier may have moved)."""
        if self._dump_records:
            raise CollisionRecordError(self._dump_records[0], "data", "mesh collision objects (parameter "
                                       "collision_object_dump_record_name) are not supported: give the object as a "
                                       "primitive in the collision_objects of collision_object_record_name's record")
        if not self._collision_record:
            return Scene([], self.collision.model.padding_for())
        try:
            doc = self._store.get_record(self._collision_record)
        except RecordNotFound:
            raise CollisionRecordError(self._collision_record, None, "not found in the parameter collection "
                                       "(planner parameter collision_object_record_name)") from None
        except StoreError as exc:
            raise CollisionRecordError(self._collision_record, None, f"cannot be read: {exc}") from None
        objects, padding = objects_from_record(doc, self._collision_record, self.planner.kin.machine.kind)
        return Scene(objects, self.collision.model.padding_for(padding))

    def _plan_report(self) -> str:
        r = self.collision.report
        clearance = "none within 1 m" if math.isinf(r.min_clearance) else f"{r.min_clearance:.3f} m"
        text = f"done; {r.checked} configurations checked, smallest clearance beyond padding {clearance}"
        return text + (f"; detours: {'; '.join(r.detours)}" if r.detours else "")

    async def _change_pose_plan(self, handle):
        g = handle.request
        pass_through, theta_w_tolerance = self._take_options(handle)

        def plan(q_plan):
            scene = self._scene()
            targets = self.collision.change_pose(
                scene,
                joint_names=list(g.trajectory.joint_names),
                joint_points=[list(p.positions) for p in g.trajectory.points],
                poses=[([p.position.x, p.position.y, p.position.z],
                        [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]) for p in g.pose_sequence],
                positions_with_angle=[([p.position.x, p.position.y, p.position.z], p.theta_w)
                                      for p in g.position_with_angle_sequence],
                current_q=q_plan, pass_through=pass_through, theta_w_tolerance=theta_w_tolerance)
            self.get_logger().info(
                f"{CHANGE_POSE_PLAN}: {len(scene.objects)} collision object(s); {self._plan_report()}"
            )
            return targets

        return await self._run(handle, TmsRpZx200ChangePose, plan, name=CHANGE_POSE_PLAN, report=self._plan_report)

    async def _excavate_plan(self, handle):
        p = handle.request.position_with_angle

        def plan(q_plan):
            scene = self._scene()
            targets = self.collision.excavate(scene, [p.position.x, p.position.y, p.position.z], p.theta_w, p.offset,
                                              q_plan)
            self.get_logger().info(f"{EXCAVATE_SIMPLE_PLAN}: {len(scene.objects)} collision object(s); "
                                   f"{self._plan_report()}")
            return targets

        return await self._run(handle, TmsRpZx200ExcavateSimple, plan, name=EXCAVATE_SIMPLE_PLAN,
                               report=self._plan_report)


def main() -> int:
    # stop_in_context: on SIGINT/SIGTERM running goals cancel their controller goals and end (on_stop_requested)
    return run_node(ArmPlannerNode, executor="single", stop_in_context=True)
