"""Names of the subtask -> ZX200 planning boundary, defined once (imports nothing from ROS).

The actions are the original's (irvs/ros2_tms_for_construction, ``tms_msg_rp``), relative to the machine
namespace ``/<model_name>``; what our subtasks need beyond them goes beside, under our own names:

* ``<change_pose>/options`` (tms_msg/srv/Zx200ChangePoseOptions): a change_pose goal's ``pass_through``
  and ``theta_w_tolerance``, given by goal id before the goal is sent; a goal without options runs with
  the defaults, as the original's goals do.
* ``tms_rp_zx200_outcome`` (tms_msg/msg/Zx200PlanningOutcome): every goal's code and message for people,
  published just before the goal ends (the original's result carries the code only).
"""

from __future__ import annotations

__all__ = [
    "PLANNER_NODE",
    "CHANGE_POSE",
    "EXCAVATE_SIMPLE",
    "RELEASE_SIMPLE",
    "CHANGE_POSE_OPTIONS",
    "PLANNING_OUTCOME",
    "OUTCOME_GRACE_S",
    "OPTIONS_TTL_S",
    "CHANGE_POSE_PLAN",
    "EXCAVATE_SIMPLE_PLAN",
    "CHANGE_POSE_PLAN_OPTIONS",
]

#: the planning node's name (zx200_planner), in the machine's namespace beside the arm controller
PLANNER_NODE = "zx200_planner"
CHANGE_POSE = "tms_rp_zx200_change_pose"          # tms_msg_rp/action/TmsRpZx200ChangePose
EXCAVATE_SIMPLE = "tms_rp_zx200_excavate_simple"  # tms_msg_rp/action/TmsRpZx200ExcavateSimple
RELEASE_SIMPLE = "tms_rp_zx200_release_simple"    # tms_msg_rp/action/TmsRpZx200ReleaseSimple
CHANGE_POSE_OPTIONS = f"{CHANGE_POSE}/options"     # tms_msg/srv/Zx200ChangePoseOptions
# the original's collision-aware variants (tms_if_for_opera zx200_*_plan_action_server), same types
CHANGE_POSE_PLAN = "tms_rp_zx200_change_pose_plan"          # tms_msg_rp/action/TmsRpZx200ChangePose
EXCAVATE_SIMPLE_PLAN = "tms_rp_zx200_excavate_simple_plan"  # tms_msg_rp/action/TmsRpZx200ExcavateSimple
CHANGE_POSE_PLAN_OPTIONS = f"{CHANGE_POSE_PLAN}/options"     # tms_msg/srv/Zx200ChangePoseOptions
PLANNING_OUTCOME = "tms_rp_zx200_outcome"          # tms_msg/msg/Zx200PlanningOutcome
#: [s wall] a client that has a failed result waits at most this long for the goal's outcome message
#: (topic and result service are separate DDS channels: either may arrive first)
OUTCOME_GRACE_S = 1.0
#: [s wall] options not claimed by a goal within this are dropped (the client gave up before sending)
OPTIONS_TTL_S = 30.0
