"""Angle control of a crawler carrier's vessel (dump body) and vessel swing, pure Python.

The COM3 carrier frame carries a *target vessel angle* (``rot_dump_cmd`` ``dump_joint`` position: 0 = lowered,
+ = raised) and, on a carrier whose vessel swings (MST types), a target swing angle (``rotate_joint``); the
machine's own hydraulics move there. One :class:`VesselController` per axis validates the target against the
machine limit, keeps sending it, watches the measured angle (``joint_states``) and decides success (inside
``tolerance`` for ``settle_time``), timeout (``|delta| / velocity + timeout_margin``) or, on cancel, holds the
axis where it is and reports once it has stopped moving. A continuous axis (a swing without limits) takes
any finite target and moves the short way round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tms_common.errors import TmsError
from tms_common.schema import setting
from tms_model.geometry import wrap_angle
from tms_model.machines import Joint, Vessel

__all__ = ["VesselParams", "VesselTuning", "VesselController", "VesselError", "VesselStep"]


class VesselError(TmsError, ValueError):
    """A bad target angle (names the value and the allowed range)."""


@dataclass(frozen=True)
class VesselTuning:
    """The ``vessel`` section of a carrier's nav file (:func:`tms_model.nav_files.load_nav_files`): when an axis
    is there, and how long it may take."""

    tolerance: float = setting(lo=1e-6, doc="[rad] measured angle within this of the target")
    settle_time: float = setting(lo=1e-6, doc="[s] inside tolerance for this long")
    timeout_margin: float = setting(lo=1e-6, doc="[s] timeout = |delta| / velocity + margin")


@dataclass(frozen=True)
class VesselParams:
    """Limits from the description (``vessel``, or the swing joint) + tuning from the nav file's ``vessel``."""

    max_angle: float
    velocity: float
    tolerance: float
    settle_time: float
    timeout_margin: float
    min_angle: float = 0.0
    continuous: bool = False  # no limits: any target, the short way round (min/max unused)
    what: str = "vessel"  # the axis, in messages
    source: str = "the machine's description"  # where the limits come from, in messages

    def __post_init__(self) -> None:
        for name in ("max_angle", "velocity", "tolerance", "settle_time", "timeout_margin"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{self.what}.{name} must be > 0, got {value!r}")
        if not (math.isfinite(self.min_angle) and self.min_angle < self.max_angle):
            raise ValueError(f"{self.what}: min_angle {self.min_angle!r} must be below max_angle {self.max_angle!r}")

    @classmethod
    def from_config(cls, machine_vessel: Vessel, tuning: VesselTuning, source: str) -> VesselParams:
        """The vessel of a carrier: its description's angle limit and velocity (``source`` names it)."""
        return cls(machine_vessel.max_angle, machine_vessel.velocity, tuning.tolerance, tuning.settle_time,
                   tuning.timeout_margin, source=source)

    @classmethod
    def for_swing(cls, joint: Joint, tuning: VesselTuning, source: str = "") -> VesselParams:
        """The vessel swing of a carrier: the swing joint's limits (none = continuous) and velocity."""
        continuous = joint.lower is None or joint.upper is None
        return cls(math.pi if continuous else float(joint.upper), joint.velocity,
                   tuning.tolerance, tuning.settle_time, tuning.timeout_margin,
                   min_angle=-math.pi if continuous else float(joint.lower), continuous=continuous,
                   what=joint.name, source=source or f"{joint.name} limits")


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

    def _error(self, target: float, measured: float) -> float:
        return wrap_angle(target - measured) if self.params.continuous else target - measured

    def start(self, target: float, measured: float, now: float) -> None:
        """Accept a target [rad]; raises :class:`VesselError` outside the limits or not finite."""
        p = self.params
        if not math.isfinite(target):
            raise VesselError(f"target_angle {target!r} is not finite")
        if p.continuous:
            target = measured + wrap_angle(target - measured)  # the short way round
        elif not p.min_angle <= target <= p.max_angle:
            sense = "0 = lowered, + = raised; " if p.what == "vessel" else ""
            raise VesselError(
                f"target_angle {target:.4f} rad ({math.degrees(target):.1f} deg) outside [{p.min_angle:g}, "
                f"{p.max_angle:.4f}] rad ({sense}{p.source})"
            )
        self.target = target
        self._inside_since = None
        self._canceling = False
        self._deadline = now + abs(self._error(target, measured)) / p.velocity + p.timeout_margin

    def cancel(self, measured: float) -> None:
        """Hold the axis at its current angle (clamped to the limits) and report once it is still."""
        p = self.params
        self.target = measured if p.continuous else min(max(measured, p.min_angle), p.max_angle)
        self._canceling = True

    def step(self, measured: float, velocity: float, now: float) -> VesselStep:
        if self.target is None:
            return VesselStep(measured, "IDLE", 0.0)
        err = self._error(self.target, measured)
        if self._canceling:
            if abs(velocity) < 0.01:
                return VesselStep(self.target, "CANCELED", err,
                                  f"canceled: {self.params.what} held at {math.degrees(measured):.1f} deg")
            return VesselStep(self.target, "RUNNING", err)
        if abs(err) <= self.params.tolerance:
            if self._inside_since is None:
                self._inside_since = now
            if now - self._inside_since >= self.params.settle_time:
                return VesselStep(self.target, "SUCCEEDED", err,
                                  f"{self.params.what} at {math.degrees(measured):.2f} deg (target "
                                  f"{math.degrees(self.target):.2f} deg)")
        else:
            self._inside_since = None
        if now > self._deadline:
            return VesselStep(self.target, "FAILED", err,
                              f"timeout: {self.params.what} at {math.degrees(measured):.2f} deg, target "
                              f"{math.degrees(self.target):.2f} deg")
        return VesselStep(self.target, "RUNNING", err)
