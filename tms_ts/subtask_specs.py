"""Every subtask as one row: record -> planning goal data, downstream action and its result check.

``SUBTASKS`` maps a subtask action name (served at ``/<model_name>/<name>``) to a :class:`SubtaskSpec`,
the one place a subtask is defined: its machine family, its planning action (relative to the machine
namespace) and that action's type, ``build(doc, record_name) -> dict`` that validates the record and
returns the planning goal as plain data, ``goal(plan) -> <action>.Goal``, ``options(plan)`` for what a goal
needs beyond the planning type (ZX200 change_pose: tms_msg/srv/Zx200ChangePoseOptions) and ``check(result)
-> (ok, detail)`` that reads the planning result's own typed code. The ZX200 rows speak the original's
tms_msg_rp actions (:mod:`tms_if_opera.interface`). A missing or malformed field raises
:class:`SubtaskRecordError` naming the record and the field. Adding a subtask is adding a row.

Planning goal data (``kind`` -> keys):

* ``change_pose``: ``mode`` joints|pose|position_with_angle and ``joints`` {name: rad} | ``pose``
  {x..qw} | ``pwa`` {x, y, z, theta_w}; ``pass_through`` (the record's optional 0/1 field: end at the
  target without waiting for rest, the next goal continues the motion); ``theta_w_tolerance`` (optional
  [rad], default 0: the nearest holdable edge angle within it where theta_w cannot be held)
* ``excavate``: ``pwa`` {x, y, z, theta_w, offset}; ``release``/``dump``: ``target_angle``
* ``navigate_to_pose``: ``pose`` {x, y, z, qx..qw}; ``follow_waypoints`` / ``navigate_through_poses``:
  ``poses`` [{x, y, z, qx..qw}, ...] in frame ``map``. ``_deg`` variants give yaw in degrees.

Imports message types only (no rclpy).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import Point, Pose, PoseStamped
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from com3_msgs.action import SetDumpAngle
from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from tms_if_opera.interface import (
    CHANGE_POSE,
    CHANGE_POSE_PLAN,
    EXCAVATE_SIMPLE,
    EXCAVATE_SIMPLE_PLAN,
    RELEASE_SIMPLE,
)
from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple
from tms_msg_rp.msg import TmsRpErrorCodes, TmsRpZx200PositionWithAngle
from tms_ts.errors import SubtaskRecordError

__all__ = ["SubtaskSpec", "SUBTASKS", "subtasks_for", "ZX200_JOINTS", "change_pose_goal", "change_pose_options",
           "zx200_ok", "nav2_ok", "dump_ok"]

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


def build_change_pose(doc: dict, record: str) -> dict:
    out = _change_pose_target(doc, record)
    out["pass_through"] = _bool(doc, record, "pass_through")
    tolerance = _num(doc, record, "theta_w_tolerance", 0.0)
    if tolerance < 0:
        raise SubtaskRecordError(record, "theta_w_tolerance", f"must be >= 0 rad, got {tolerance}")
    if tolerance > 0 and out["mode"] == "joints":
        raise SubtaskRecordError(record, "theta_w_tolerance", "applies to pose / position_with_angle targets, not joints")
    out["theta_w_tolerance"] = tolerance
    return out


def _change_pose_target(doc: dict, record: str) -> dict:
    if _flag(doc, "trajectory"):
        return {"kind": "change_pose", "mode": "joints", "joints": {j: _num(doc, record, j) for j in ZX200_JOINTS}}
    if _flag(doc, "pose"):
        pose = {k: _num(doc, record, k) for k in ("x", "y", "z")}
        pose.update(_unit_quat(record, {k: _num(doc, record, k) for k in _QUAT}))
        return {"kind": "change_pose", "mode": "pose", "pose": pose}
    if _flag(doc, "position_with_angle"):
        return {"kind": "change_pose", "mode": "position_with_angle",
                "pwa": {k: _num(doc, record, k) for k in ("x", "y", "z", "theta_w")}}
    raise SubtaskRecordError(record, "trajectory|pose|position_with_angle", "no target kind selected (one must be 1)")


def build_excavate(doc: dict, record: str) -> dict:
    if not _flag(doc, "position_with_angle"):
        raise SubtaskRecordError(record, "position_with_angle", "must be 1 for an excavation target")
    pwa = {k: _num(doc, record, k) for k in ("x", "y", "z", "theta_w")}
    pwa["offset"] = _num(doc, record, "offset", 0.0)
    return {"kind": "excavate", "pwa": pwa}


def build_release(doc: dict, record: str) -> dict:
    return {"kind": "release", "target_angle": _num(doc, record, "target_angle")}


def build_dump(doc: dict, record: str) -> dict:
    return {"kind": "dump", "target_angle": _num(doc, record, "target_angle")}


def build_nav_pose(deg: bool) -> Callable[[dict, str], dict]:
    def build(doc: dict, record: str) -> dict:
        pose = {"x": _num(doc, record, "x"), "y": _num(doc, record, "y"), "z": _num(doc, record, "z", 0.0)}
        if deg:
            pose.update(_yaw_quat(_num(doc, record, "yaw")))
        else:
            pose.update(_unit_quat(record, {k: _num(doc, record, k) for k in _QUAT}))
        return {"kind": "navigate_to_pose", "pose": pose}

    return build


def build_poses(kind: str, deg: bool) -> Callable[[dict, str], dict]:
    def build(doc: dict, record: str) -> dict:
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
        return {"kind": kind, "poses": poses}

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


def change_pose_goal(plan: dict) -> TmsRpZx200ChangePose.Goal:
    """The original's goal: exactly one of trajectory / pose_sequence / position_with_angle_sequence."""
    goal = TmsRpZx200ChangePose.Goal()
    if plan["mode"] == "joints":
        goal.trajectory = JointTrajectory(joint_names=list(plan["joints"]))
        goal.trajectory.points = [JointTrajectoryPoint(positions=list(plan["joints"].values()))]
    elif plan["mode"] == "pose":
        goal.pose_sequence = [_pose(plan["pose"])]
    else:
        goal.position_with_angle_sequence = [_pwa(plan["pwa"])]
    return goal


