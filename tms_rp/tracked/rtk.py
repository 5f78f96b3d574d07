"""A machine whose converter already gives its pose in the map frame (RTK GNSS at the swing centre).

The COM3 excavator (ZX200, ZX120) reports ``Swing_Center_Position`` (RTK GNSS, plane coordinates) and the
track body's azimuth; com3_can's excavator profile forwards them as ``odom_pose`` in frame ``map``. There is
nothing to fuse: :class:`GlobalPoseRelay` passes the pose through and adds what the navigator also needs and
the frames do not carry, the body velocity (forward speed and yaw rate), as the least-squares slope of the
poses of the last ``window_s`` (a 1 s window at 50-100 Hz of 1 cm RTK noise gives a few mm/s of noise, well
below the navigator's 0.02 m/s rest threshold). Pure Python, no rclpy.
"""

from __future__ import annotations

import math
from collections import deque

from tms_model.geometry import wrap_angle

__all__ = ["GlobalPoseRelay"]


class GlobalPoseRelay:
    """``update(t, x, y, yaw) -> (v, yaw_rate)``: the body velocity over the last ``window_s`` seconds."""

    def __init__(self, window_s: float = 1.0) -> None:
        if not window_s > 0:
            raise ValueError(f"window_s must be > 0, got {window_s!r}")
        self.window_s = window_s
        self._hist: deque[tuple[float, float, float, float]] = deque()  # t, x, y, unwrapped yaw

    def update(self, t: float, x: float, y: float, yaw: float) -> tuple[float, float]:
        if not all(math.isfinite(v) for v in (t, x, y, yaw)):
            raise ValueError(f"pose not finite: t={t}, x={x}, y={y}, yaw={yaw}")
        if self._hist and t < self._hist[-1][0]:
            self._hist.clear()  # time went back (a restarted clock): start again
        if self._hist:
            yaw = self._hist[-1][3] + wrap_angle(yaw - self._hist[-1][3])
        self._hist.append((t, x, y, yaw))
        while self._hist and t - self._hist[0][0] > self.window_s:
            self._hist.popleft()
        n = len(self._hist)
        if n < 3:
            return 0.0, 0.0
        ts = [h[0] for h in self._hist]
        tm = sum(ts) / n
        den = sum((ti - tm) ** 2 for ti in ts)
        if den < 1e-9:
            return 0.0, 0.0

        def slope(k: int) -> float:
            vals = [h[k] for h in self._hist]
            vm = sum(vals) / n
            return sum((ti - tm) * (vi - vm) for ti, vi in zip(ts, vals, strict=True)) / den

        vx, vy, w = slope(1), slope(2), slope(3)
        return vx * math.cos(yaw) + vy * math.sin(yaw), w
