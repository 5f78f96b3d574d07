"""Every subtask as one row: record -> planning goal data, downstream action and its result check.

``SUBTASKS`` maps a subtask action name (served at ``/<model_name>/<name>``) to a :class:`SubtaskSpec`,
the one place a subtask is defined: its name family, its planning action (relative to the machine
namespace; or a service, ``downstream="service"``) and that action's type, ``build(doc, record_name) -> dict`` that
validates the record and
returns the planning goal as plain data, ``goal(plan) -> <action>.Goal``, ``options(plan)`` for what a goal
needs beyond the planning type (ZX200 change_pose: tms_msg/srv/Zx200ChangePoseOptions) and ``check(result)
-> (ok, detail)`` that reads the planning result's own typed code. The ZX200 rows speak the original's
tms_msg_rp actions (:mod:`tms_if_opera.interface`). A missing or malformed field raises
:class:`SubtaskRecordError` naming the record and the field. Adding a subtask is adding a row.

A row may need the machine's state besides its record: ``resolve(plan, joints, machine) -> plan`` gets the
latest ``/<model_name>/joint_states`` (name -> position) and the machine's description (None when the name is
not on the site) and finishes the plan (the sample subtasks keep the other joints where they are; the swing
alignment picks 0 or pi). ``reads_record=False``: the row reads no record (the original's swing alignment).

Which machine serves which rows: ``KIND_SUBTASKS`` maps each machine kind to the name patterns of its rows
(the original's prefixes: kind ``mst2200vd`` serves ``st_mst2200_*`` and, as the original's trees send it to
``/mst2200``, ``st_ic120_release_soil``). A subtask server for machine NAME serves :func:`subtasks_for` its
kind under ``/<NAME>/<subtask>``. Adding a kind is adding its entry (and rows, if its names are new); the
travel rows of a name prefix are :func:`travel_rows`.

Planning goal data (``kind`` -> keys):

* ``change_pose``: ``mode`` joints|pose|position_with_angle and ``joints`` {name: rad} | ``pose``
  {x..qw} | ``pwa`` {x, y, z, theta_w}; ``pass_through`` (the record's optional 0/1 field: end at the
  target without waiting for rest, the next goal continues the motion); ``theta_w_tolerance`` (optional
  [rad], default 0: the nearest holdable edge angle within it where theta_w cannot be held)
* ``excavate``: ``pwa`` {x, y, z, theta_w, offset}; ``release``/``dump``: ``target_angle``
* ``excavate_design`` (ours, beside the original's): :class:`~tms_ts.plans.DesignPlan` from the record's
  ``design`` (a design's name, tms_db collection ``design``), ``base_x``, ``base_y``, ``base_yaw`` [rad] (and
  ``base_z``, default 0: the excavator's base_link on the map; or ``base_measured`` 1 instead of x, y, yaw: the
  machine's own pose from ``/<model_name>/odom_pose`` when the subtask starts, e.g. after a travel subtask),
  ``scope`` (``design``, default: done when the whole design is within tolerance; ``reachable``: done when nothing
  reachable from the base is worth a pass, one base pose of several), optional ``dump_x``, ``dump_y`` (map; both or
  none: a fixed dump place, e.g. a carrier's vessel or a spoil heap; absent: the pass planner's place) and ``dump_z``
  (its ground), ``dump_height`` (1.5 m), ``theta_w`` (1.1 rad), ``max_passes`` (200), ``terrain_id`` (3031, the
  dynamic terrain's DATA_ID). The row's ``steps`` name the rows whose planning actions each pass runs
  (excavate, change_pose, release; :mod:`tms_ts.design_excavation`); the server loops until the pass planner stops.
* ``navigate_to_pose``: ``pose`` {x, y, z, qx..qw}; ``follow_waypoints`` / ``navigate_through_poses``:
  ``poses`` [{x, y, z, qx..qw}, ...] in frame ``map``. ``_deg`` variants give yaw in degrees.
* ``swing``: ``target_angle`` [rad] (SetSwingAngle); ``swing_align``: ``target_angle`` 0 or pi, whichever is
  nearer the swing joint's position (resolved from ``joint_states``)
* ``sample``: ``joint`` and ``goal`` [rad] (the record's ``<machine>_<joint>_goal_pos`` [deg]); resolved to
  ``joints`` [rad] of the four front joints, the others where they are (one JOINT segment of
  ``arm_controller/move``, tms_msg/action/Zx200ArmMove: the arm controller moves the joint and reports
  SUCCESS when it is there; the original's stub published std_msgs/Float64 on ``/zx200/<joint>/cmd``, a topic
  no node of OPERA's stack nor ours subscribes)

Imports message types only (no rclpy).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from fnmatch import fnmatchcase
from typing import Any

from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Point, Pose, PoseStamped
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from com3_msgs.action import SetDumpAngle, SetSwingAngle
from com3_msgs.srv import DumpUp
from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from tms_common.errors import ConfigError
from tms_if_opera.interface import (
    CHANGE_POSE,
    CHANGE_POSE_PLAN,
    EXCAVATE_SIMPLE,
    EXCAVATE_SIMPLE_PLAN,
    RELEASE_SIMPLE,
)
from tms_model.fleet import vessel_swing_joint
from tms_msg.action import Zx200ArmMove
from tms_msg.msg import Zx200ArmSegment
from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple
from tms_msg_rp.msg import TmsRpErrorCodes, TmsRpZx200PositionWithAngle
from tms_ts.errors import SubtaskRecordError, SubtaskStateError
from tms_ts.plans import (
    JOINTS,
    POSE,
    POSITION_WITH_ANGLE,
    AnglePlan,
    ChangePosePlan,
    DesignPlan,
    ExcavatePlan,
    Plan,
    PosePlan,
    PosesPlan,
    SamplePlan,
    SwingAlignPlan,
)

__all__ = ["SubtaskSpec", "SUBTASKS", "KIND_SUBTASKS", "subtasks_for", "travel_rows", "ZX200_JOINTS",
           "change_pose_goal", "change_pose_options", "zx200_ok", "nav2_ok", "dump_ok", "dump_up_ok", "swing_ok",
           "arm_ok", "planning_verdict"]

ZX200_JOINTS = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")
_QUAT = ("qx", "qy", "qz", "qw")


def _num(doc: dict, record: str, field: str, default: Any = None) -> float:
    if field not in doc:
        if default is not None:
            return float(default)
        raise SubtaskRecordError(record, field, "missing")
    value = doc[field]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(float(value)):
        raise SubtaskRecordError(record, field, f"must be a finite number, got {value!r}")
    return float(value)


def _arr(doc: dict, record: str, field: str) -> list[float]:
    if field not in doc:
        raise SubtaskRecordError(record, field, "missing")
    value = doc[field]
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value:
        raise SubtaskRecordError(record, field, f"must be a non-empty array of numbers, got {value!r}")
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(float(v)):
            raise SubtaskRecordError(record, f"{field}[{i}]", f"must be a finite number, got {v!r}")
    return [float(v) for v in value]


def _flag(doc: dict, field: str) -> bool:
    value = doc.get(field, 0)
    return not isinstance(value, bool) and isinstance(value, int | float) and value > 0.5 or value is True


def _yaw_quat(yaw_deg: float) -> dict[str, float]:
    half = math.radians(yaw_deg) / 2.0
    return {"qx": 0.0, "qy": 0.0, "qz": math.sin(half), "qw": math.cos(half)}


def _unit_quat(record: str, q: dict[str, float]) -> dict[str, float]:
    norm = math.sqrt(sum(v * v for v in q.values()))
    if norm < 1e-6:
        raise SubtaskRecordError(record, "qw", "quaternion qx,qy,qz,qw has zero length")
    return {k: v / norm for k, v in q.items()}


def _bool(doc: dict, record: str, field: str) -> bool:
    """An optional 0/1 or true/false field (absent = false); anything else names the record and field."""
    value = doc.get(field, False)
    if isinstance(value, bool):
        return value
    if isinstance(value, int | float) and value in (0, 1):
        return bool(value)
    raise SubtaskRecordError(record, field, f"must be 0/1 or true/false, got {value!r}")


def build_change_pose(doc: dict, record: str) -> ChangePosePlan:
    target = _change_pose_target(doc, record)
    tolerance = _num(doc, record, "theta_w_tolerance", 0.0)
    if tolerance < 0:
        raise SubtaskRecordError(record, "theta_w_tolerance", f"must be >= 0 rad, got {tolerance}")
    if tolerance > 0 and target.mode == JOINTS:
        raise SubtaskRecordError(
            record, "theta_w_tolerance", "applies to pose / position_with_angle targets, not joints"
        )
    return replace(target, pass_through=_bool(doc, record, "pass_through"), theta_w_tolerance=tolerance)


def _change_pose_target(doc: dict, record: str) -> ChangePosePlan:
    if _flag(doc, "trajectory"):
        return ChangePosePlan(JOINTS, joints={j: _num(doc, record, j) for j in ZX200_JOINTS})
    if _flag(doc, "pose"):
        pose = {k: _num(doc, record, k) for k in ("x", "y", "z")}
        pose.update(_unit_quat(record, {k: _num(doc, record, k) for k in _QUAT}))
        return ChangePosePlan(POSE, pose=pose)
    if _flag(doc, "position_with_angle"):
        return ChangePosePlan(POSITION_WITH_ANGLE, pwa={k: _num(doc, record, k) for k in ("x", "y", "z", "theta_w")})
    raise SubtaskRecordError(record, "trajectory|pose|position_with_angle", "no target kind selected (one must be 1)")


def build_excavate(doc: dict, record: str) -> ExcavatePlan:
    if not _flag(doc, "position_with_angle"):
        raise SubtaskRecordError(record, "position_with_angle", "must be 1 for an excavation target")
    pwa = {k: _num(doc, record, k) for k in ("x", "y", "z", "theta_w")}
    pwa["offset"] = _num(doc, record, "offset", 0.0)
    return ExcavatePlan(pwa)


#: a design record's ``scope``: done when the whole design is within tolerance, or when nothing reachable from the
#: base is worth a pass (one base pose of several, each a subtask of the tree)
DESIGN_SCOPES = ("design", "reachable")


def build_excavate_design(doc: dict, record: str) -> DesignPlan:
    """The design subtask's record (see the module docstring): a design name, the base pose, the dump place."""
    design = doc.get("design")
    if not isinstance(design, str) or not design.strip():
        raise SubtaskRecordError(record, "design", f"must be a design's name (tms-db design list), got {design!r}")
    measured = _bool(doc, record, "base_measured")
    if measured:
        given = [f"base_{k}" for k in ("x", "y", "yaw") if f"base_{k}" in doc]
        if given:
            raise SubtaskRecordError(record, given[0], "give base_x, base_y, base_yaw or base_measured, not both")
        base = {}
    else:
        base = {k: _num(doc, record, f"base_{k}") for k in ("x", "y", "yaw")}
    base["z"] = _num(doc, record, "base_z", 0.0)
    scope = doc.get("scope", "design")
    if scope not in DESIGN_SCOPES:
        raise SubtaskRecordError(record, "scope", f"must be one of {', '.join(DESIGN_SCOPES)}, got {scope!r}")
    given = [k for k in ("dump_x", "dump_y") if k in doc]
    if len(given) == 1:
        raise SubtaskRecordError(record, "dump_x|dump_y", f"give both or neither (only {given[0]} is there)")
    dump = None
    if given:
        dump = {"x": _num(doc, record, "dump_x"), "y": _num(doc, record, "dump_y")}
        if "dump_z" in doc:
            dump["z"] = _num(doc, record, "dump_z")
    height = _num(doc, record, "dump_height", 1.5)
    if not 0.0 < height <= 10.0:
        raise SubtaskRecordError(record, "dump_height", f"must be in (0, 10] m, got {height}")
    passes = _num(doc, record, "max_passes", 200)
    if passes != int(passes) or not 1 <= passes <= 100000:
        raise SubtaskRecordError(record, "max_passes", f"must be an integer 1..100000, got {passes}")
    terrain = _num(doc, record, "terrain_id", 3031)
    if terrain != int(terrain):
        raise SubtaskRecordError(record, "terrain_id", f"must be an integer, got {terrain}")
    theta_w = _num(doc, record, "theta_w", 1.1)
    return DesignPlan(design=design, base=base, dump=dump, dump_height=height, theta_w=theta_w,
                      max_passes=int(passes), terrain_id=int(terrain), base_measured=measured, scope=scope)


