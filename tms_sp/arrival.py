"""The arrival processor: SENSING_ARRIVAL_FLG from the measured pose of the sensed carrier.

The flag rises when the carrier has stood within ``position_tolerance`` and ``yaw_tolerance`` of the
loading point, slower than ``max_speed``, for ``hold_s`` seconds of (simulated) time; it falls as
soon as any of these stops holding. The speed is the displacement over the last ``speed_window_s``
(not between two consecutive poses): at a 50 Hz pose rate a millimetre of contact jitter of a
standing machine would read as 0.05 m/s and make the flag flicker. Time is injected (``update(t, pose)``), so the same
core runs
on ``/clock`` time, wall time, or in a test.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from tms_model.geometry import Pose2D, wrap_angle

__all__ = ["ArrivalParams", "ArrivalDetector"]


@dataclass(frozen=True)
class ArrivalParams:
    """Parameters of :class:`ArrivalDetector` (config/tms_sp/sensing.yaml ``arrival``)."""

    position_tolerance: float = 0.6
    yaw_tolerance: float = math.radians(10.0)
    max_speed: float = 0.05
    hold_s: float = 1.0
    speed_window_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("position_tolerance", "yaw_tolerance", "max_speed", "hold_s", "speed_window_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"ArrivalParams: {name} must be >= 0, got {getattr(self, name)}")


@dataclass
class ArrivalDetector:
    """Stateful arrival check against one target pose."""

    target: Pose2D
    params: ArrivalParams = field(default_factory=ArrivalParams)
    _history: deque = field(default_factory=deque)  # (t, pose), oldest first, spanning speed_window_s
    _since: float | None = None
    speed: float = 0.0
    distance: float = math.inf

    def update(self, t: float, pose: Pose2D) -> bool:
        """Feed one pose measured at time ``t`` [s]; returns the current flag value."""
        history = self._history
        if history and t < history[-1][0]:
            self._since = None  # time jumped back (sim reset): start over
            history.clear()
        if history and t == history[-1][0]:
            history.pop()  # same stamp twice: keep the newer pose
        history.append((t, pose))
        # drop samples older than the window, keeping one at or beyond it as the reference
        while len(history) > 2 and t - history[1][0] >= self.params.speed_window_s:
            history.popleft()
        t0, p0 = history[0]
        if t > t0:
            self.speed = math.hypot(pose.x - p0.x, pose.y - p0.y) / (t - t0)
        window_full = t - t0 >= self.params.speed_window_s - 1e-9
        self.distance = math.hypot(pose.x - self.target.x, pose.y - self.target.y)
        yaw_err = abs(wrap_angle(pose.yaw - self.target.yaw))
        inside = (
            window_full
            and self.distance <= self.params.position_tolerance
            and yaw_err <= self.params.yaw_tolerance
            and self.speed <= self.params.max_speed
        )
        if not inside:
            self._since = None
            return False
        if self._since is None:
            self._since = t
        return t - self._since >= self.params.hold_s
