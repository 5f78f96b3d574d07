"""Vessel (dump body) angle control of the IC120, pure Python.

The COM3 carrier frame carries a *target vessel angle* (``rot_dump_cmd`` ``dump_joint`` position: 0 = lowered, + = raised);
the machine's own hydraulics move the vessel there. This controller validates the target against the
machine limit, keeps sending it, watches the measured angle (``joint_states`` ``vessel_joint``) and decides
success (inside ``tolerance`` for ``settle_time``), timeout (``|delta| / vessel.velocity + timeout_margin``)
or, on cancel, holds the vessel where it is and reports once it has stopped moving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tms_common.errors import TmsError
from tms_model.machines import Vessel

__all__ = ["VesselParams", "VesselController", "VesselError", "VesselStep"]


class VesselError(TmsError, ValueError):
    """A bad target angle (names the value and the allowed range)."""


@dataclass(frozen=True)
class VesselParams:
    """Limits from config/machines/ic120.yaml ``vessel`` + tuning from config/nav/ic120_nav.yaml ``vessel``."""

    max_angle: float = 1.134464
    velocity: float = 0.3
    tolerance: float = math.radians(2.0)
    settle_time: float = 0.3
    timeout_margin: float = 10.0

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"vessel.{name} must be > 0, got {value!r}")

    @classmethod
    def from_config(cls, machine_vessel: Vessel, nav_vessel: dict) -> VesselParams:
        return cls(machine_vessel.max_angle, machine_vessel.velocity,
                   float(nav_vessel["tolerance"]), float(nav_vessel["settle_time"]), float(nav_vessel["timeout_margin"]))


@dataclass
class VesselStep:
    """Command to send (target angle) and the goal status: RUNNING, SUCCEEDED, FAILED, CANCELED."""

    command: float
    status: str
    error: float
    message: str = ""


class VesselController:
    """One target at a time: ``start`` then ``step(measured, velocity, now)`` until not RUNNING."""

    def __init__(self, params: VesselParams) -> None:
        self.params = params
        self.target: float | None = None
        self._inside_since: float | None = None
        self._deadline = 0.0
        self._canceling = False

    def start(self, target: float, measured: float, now: float) -> None:
        """Accept a target [rad]; raises :class:`VesselError` outside [0, max_angle] or not finite."""
        if not math.isfinite(target):
            raise VesselError(f"target_angle {target!r} is not finite")
        if not 0.0 <= target <= self.params.max_angle:
            raise VesselError(
                f"target_angle {target:.4f} rad ({math.degrees(target):.1f} deg) outside [0, {self.params.max_angle:.4f}] rad "
                f"(0 = lowered, + = raised; config/machines/ic120.yaml vessel.max_angle)"
            )
        self.target = target
        self._inside_since = None
        self._canceling = False
        self._deadline = now + abs(target - measured) / self.params.velocity + self.params.timeout_margin

    def cancel(self, measured: float) -> None:
        """Hold the vessel at its current angle (clamped to the limits) and report once it is still."""
        self.target = min(max(measured, 0.0), self.params.max_angle)
        self._canceling = True

    def step(self, measured: float, velocity: float, now: float) -> VesselStep:
        if self.target is None:
            return VesselStep(measured, "IDLE", 0.0)
        err = self.target - measured
        if self._canceling:
            if abs(velocity) < 0.01:
                return VesselStep(self.target, "CANCELED", err, f"canceled: vessel held at {math.degrees(measured):.1f} deg")
            return VesselStep(self.target, "RUNNING", err)
        if abs(err) <= self.params.tolerance:
            if self._inside_since is None:
                self._inside_since = now
            if now - self._inside_since >= self.params.settle_time:
                return VesselStep(self.target, "SUCCEEDED", err,
                                  f"vessel at {math.degrees(measured):.2f} deg (target {math.degrees(self.target):.2f} deg)")
        else:
            self._inside_since = None
        if now > self._deadline:
            return VesselStep(self.target, "FAILED", err,
                              f"timeout: vessel at {math.degrees(measured):.2f} deg, target {math.degrees(self.target):.2f} deg")
        return VesselStep(self.target, "RUNNING", err)