def build_angle(what: str) -> Callable[[dict, str], AnglePlan]:
    """``target_angle`` [rad] of a release (bucket), dump (vessel) or swing (vessel swing) record."""
    return lambda doc, record: AnglePlan(what, _num(doc, record, "target_angle"))


build_release, build_dump, build_swing = build_angle("release"), build_angle("dump"), build_angle("swing")


def build_swing_align(doc: dict, record: str) -> SwingAlignPlan:
    """The original's align subtask reads no record: the target comes from joint_states
    (:func:`resolve_swing_align`)."""
    return SwingAlignPlan()


def resolve_swing_align(plan: SwingAlignPlan, joints: dict[str, float], machine: Any) -> SwingAlignPlan:
    """0 or pi, whichever is nearer (wrapped) the position of the vessel's swing joint: the description's
    (:func:`tms_model.fleet.vessel_swing_joint`), else ``swing_joint`` as the original reads."""
    joint = vessel_swing_joint(machine) if machine is not None else None
    name = joint.name if joint is not None else "swing_joint"
    if name not in joints:
        raise SubtaskStateError(f"no {name} on joint_states (has {sorted(joints)})")
    q = joints[name]
    to_zero, to_pi = abs(math.remainder(q, 2 * math.pi)), abs(math.remainder(q - math.pi, 2 * math.pi))
    return SwingAlignPlan(0.0 if to_zero <= to_pi else math.pi)


