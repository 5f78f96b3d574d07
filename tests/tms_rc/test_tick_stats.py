"""TickStats: the control-loop timing the arm controller node logs with each goal (pure, no ROS)."""

from __future__ import annotations

import pytest

from tms_rc.excavator.tick_stats import TickStats


def test_late_ticks_longest_gap_and_measurement_age_are_counted():
    stats = TickStats(0.02)
    # 50 Hz ticks, one 60 ms gap, measurements 20 ms old except one 80 ms old
    times = [0.0, 0.02, 0.04, 0.10, 0.12]
    ages = [0.02, 0.02, 0.08, 0.02, 0.02]
    for t, age in zip(times, ages, strict=True):
        stats.tick(t, t - age)
    assert stats.ticks == 5 and stats.late == 1
    assert stats.max_gap == pytest.approx(0.06) and stats.max_age == pytest.approx(0.08)
    line = stats.summary()
    assert "5 ticks, 1 late" in line and "longest gap 60 ms" in line and "32 ms old on average, at most 80 ms" in line


def test_no_stamp_and_a_bad_period():
    stats = TickStats(0.02)
    stats.tick(1.0, None)
    stats.tick(1.02, None)
    assert stats.late == 0 and stats.max_age == 0.0 and stats.ticks == 2
    with pytest.raises(ValueError, match="period"):
        TickStats(0.0)


def test_segment_spans_of_a_goal_that_ended_before_any_tick_read_at_once():
    from tms_rc.excavator.tick_stats import SegmentSpans

    # a goal to the pose already held can end on its first tick, a preempted one before it: no span recorded
    assert SegmentSpans().summary(12.0) == "at once"


def test_segment_spans_end_where_the_next_begins_and_repeat_labels_extend_a_span():
    from tms_rc.excavator.tick_stats import SegmentSpans

    spans = SegmentSpans()
    for label, t in (("approach", 1.0), ("approach", 1.5), ("penetrate", 3.0), ("stopping", 4.0)):
        spans.enter(label, t)
    assert spans.summary(4.5) == "after 3.5 s; segments [s]: approach 2.0, penetrate 1.0, stopping 0.5"
