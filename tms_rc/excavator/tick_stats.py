"""Timing of one goal: how regular the control ticks were, how old the measurement was, where the time went.

The arm controller node logs :meth:`TickStats.summary` and :meth:`SegmentSpans.summary` with each goal's
result, so a goal that took longer in the running stack than in-process (``python -m tests.bench load_pass``)
can be told apart from a late control loop (CPU starvation on a loaded host) or a stale ``joint_states``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SegmentSpans", "TickStats"]


@dataclass
class TickStats:
    """Tick gaps and measurement ages over one goal, in ROS-clock seconds (simulated time in the launches).

    Args:
        period: the nominal control period [s].
        late_factor: a gap longer than this many periods counts as a late tick.
    """

    period: float
    late_factor: float = 1.5
    ticks: int = 0
    late: int = 0
    max_gap: float = 0.0
    max_age: float = 0.0
    age_sum: float = 0.0
    _last: float | None = None

    def __post_init__(self) -> None:
        if not self.period > 0:
            raise ValueError(f"TickStats: period must be > 0 s, got {self.period}")

    def tick(self, now: float, measured_at: float | None) -> None:
        """One control tick at ``now``, using a measurement stamped ``measured_at`` (None: no stamp)."""
        if self._last is not None:
            gap = now - self._last
            self.max_gap = max(self.max_gap, gap)
            if gap > self.late_factor * self.period:
                self.late += 1
        self._last = now
        self.ticks += 1
        if measured_at is not None:
            age = max(0.0, now - measured_at)
            self.max_age = max(self.max_age, age)
            self.age_sum += age

    def summary(self) -> str:
        """One line for the goal's log entry."""
        mean_age = self.age_sum / self.ticks if self.ticks else 0.0
        return (f"{self.ticks} ticks, {self.late} late (> {self.late_factor:g} periods apart, longest gap "
                f"{self.max_gap * 1000:.0f} ms), joint_states {mean_age * 1000:.0f} ms old on average, "
                f"at most {self.max_age * 1000:.0f} ms")


@dataclass
class SegmentSpans:
    """The phases of one goal as (label, start) in ROS-clock seconds, in the order the goal saw them."""

    spans: list[tuple[str, float]] = field(default_factory=list)

    def enter(self, label: str, now: float) -> None:
        """The goal is in phase ``label`` at ``now`` (a new span only when the label changes)."""
        if not self.spans or self.spans[-1][0] != label:
            self.spans.append((label, now))

    def summary(self, now: float) -> str:
        """``after X s; segments [s]: a 1.0, b 2.0`` with the goal ending at ``now``; ``at once`` for a goal
        that ended before any tick recorded a phase (a goal to the pose already held can end on its first
        tick, and a preempted one before it). Each span ends where the next begins, the last at ``now``."""
        if not self.spans:
            return "at once"
        ends = [start for _, start in self.spans[1:]] + [now]
        parts = [f"{label} {end - start:.1f}" for (label, start), end in zip(self.spans, ends, strict=True)]
        return f"after {now - self.spans[0][1]:.1f} s; segments [s]: " + ", ".join(parts)