def build_sample(machine: str, joint: str) -> Callable[[dict, str], SamplePlan]:
    """The original's single-joint sample subtask: field ``<machine>_<joint>_goal_pos`` [deg] of ``<joint>_joint``."""
    field = f"{machine}_{joint}_goal_pos"

    def build(doc: dict, record: str) -> SamplePlan:
        return SamplePlan(f"{joint}_joint", math.radians(_num(doc, record, field)))

    return build


def resolve_sample(plan: SamplePlan, joints: dict[str, float], machine: Any) -> SamplePlan:
    """The four front joints: the sampled one at its goal, the others where joint_states has them."""
    missing = [j for j in ZX200_JOINTS if j not in joints]
    if missing:
        raise SubtaskStateError(f"no {', '.join(missing)} on joint_states (has {sorted(joints)})")
    return replace(plan, joints={j: plan.goal if j == plan.joint else joints[j] for j in ZX200_JOINTS})


def build_nav_pose(deg: bool) -> Callable[[dict, str], PosePlan]:
    def build(doc: dict, record: str) -> PosePlan:
        pose = {"x": _num(doc, record, "x"), "y": _num(doc, record, "y"), "z": _num(doc, record, "z", 0.0)}
        if deg:
            pose.update(_yaw_quat(_num(doc, record, "yaw")))
        else:
            pose.update(_unit_quat(record, {k: _num(doc, record, k) for k in _QUAT}))
        return PosePlan(pose)

    return build


