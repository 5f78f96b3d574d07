"""tms_model.excavator.codes.reported: a goal that did not succeed never reports SUCCESS or no code (no ROS)."""

from __future__ import annotations

from tms_model.excavator import codes


def test_success_only_when_the_goal_succeeded_with_the_success_code():
    assert codes.reported(True, codes.SUCCESS, "reached") == (codes.SUCCESS, "reached")


def test_a_failure_code_is_kept_whatever_the_status():
    assert codes.reported(False, codes.TIMEOUT, "segment 1 not reached") == (codes.TIMEOUT, "segment 1 not reached")
    # a SUCCEEDED status does not turn a failure code into a success
    assert codes.reported(True, codes.JOINT_LIMIT, "boom") == (codes.JOINT_LIMIT, "boom")


def test_an_aborted_goal_without_a_result_is_a_failure_naming_it():
    # rclpy's empty result after an execute callback raised: error_code 0, no message
    assert codes.reported(False, codes.NO_CODE, "", "ABORTED at the arm controller") == (
        codes.FAILURE, "goal ABORTED at the arm controller without a result")


def test_an_aborted_goal_whose_result_says_success_is_a_failure_naming_it():
    code, message = codes.reported(False, codes.SUCCESS, "reached", "ABORTED")
    assert code == codes.FAILURE
    assert message == "goal ABORTED although its result says SUCCESS: reached"


def test_a_succeeded_goal_without_a_code_is_a_failure():
    code, message = codes.reported(True, codes.NO_CODE, "")
    assert code == codes.FAILURE and "without a result code (error_code 0)" in message