def change_pose_options(plan: dict) -> dict | None:
    """What the goal needs beyond the original's type (tms_msg/srv/Zx200ChangePoseOptions fields), or None
    when it needs nothing beyond it (then no options are sent and a planner without them serves it too)."""
    options = {"pass_through": bool(plan.get("pass_through", False)),
               "theta_w_tolerance": float(plan.get("theta_w_tolerance", 0.0))}
    return options if options["pass_through"] or options["theta_w_tolerance"] > 0 else None


def _poses_goal(action_type):  # noqa: ANN001, ANN202
    return lambda plan: action_type.Goal(poses=[_stamped(p) for p in plan["poses"]])


# planning results -> (ok, detail for people) ---------------------------------------------------------
def zx200_ok(result) -> tuple[bool, str]:  # noqa: ANN001 - a TmsRpZx200* action result
    """tms_msg_rp/TmsRpErrorCodes: SUCCESS or a failure code (the text comes from the planning outcome topic)."""
    return result.error_code.val == TmsRpErrorCodes.SUCCESS, f"error_code {result.error_code.val}"


def nav2_ok(result) -> tuple[bool, str]:  # noqa: ANN001 - a Nav2-shaped action result
    """Nav2 ``error_code``: NONE (0) or a failure code."""
    return result.error_code == 0, f"error_code {result.error_code}: {result.error_msg}"


def dump_ok(result) -> tuple[bool, str]:  # noqa: ANN001 - com3_msgs SetDumpAngle.Result
    """com3_msgs SetDumpAngle: the ``success`` flag (the peer's result carries no reason; the server logs it)."""
    return bool(result.success), "" if result.success else "success false (the set_dump_angle server's log says why)"


@dataclass(frozen=True)
class SubtaskSpec:
    """One subtask: machine family, downstream planning action, record -> goal, result check."""

    name: str
    machine: str
    planning_action: str  # relative to /<model_name>
    action_type: Any  # the planning action's type, e.g. tms_msg_rp.action.TmsRpZx200ChangePose
    build: Callable[[dict, str], dict]
    goal: Callable[[dict], Any]
    check: Callable[[Any], tuple[bool, str]]
    #: the original non-plan ZX200 change_pose / excavate_simple set LOCK_FLG=false when a result arrives
    clears_lock_flg: bool = False
    #: plan -> the goal's options beyond the planning type (None: none needed), sent to ``<planning>/options``
    options: Callable[[dict], dict | None] | None = None
    #: the planning server publishes each goal's outcome text on /<model_name>/tms_rp_zx200_outcome
    zx200_planning: bool = False