def build_poses(what: str, deg: bool) -> Callable[[dict, str], PosesPlan]:
    def build(doc: dict, record: str) -> PosesPlan:
        xs, ys = _arr(doc, record, "x"), _arr(doc, record, "y")
        zs = _arr(doc, record, "z") if "z" in doc else [0.0] * len(xs)
        fields = ["yaw"] if deg else list(_QUAT)
        extra = {f: _arr(doc, record, f) for f in fields}
        n = len(xs)
        for name, values in [("y", ys), ("z", zs), *extra.items()]:
            if len(values) == 1 and n > 1 and name not in ("y", "z"):
                extra[name] = values * n  # navigate_through_poses: one orientation for all poses
            elif len(values) != n:
                raise SubtaskRecordError(record, name, f"has {len(values)} elements, x has {n}")
        poses = []
        for i in range(n):
            pose = {"x": xs[i], "y": ys[i], "z": zs[i]}
            if deg:
                pose.update(_yaw_quat(extra["yaw"][i]))
            else:
                pose.update(_unit_quat(record, {k: extra[k][i] for k in _QUAT}))
            poses.append(pose)
        return PosesPlan(what, tuple(poses))

    return build


# planning goal data -> goal messages -------------------------------------------------------------
def _pose(p: dict) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = p["x"], p["y"], p["z"]
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = p["qx"], p["qy"], p["qz"], p["qw"]
    return pose


