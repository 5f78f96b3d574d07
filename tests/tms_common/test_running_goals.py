"""tms_common.goals.RunningGoals: what a node's stop hook answers while its goals wind down."""

from __future__ import annotations

import time

from tms_common.goals import RunningGoals


def test_wind_down_holds_the_stop_while_a_goal_runs_and_reports_once():
    goals = RunningGoals()
    reported: list[int] = []
    assert not goals.stopping.is_set()
    with goals.running(), goals.running():
        assert goals.wind_down(10.0, reported.append) is True
        assert goals.stopping.is_set()
        assert goals.wind_down(10.0, reported.append) is True
    assert reported == [2], "the running goals are reported on the first request only"
    assert goals.wind_down(10.0, reported.append) is False, "no goal left: the node may stop"


def test_wind_down_gives_up_at_the_deadline_of_the_first_request():
    goals = RunningGoals()
    with goals.running():
        assert goals.wind_down(0.05) is True
        time.sleep(0.08)
        assert goals.wind_down(10.0) is False, "a later call does not extend the first request's deadline"


def test_no_report_and_no_wait_without_running_goals():
    goals = RunningGoals()
    reported: list[int] = []
    assert goals.wind_down(10.0, reported.append) is False
    assert reported == [] and goals.stopping.is_set()


def test_a_goal_that_raises_is_no_longer_counted():
    goals = RunningGoals()
    try:
        with goals.running():
            raise ValueError("execute callback failed")
    except ValueError:
        pass
    assert goals.wind_down(10.0) is False
