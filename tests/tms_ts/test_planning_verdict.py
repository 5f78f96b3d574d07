"""tms_ts.subtask_specs.planning_verdict: the planning goal's status and result read together (no ROS graph).

The subtask server once reported ``PLANNING_FAILED ... error_code 0`` for a planning goal aborted with rclpy's
empty result: the failure went on with a code that means nothing (TmsRpErrorCodes) or success (Nav2's NONE).
"""

from __future__ import annotations

from action_msgs.msg import GoalStatus

from nav2_msgs.action import FollowWaypoints
from tms_msg_rp.action import TmsRpZx200ChangePose
from tms_msg_rp.msg import TmsRpErrorCodes
from tms_ts.subtask_specs import nav2_ok, planning_verdict, zx200_ok

SUCCEEDED, ABORTED, CANCELED = GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_ABORTED, GoalStatus.STATUS_CANCELED


def _zx200(val: int) -> TmsRpZx200ChangePose.Result:
    result = TmsRpZx200ChangePose.Result()
    result.error_code.val = val
    return result


def test_a_succeeded_goal_with_a_success_result_is_ok():
    assert planning_verdict(zx200_ok, _zx200(TmsRpErrorCodes.SUCCESS), SUCCEEDED) == (True, "error_code 1")
    # Nav2's success is NONE (0) with an otherwise empty result: that is a success, not "no result"
    assert planning_verdict(nav2_ok, FollowWaypoints.Result(), SUCCEEDED)[0] is True


def test_an_aborted_goal_with_an_empty_result_is_named_as_such():
    ok, detail = planning_verdict(zx200_ok, TmsRpZx200ChangePose.Result(), ABORTED)
    assert not ok and detail.startswith("planning goal ABORTED without a result"), detail
    ok, detail = planning_verdict(nav2_ok, FollowWaypoints.Result(), ABORTED)
    assert not ok and detail.startswith("planning goal ABORTED without a result"), detail


def test_an_aborted_goal_whose_result_reads_as_success_fails():
    ok, detail = planning_verdict(zx200_ok, _zx200(TmsRpErrorCodes.SUCCESS), ABORTED)
    assert not ok and "ABORTED although its result reads as a success" in detail, detail
    ok, detail = planning_verdict(nav2_ok, FollowWaypoints.Result(error_msg="x"), CANCELED)
    assert not ok and "CANCELED although its result reads as a success" in detail, detail


def test_a_failure_code_is_passed_on():
    assert planning_verdict(zx200_ok, _zx200(6), ABORTED) == (False, "error_code 6")
    assert planning_verdict(nav2_ok, FollowWaypoints.Result(error_code=105, error_msg="stuck"), ABORTED) == (
        False, "error_code 105: stuck")
    # a SUCCEEDED status with a failure code in the result is not a success either
    assert planning_verdict(zx200_ok, _zx200(TmsRpErrorCodes.FAILURE), SUCCEEDED)[0] is False