def _stamped(p: dict) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = "map"
    msg.pose = _pose(p)
    return msg


def _pwa(d: dict) -> TmsRpZx200PositionWithAngle:
    return TmsRpZx200PositionWithAngle(position=Point(x=d["x"], y=d["y"], z=d["z"]), theta_w=d["theta_w"],
                                       offset=d.get("offset", 0.0))


def change_pose_goal(plan: ChangePosePlan) -> TmsRpZx200ChangePose.Goal:
    """The original's goal: exactly one of trajectory / pose_sequence / position_with_angle_sequence."""
    goal = TmsRpZx200ChangePose.Goal()
    if plan.mode == JOINTS and plan.joints is not None:
        goal.trajectory = JointTrajectory(joint_names=list(plan.joints))
        goal.trajectory.points = [JointTrajectoryPoint(positions=list(plan.joints.values()))]
    elif plan.mode == POSE and plan.pose is not None:
        goal.pose_sequence = [_pose(plan.pose)]
    elif plan.mode == POSITION_WITH_ANGLE and plan.pwa is not None:
        goal.position_with_angle_sequence = [_pwa(plan.pwa)]
    else:
        raise ValueError(f"change_pose plan without the target of its mode {plan.mode!r}: {plan}")
    return goal


def change_pose_options(plan: ChangePosePlan) -> dict | None:
    """What the goal needs beyond the original's type (tms_msg/srv/Zx200ChangePoseOptions fields), or None
    when it needs nothing beyond it (then no options are sent and a planner without them serves it too)."""
    options = {"pass_through": plan.pass_through, "theta_w_tolerance": plan.theta_w_tolerance}
    return options if plan.pass_through or plan.theta_w_tolerance > 0 else None


def _poses_goal(action_type: Any) -> Callable[[PosesPlan], Any]:
    return lambda plan: action_type.Goal(poses=[_stamped(p) for p in plan.poses])


# planning results -> (ok, detail for people) ---------------------------------------------------------
def zx200_ok(result) -> tuple[bool, str]:  # a TmsRpZx200* action result
    """tms_msg_rp/TmsRpErrorCodes: SUCCESS or a failure code (the text comes from the planning outcome topic)."""
    return result.error_code.val == TmsRpErrorCodes.SUCCESS, f"error_code {result.error_code.val}"


def nav2_ok(result) -> tuple[bool, str]:  # a Nav2-shaped action result
    """Nav2 ``error_code``: NONE (0) or a failure code."""
    return result.error_code == 0, f"error_code {result.error_code}: {result.error_msg}"


