"""Errors of tracked-machine navigation, each carrying the Nav2 ``error_code`` a Nav2 (jazzy) navigator reports for it.

The navigator node turns any :class:`NavError` into an aborted action result with ``error_code`` =
``exc.code`` and ``error_msg`` = ``str(exc)`` through one table (no per-class catch ladder).

Nav2 jazzy's ``NavigateToPose`` / ``NavigateThroughPoses`` results define only ``NONE``; a failed navigation
reports the code of the behaviour-tree node that failed: the planner's (``nav2_msgs/action/ComputePathToPose``,
2xx) or the controller's (``nav2_msgs/action/FollowPath``, 1xx). Our failures take those values, so a client
written against Nav2 reads the same codes. ``FollowWaypoints`` has its own (6xx).
"""

from __future__ import annotations

from tms_common.errors import TmsError

NONE = 0
# nav2_msgs/action/ComputePathToPose (jazzy) result codes
PLANNER_UNKNOWN = 200
PLANNER_TF_ERROR = 202
GOAL_OUTSIDE_MAP = 204
GOAL_OCCUPIED = 206
NO_VALID_PATH = 208
# nav2_msgs/action/FollowPath (jazzy) result codes
FAILED_TO_MAKE_PROGRESS = 105
# nav2_msgs/action/FollowWaypoints (jazzy) result codes
WAYPOINTS_UNKNOWN = 600


class NavError(TmsError):
    """Base of navigation failures; ``code`` is the Nav2 result error code."""

    code = PLANNER_UNKNOWN


class InvalidGoalError(NavError, ValueError):
    """A goal pose is malformed (NaN, zero quaternion, wrong frame, no poses)."""

    code = PLANNER_UNKNOWN


class GoalOutsideMapError(InvalidGoalError):
    """A goal pose lies outside the map."""

    code = GOAL_OUTSIDE_MAP


class GoalOccupiedError(NavError):
    """The goal (or the start) lies in an obstacle or its inflated footprint."""

    code = GOAL_OCCUPIED


class NoValidPathError(NavError):
    """No collision-free path connects start and goal (or the path got blocked and replanning failed)."""

    code = NO_VALID_PATH


class NavTimeoutError(NavError):
    """The machine made no progress for too long."""

    code = FAILED_TO_MAKE_PROGRESS


class LocalizationError(NavError):
    """No pose estimate is available (no GNSS fix yet, or the estimate is too old): Nav2 sees no transform."""

    code = PLANNER_TF_ERROR
