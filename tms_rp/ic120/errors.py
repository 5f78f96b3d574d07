"""Errors of IC120 planning, each carrying the Nav2 action ``error_code`` it maps to.

The navigator node turns any :class:`NavError` into an aborted action result with ``error_code`` =
``exc.code`` and ``error_msg`` = ``str(exc)`` through one table (no per-class catch ladder).
"""

from __future__ import annotations

from tms_common.errors import TmsError

# Nav2 NavigateToPose / NavigateThroughPoses result codes (tms_msg/action/NavigateToPose.action).
UNKNOWN = 9000
TIMEOUT = 9002
GOAL_OCCUPIED = 9003
NO_VALID_PATH = 9004
INVALID_GOAL = 9005
CANCELED = 9006


class NavError(TmsError):
    """Base of navigation failures; ``code`` is the Nav2 result error code."""

    code = UNKNOWN


class InvalidGoalError(NavError, ValueError):
    """A goal pose is malformed (NaN, zero quaternion, outside the map, wrong frame)."""

    code = INVALID_GOAL


class GoalOccupiedError(NavError):
    """The goal (or the start) lies in an obstacle or its inflated footprint."""

    code = GOAL_OCCUPIED


class NoValidPathError(NavError):
    """No collision-free path connects start and goal (or the path got blocked and replanning failed)."""

    code = NO_VALID_PATH


class NavTimeoutError(NavError):
    """The machine made no progress for too long."""

    code = TIMEOUT


class LocalizationError(NavError):
    """No pose estimate is available (no GNSS fix yet, or the estimate is too old)."""

    code = UNKNOWN