def dump_ok(result) -> tuple[bool, str]:  # com3_msgs SetDumpAngle.Result
    """com3_msgs SetDumpAngle: the ``success`` flag (the peer's result carries no reason; the server logs it)."""
    return bool(result.success), "" if result.success else "success false (the set_dump_angle server's log says why)"


def swing_ok(result) -> tuple[bool, str]:  # com3_msgs SetSwingAngle.Result
    """com3_msgs SetSwingAngle: the ``success`` flag (the server logs the reason)."""
    return bool(result.success), "" if result.success else "success false (the set_swing_angle server's log says why)"


def dump_up_ok(response) -> tuple[bool, str]:  # com3_msgs DumpUp.Response
    """com3_msgs/srv/DumpUp: the reply's ``result`` (the server logs the reason)."""
    return bool(
        response.result
    ), "" if response.result else "result false (the vessel_target_pos server's log says why)"


def arm_ok(result) -> tuple[bool, str]:  # tms_msg Zx200ArmMove.Result
    """The arm controller: TmsRpErrorCodes SUCCESS, else its code and message."""
    return result.error_code.val == TmsRpErrorCodes.SUCCESS, f"error_code {result.error_code.val}: {result.message}"


_STATUS_NAMES = {GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED", GoalStatus.STATUS_CANCELED: "CANCELED",
                 GoalStatus.STATUS_ABORTED: "ABORTED"}


def planning_verdict(check: Callable[[Any], tuple[bool, str]], result: Any, status: int) -> tuple[bool, str]:
    """(ok, detail) of a planning goal that ended with action ``status`` and ``result``, read by its row's ``check``.

    ok only when the goal SUCCEEDED and ``check`` reads its result as a success. A goal that ended otherwise
    while its result reads as a success, or whose result is empty (rclpy ends a goal whose execute callback
    raised ABORTED with a default-constructed result: Nav2's error_code 0 there reads as NONE, TmsRpErrorCodes'
    0 is no code at all), is named for what happened instead of passing on that code as the failure's.
    """
    ok, detail = check(result)
    empty = result == type(result)()
    if status == GoalStatus.STATUS_SUCCEEDED:
        if ok or not empty:
            return ok, detail
        return False, f"planning goal SUCCEEDED with an empty result ({detail})"
    name = _STATUS_NAMES.get(status, f"with status {status}")
    if empty:
        return False, f"planning goal {name} without a result (an empty result: {detail})"
    if ok:
        return False, f"planning goal {name} although its result reads as a success ({detail})"
    return False, detail


@dataclass(frozen=True)
class SubtaskSpec:
    """One subtask: machine family, downstream planning action, record -> goal, result check."""

    name: str
    machine: str
    planning_action: str  # relative to /<model_name>
    action_type: Any  # the planning action's type, e.g. tms_msg_rp.action.TmsRpZx200ChangePose
    build: Callable[[dict, str], Plan]
    goal: Callable[[Any], Any]  # the row's own Plan type -> its goal or request
    check: Callable[[Any], tuple[bool, str]]
    #: the original non-plan ZX200 change_pose / excavate_simple set LOCK_FLG=false when a result arrives
    clears_lock_flg: bool = False
    #: plan -> the goal's options beyond the planning type (None: none needed), sent to ``<planning>/options``
    options: Callable[[Any], dict | None] | None = None
    #: the planning server publishes each goal's outcome text on /<model_name>/tms_rp_zx200_outcome
    outcome_topic: bool = False
    #: "action" or "service" (``action_type`` is then the service type, ``goal`` builds its request and ``check``
    #: reads its response)
    downstream: str = "action"
    #: False: the row reads no record (the goal's record_name is not looked up)
    reads_record: bool = True
    #: (plan, joints {name: rad} from /<model_name>/joint_states, the machine's description or None) -> plan
    resolve: Callable[[Any, dict[str, float], Any], Plan] | None = None
    #: a row that runs several downstream goals (the design subtask): step name -> the row whose planning action,
    #: goal and check serve it (tms_ts.design_excavation); None: one goal to ``planning_action``
    steps: dict[str, SubtaskSpec] | None = None


