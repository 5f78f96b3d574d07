"""Cyclic frame scheduler: which command frames are due, each at its DBC cycle time.

Pure and clock-agnostic (times in seconds from any monotonic source). Frames keep their phase
(``next = previous + period``) so the rate does not drift; a frame more than one period late is
sent once and rescheduled from now rather than bursting. A frame sent early because a new command
arrived (:meth:`FrameScheduler.sent`) restarts its period, so event-triggered sends never double the rate.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["FrameScheduler"]


class FrameScheduler:
    """Due times of cyclic frames.

    Args:
        periods_s: frame name -> period [s] (> 0).
        start: time of the first emission of every frame.
    """

    def __init__(self, periods_s: Mapping[str, float], start: float) -> None:
        for name, period in periods_s.items():
            if not period > 0:
                raise ValueError(f"frame {name}: period must be > 0 s, got {period}")
        self._period = dict(periods_s)
        self._next = {name: start for name in periods_s}

    def due(self, now: float) -> list[str]:
        """Frames due at ``now`` (each at most once), in declaration order; advances their schedule."""
        out = []
        for name, when in self._next.items():
            if when <= now:
                out.append(name)
                period = self._period[name]
                nxt = when + period
                self._next[name] = nxt if nxt > now else now + period
        return out

    def sent(self, name: str, now: float) -> None:
        """Record an out-of-cycle send of ``name`` at ``now``: its next cyclic send is one period later."""
        self._next[name] = now + self._period[name]

    def next_due(self) -> float:
        """Earliest due time of any frame."""
        return min(self._next.values())
