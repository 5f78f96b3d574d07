"""Skid-steer undercarriage with track dynamics and slip.

Each track speed follows its command through the same dead time + first-order lag as the front
joints (clamped to ``max_speed``). The ground does not follow the tracks exactly: the body moves at
``(vl + vr) / 2 * (1 - slip)`` and turns at ``(vr - vl) / gauge * (1 - yaw_slip)``. Track odometry
(what the machine reports) integrates the *track* speeds, so it drifts from the truth the way a real
crawler's does.
"""

from __future__ import annotations

import math

from sim_bridge.hydraulics import DeadTimeLag
from tms_model.machines import TrackDrive, Tracks

__all__ = ["SkidSteer", "centre_to_tracks"]


def centre_to_tracks(v: float, yaw_rate: float, gauge: float, max_yaw_rate: float) -> tuple[float, float]:
    """Centre velocity and yaw rate -> (left, right) track speeds, yaw rate clamped to ``max_yaw_rate``."""
    w = max(-max_yaw_rate, min(max_yaw_rate, yaw_rate))
    return v - w * gauge / 2.0, v + w * gauge / 2.0


class SkidSteer:
    """Planar pose (x, y, yaw) of a tracked base driven by left/right track speed commands."""

    def __init__(self, tracks: Tracks, drive: TrackDrive, dt: float, pose: tuple[float, float, float]) -> None:
        """``tracks`` (gauge, speed limit) and ``drive`` (travel hydraulics, slip) as the machine description has
        them."""
        self.tracks = tracks
        self.drive = drive
        self.dt = dt
        self.left = DeadTimeLag(drive.dead_time, drive.time_constant, tracks.max_speed, dt)
        self.right = DeadTimeLag(drive.dead_time, drive.time_constant, tracks.max_speed, dt)
        self.command = [0.0, 0.0]  # left, right [m/s]
        self.x, self.y, self.yaw = pose
        self.v = 0.0  # true ground speed [m/s]
        self.w = 0.0  # true yaw rate [rad/s]
        self.vl = 0.0  # measured track speeds [m/s]
        self.vr = 0.0
        self.cut_alpha: float | None = None  # pilot cut off: per-step decay factor of the track speeds

    def set_cutoff(self, time_constant: float | None) -> None:
        """Engage (travel spools centring + motor brake time constant [s]) or release (None) the pilot cut-off."""
        if time_constant is None:
            self.cut_alpha = None
            return
        self.left.vent()
        self.right.vent()
        self.rest()
        self.cut_alpha = 1.0 if time_constant <= 0 else 1.0 - math.exp(-self.dt / time_constant)

    def step(self) -> None:
        d = self.drive
        if self.cut_alpha is not None:
            self.vl = self.left.step_vented(self.cut_alpha)
            self.vr = self.right.step_vented(self.cut_alpha)
        else:
            self.vl = self.left.step(self.command[0])
            self.vr = self.right.step(self.command[1])
        self.v = 0.5 * (self.vl + self.vr) * (1.0 - d.slip)
        self.w = (self.vr - self.vl) / self.tracks.gauge * (1.0 - d.yaw_slip)
        yaw_mid = self.yaw + 0.5 * self.w * self.dt
        self.x += self.v * math.cos(yaw_mid) * self.dt
        self.y += self.v * math.sin(yaw_mid) * self.dt
        self.yaw = math.atan2(math.sin(self.yaw + self.w * self.dt), math.cos(self.yaw + self.w * self.dt))

    def rest(self) -> None:
        self.command[0] = self.command[1] = 0.0

    def at_rest(self, tol: float = 1e-3) -> bool:
        return abs(self.vl) < tol and abs(self.vr) < tol