def _excavate_goal(plan: dict) -> TmsRpZx200ExcavateSimple.Goal:
    return TmsRpZx200ExcavateSimple.Goal(position_with_angle=_pwa(plan["pwa"]))


def _nav_pose_goal(plan: dict) -> NavigateToPose.Goal:
    return NavigateToPose.Goal(pose=_stamped(plan["pose"]))


_FW, _NTP = _poses_goal(FollowWaypoints), _poses_goal(NavigateThroughPoses)
_SPECS = [
    SubtaskSpec("subtask_zx200_change_pose", "zx200", CHANGE_POSE, TmsRpZx200ChangePose,
                build_change_pose, change_pose_goal, zx200_ok, clears_lock_flg=True, options=change_pose_options,
                zx200_planning=True),
    SubtaskSpec("subtask_zx200_excavate_simple", "zx200", EXCAVATE_SIMPLE, TmsRpZx200ExcavateSimple,
                build_excavate, _excavate_goal, zx200_ok, clears_lock_flg=True, zx200_planning=True),
    # the original's _plan variants: the same records; the planning server plans around the collision objects of
    # its DB record (collision_object_record_name) and refuses with FAILURE naming the object
    SubtaskSpec("subtask_zx200_change_pose_plan", "zx200", CHANGE_POSE_PLAN, TmsRpZx200ChangePose,
                build_change_pose, change_pose_goal, zx200_ok, clears_lock_flg=True, options=change_pose_options,
                zx200_planning=True),
    SubtaskSpec("subtask_zx200_excavate_simple_plan", "zx200", EXCAVATE_SIMPLE_PLAN, TmsRpZx200ExcavateSimple,
                build_excavate, _excavate_goal, zx200_ok, clears_lock_flg=True, zx200_planning=True),
    SubtaskSpec("subtask_zx200_release_simple", "zx200", RELEASE_SIMPLE, TmsRpZx200ReleaseSimple,
                build_release, lambda plan: TmsRpZx200ReleaseSimple.Goal(target_angle=plan["target_angle"]), zx200_ok,
                zx200_planning=True),
    SubtaskSpec("st_ic120_follow_waypoints", "ic120", "follow_waypoints", FollowWaypoints,
                build_poses("follow_waypoints", False), _FW, nav2_ok),
    SubtaskSpec("st_ic120_follow_waypoints_deg", "ic120", "follow_waypoints", FollowWaypoints,
                build_poses("follow_waypoints", True), _FW, nav2_ok),
    SubtaskSpec("st_ic120_navigate_anywhere", "ic120", "navigate_to_pose", NavigateToPose,
                build_nav_pose(False), _nav_pose_goal, nav2_ok),
    SubtaskSpec("st_ic120_navigate_anywhere_deg", "ic120", "navigate_to_pose", NavigateToPose,
                build_nav_pose(True), _nav_pose_goal, nav2_ok),
    SubtaskSpec("st_ic120_navigate_through_poses", "ic120", "navigate_through_poses", NavigateThroughPoses,
                build_poses("navigate_through_poses", False), _NTP, nav2_ok),
    SubtaskSpec("st_ic120_navigate_through_poses_deg", "ic120", "navigate_through_poses", NavigateThroughPoses,
                build_poses("navigate_through_poses", True), _NTP, nav2_ok),
    SubtaskSpec("st_ic120_release_soil", "ic120", "set_dump_angle", SetDumpAngle,
                build_dump, lambda plan: SetDumpAngle.Goal(target_angle=plan["target_angle"]), dump_ok),
]
SUBTASKS: dict[str, SubtaskSpec] = {s.name: s for s in _SPECS}


def subtasks_for(machine: str) -> list[SubtaskSpec]:
    """Every subtask of a machine family (``zx200`` or ``ic120``); ValueError naming the valid ones."""
    specs = [s for s in _SPECS if s.machine == machine]
    if not specs:
        valid = sorted({s.machine for s in _SPECS})
        raise ValueError(f"unknown machine {machine!r}: expected one of {', '.join(valid)}")
    return specs