def _excavate_goal(plan: ExcavatePlan) -> TmsRpZx200ExcavateSimple.Goal:
    return TmsRpZx200ExcavateSimple.Goal(position_with_angle=_pwa(plan.pwa))


def _nav_pose_goal(plan: PosePlan) -> NavigateToPose.Goal:
    return NavigateToPose.Goal(pose=_stamped(plan.pose))


_FW, _NTP = _poses_goal(FollowWaypoints), _poses_goal(NavigateThroughPoses)


def travel_rows(prefix: str) -> list[SubtaskSpec]:
    """``st_<prefix>_{follow_waypoints,navigate_anywhere,navigate_through_poses}[_deg]``: the original's travel
    subtasks of every tracked machine, to the Nav2-named actions of the machine's navigator (tms_rp)."""
    rows = []
    for deg in (False, True):
        tail = "_deg" if deg else ""
        rows += [
            SubtaskSpec(f"st_{prefix}_follow_waypoints{tail}", prefix, "follow_waypoints", FollowWaypoints,
                        build_poses("follow_waypoints", deg), _FW, nav2_ok),
            SubtaskSpec(f"st_{prefix}_navigate_anywhere{tail}", prefix, "navigate_to_pose", NavigateToPose,
                        build_nav_pose(deg), _nav_pose_goal, nav2_ok),
            SubtaskSpec(f"st_{prefix}_navigate_through_poses{tail}", prefix, "navigate_through_poses",
                        NavigateThroughPoses, build_poses("navigate_through_poses", deg), _NTP, nav2_ok),
        ]
    return rows


def _swing_rows(prefix: str) -> list[SubtaskSpec]:
    """The vessel swing and the DumpUp release of an MST-type carrier (the vessel controller of tms_rc)."""
    swing_goal = lambda plan: SetSwingAngle.Goal(target_angle=plan.target_angle)  # noqa: E731
    return [
        SubtaskSpec(f"st_{prefix}_release_soil", prefix, "vessel_target_pos", DumpUp, build_dump,
                    lambda plan: DumpUp.Request(vessel_angle=plan.target_angle), dump_up_ok, downstream="service"),
        SubtaskSpec(f"st_{prefix}_swing", prefix, "set_swing_angle", SetSwingAngle, build_swing, swing_goal, swing_ok),
        SubtaskSpec(f"st_{prefix}_swing_align_to_heading", prefix, "set_swing_angle", SetSwingAngle, build_swing_align,
                    swing_goal, swing_ok, reads_record=False, resolve=resolve_swing_align),
    ]


def _sample_rows(prefix: str) -> list[SubtaskSpec]:
    """The original's single-joint sample subtasks of an excavator, through its arm controller."""
    goal = lambda plan: Zx200ArmMove.Goal(segments=[Zx200ArmSegment(  # noqa: E731
        kind=Zx200ArmSegment.JOINT, label=f"sample {plan.joint}",
        joint_positions=[plan.joints[j] for j in ZX200_JOINTS])])
    return [SubtaskSpec(f"st_{prefix}_sample_{j}", prefix, "arm_controller/move", Zx200ArmMove, build_sample(prefix, j),
                        goal, arm_ok, resolve=resolve_sample) for j in ("swing", "boom", "arm", "bucket")]


def _design_row(prefix: str, change_pose: SubtaskSpec, excavate: SubtaskSpec, release: SubtaskSpec) -> SubtaskSpec:
    """Ours: excavation to a stored design, each pass through the original's excavate, change_pose and release
    planning actions (their rows' goals and checks; no LOCK_FLG: the design record is not sensing's target)."""
    steps = {"excavate": replace(excavate, clears_lock_flg=False),
             "change_pose": replace(change_pose, clears_lock_flg=False), "release": release}
    return SubtaskSpec(f"subtask_{prefix}_excavate_design", prefix, excavate.planning_action, excavate.action_type,
                       build_excavate_design, excavate.goal, zx200_ok, outcome_topic=True, steps=steps)


