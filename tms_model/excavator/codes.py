"""Result codes and errors of excavator arm motion: each error carries the value an action result reports in
its ``error_code.val`` (tms_msg_rp/TmsRpErrorCodes).

A goal is rejected *before* motion with one of these; the message names the culprit (which joint and
its limit, which distance and the reachable range, which field is NaN or empty).
"""

from __future__ import annotations

from tms_common.errors import TmsError

# SUCCESS / FAILURE are tms_msg_rp/TmsRpErrorCodes' (the original's); the others mirror the finer classes of
# tms_msg/msg/Zx200PlanningOutcome.msg (plain ints so the pure core needs no rclpy).
SUCCESS = 1
FAILURE = 99999
INVALID_GOAL = 2
OUT_OF_REACH = 3
JOINT_LIMIT = 4
CANCELED = 5
TIMEOUT = 6
NO_VALID_CONTROL = 7


class PlanningError(TmsError):
    """A goal cannot be planned; ``code`` is the value for the action result's ``error_code.val``."""

    code = FAILURE


class InvalidGoalError(PlanningError, ValueError):
    """NaN, infinite, empty or malformed goal."""

    code = INVALID_GOAL


class OutOfReachError(PlanningError):
    """The target lies outside the arm's workspace (message gives the distance and the range)."""

    code = OUT_OF_REACH


class JointLimitError(PlanningError):
    """The target needs a joint outside its position limits (message names the joint and limit)."""

    code = JOINT_LIMIT
