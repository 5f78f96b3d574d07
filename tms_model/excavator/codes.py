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
#: no code at all: the value of a result nobody filled in (rclpy ends a goal whose execute callback raised
#: ABORTED with such an empty result); not a class of its own, and never reported as one
NO_CODE = 0


def reported(succeeded: bool, code: int, message: str, status: str = "ABORTED") -> tuple[int, str]:
    """The (code, message) to report for a goal that ended ``status`` with ``code`` and ``message`` in its result.

    SUCCESS only when the goal SUCCEEDED and its result says SUCCESS. Otherwise a failure code: the result's
    own when it carries one; FAILURE when it carries SUCCESS or :data:`NO_CODE` (the goal aborted without a
    result, or succeeded without a code), with a message naming what happened, so no failure goes on with
    the success code (or none).
    """
    if code == SUCCESS and succeeded:
        return code, message
    if code not in (SUCCESS, NO_CODE):
        return code, message
    if succeeded:
        what = f"goal {status} without a result code (error_code {code})"
    elif code == NO_CODE and not message:
        what = f"goal {status} without a result"
    else:
        what = f"goal {status} although its result says {'SUCCESS' if code == SUCCESS else f'error_code {code}'}"
    return FAILURE, f"{what}: {message}" if message else what


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
