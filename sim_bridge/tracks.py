"""Skid-steer undercarriage with track dynamics and slip.

Each track speed follows its command through the same dead time + first-order lag as the front
joints (clamped to ``max_speed``). The ground does not follow the tracks exactly: the body moves at
``(vl + vr) / 2 * (1 - slip)`` and turns at ``(vr - vl) / gauge * (1 - yaw_slip)``. Track odometry
(what the machine reports) integrates the *track* speeds, so it drifts from the truth the way a real
crawler's does.

Under a drawbar load (a dozer's blade, set by the plant: :meth:`SkidSteer.set_traction`, ``drawbar``) the tracks
slip more: Janosi and Hanamoto's shear stress-displacement law integrated over a track of uniform pressure (Wong,
"Theory of Ground Vehicles", 4th ed. 2008, ch. 2-3) gives the thrust at slip s as
``F = F_max (1 - K / (s L) (1 - exp(-s L / K)))`` with ``F_max`` the traction limit, K the soil's shear deformation
modulus and L the track's contact length; the load slip is the s where F = the resistance R (s = 1, tracks
spinning on a still machine, from R >= F(1) ~ F_max on). The body moves at ``(vl + vr) / 2 * (1 - slip) * (1 - s)``:
the constant slip is the no-load figure, the load slip comes on top (with R = 0, s = 0 and nothing changes).
"""

from __future__ import annotations

import math

import numpy as np

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
        #: resistance [N] against forward travel (a dozer blade's), set by the plant; acts once traction is set
        self.drawbar = 0.0
        self.load_slip = 0.0  # the slip [0, 1] the last step's drawbar load added
        self._f_max = 0.0  # [N] traction limit; 0: no traction model (the constant slip only)
        self._slip_table: tuple[np.ndarray, np.ndarray] | None = None  # (F / F_max, s), increasing

    def set_traction(self, f_max: float, shear_modulus: float, contact_length: float) -> None:
        """The traction model: limit ``f_max`` [N] (traction coefficient x weight), the soil's shear deformation
        modulus K [m] and the tracks' contact length L [m] (see the module docstring)."""
        if not (f_max > 0.0 and shear_modulus > 0.0 and contact_length > 0.0):
            raise ValueError(f"set_traction: f_max, shear_modulus and contact_length must be > 0, got {f_max!r}, "
                             f"{shear_modulus!r}, {contact_length!r}")
        self._f_max = f_max
        # F / F_max as a function of s, tabulated densely at small slips (where it is steep); exact at the nodes
        s = np.concatenate(([0.0], np.geomspace(1e-6, 1.0, 600)))
        x = s[1:] * contact_length / shear_modulus
        ratio = np.concatenate(([0.0], 1.0 - -np.expm1(-x) / x))
        self._slip_table = (ratio, s)

    def slip_under(self, resistance: float) -> float:
        """The track slip [0, 1] whose thrust carries ``resistance`` [N]: 0 for none (or no traction model), 1 from
        the thrust at full slip on (the tracks spin, the machine stands)."""
        if resistance <= 0.0 or self._slip_table is None:
            return 0.0
        ratio, s = self._slip_table
        return float(np.interp(resistance / self._f_max, ratio, s))  # beyond the last node: s = 1

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
        # the drawbar load resists forward travel only (a blade backing up pushes nothing)
        self.load_slip = self.slip_under(self.drawbar) if self.v > 0.0 else 0.0
        if self.load_slip > 0.0:
            self.v *= 1.0 - self.load_slip
        self.w = (self.vr - self.vl) / self.tracks.gauge * (1.0 - d.yaw_slip)
        yaw_mid = self.yaw + 0.5 * self.w * self.dt
        self.x += self.v * math.cos(yaw_mid) * self.dt
        self.y += self.v * math.sin(yaw_mid) * self.dt
        self.yaw = math.atan2(math.sin(self.yaw + self.w * self.dt), math.cos(self.yaw + self.w * self.dt))

    def rest(self) -> None:
        self.command[0] = self.command[1] = 0.0

    def at_rest(self, tol: float = 1e-3) -> bool:
        return abs(self.vl) < tol and abs(self.vr) < tol