_ZX200_CHANGE_POSE = SubtaskSpec("subtask_zx200_change_pose", "zx200", CHANGE_POSE, TmsRpZx200ChangePose,
                                 build_change_pose, change_pose_goal, zx200_ok, clears_lock_flg=True,
                                 options=change_pose_options, outcome_topic=True)
_ZX200_EXCAVATE = SubtaskSpec("subtask_zx200_excavate_simple", "zx200", EXCAVATE_SIMPLE, TmsRpZx200ExcavateSimple,
                              build_excavate, _excavate_goal, zx200_ok, clears_lock_flg=True, outcome_topic=True)
_ZX200_RELEASE = SubtaskSpec("subtask_zx200_release_simple", "zx200", RELEASE_SIMPLE, TmsRpZx200ReleaseSimple,
                             build_release, lambda plan: TmsRpZx200ReleaseSimple.Goal(target_angle=plan.target_angle),
                             zx200_ok, outcome_topic=True)

_SPECS = [
    _ZX200_CHANGE_POSE,
    _ZX200_EXCAVATE,
    # the original's _plan variants: the same records; the planning server plans around the collision objects of
    # its DB record (collision_object_record_name) and refuses with FAILURE naming the object
    SubtaskSpec("subtask_zx200_change_pose_plan", "zx200", CHANGE_POSE_PLAN, TmsRpZx200ChangePose,
                build_change_pose, change_pose_goal, zx200_ok, clears_lock_flg=True, options=change_pose_options,
                outcome_topic=True),
    SubtaskSpec("subtask_zx200_excavate_simple_plan", "zx200", EXCAVATE_SIMPLE_PLAN, TmsRpZx200ExcavateSimple,
                build_excavate, _excavate_goal, zx200_ok, clears_lock_flg=True, outcome_topic=True),
    _ZX200_RELEASE,
    _design_row("zx200", _ZX200_CHANGE_POSE, _ZX200_EXCAVATE, _ZX200_RELEASE),  # ours: to a stored design
    *travel_rows("ic120"),
    SubtaskSpec("st_ic120_release_soil", "ic120", "set_dump_angle", SetDumpAngle,
                build_dump, lambda plan: SetDumpAngle.Goal(target_angle=plan.target_angle), dump_ok),
    *travel_rows("zx200"), *_sample_rows("zx200"),
    *travel_rows("zx120"), *_sample_rows("zx120"),  # the original has the ZX120's sample subtasks only
    *travel_rows("mst2200"), *_swing_rows("mst2200"),
    *travel_rows("mst110cr"), *_swing_rows("mst110cr"),
    *travel_rows("d37pxi"),  # the original builds the D37PXi's travel subtasks only (no blade, no release)
]
SUBTASKS: dict[str, SubtaskSpec] = {s.name: s for s in _SPECS}

#: machine kind -> the name patterns (fnmatch) of the rows a machine of that kind serves
KIND_SUBTASKS: dict[str, tuple[str, ...]] = {
    "zx200": ("subtask_zx200_*", "st_zx200_*"),
    "zx120": ("st_zx120_*",),
    "ic120": ("st_ic120_*",),
    "mst110cr": ("st_mst110cr_*",),
    "mst2200vd": ("st_mst2200_*", "st_ic120_release_soil"),  # the original's trees send that name to /mst2200
    "d37pxi": ("st_d37pxi_*",),
}


def subtasks_for(kind: str) -> list[SubtaskSpec]:
    """Every subtask a machine of ``kind`` serves (``KIND_SUBTASKS``); ConfigError naming the known kinds."""
    patterns = KIND_SUBTASKS.get(kind)
    if patterns is None:
        raise ConfigError(f"unknown machine kind {kind!r}: expected one of {', '.join(sorted(KIND_SUBTASKS))}")
    return [s for s in _SPECS if any(fnmatchcase(s.name, p) for p in patterns)]
