"""Local controller of a tracked machine: a regulated pure pursuit for a tracked (skid-steer) vehicle.

Nav2's RPP adapted to tracks: the machine can turn on the spot, so a large heading error is removed by
rotating in place ("align"); the path is then tracked forward or in *reverse* (the virtual robot frame is
turned by pi, so the same curvature law drives backwards into the loading point). The speed is regulated
by the path curvature and by the distance to the goal, then limited by the machine's speed, yaw-rate and
acceleration limits (config/machines/<kind>.yaml ``tracks``, the nav file's ``tracks`` where it has none). At the end of
the path translation stops
and the machine turns to the goal heading ("final_rotate"). :meth:`TrackedPurePursuit.compute` is pure
apart from the controller's own state: no I/O, the debug values are returned in the command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tms_common.errors import ConfigError
from tms_model.geometry import wrap_angle
from tms_model.machines import Tracks

__all__ = ["Limits", "ControllerParams", "TrackedPurePursuit", "Command"]


@dataclass(frozen=True)
class Limits:
    """Machine limits (config/machines/<kind>.yaml ``tracks``, the nav file's ``tracks`` where it has none)."""

    max_speed: float
    max_yaw_rate: float
    max_accel: float
    max_yaw_accel: float

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_yaw_rate", "max_accel", "max_yaw_accel"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"tracks.{name} must be > 0, got {value!r}")

    @classmethod
    def from_tracks(cls, tracks: Tracks, source: str = "machine description") -> Limits:
        """From a machine description's tracks; navigation needs the optional accelerations."""
        if tracks.max_accel is None or tracks.max_yaw_accel is None:
            raise ConfigError(f"{source}: tracks: navigation needs max_accel and max_yaw_accel")
        return cls(tracks.max_speed, tracks.max_yaw_rate, tracks.max_accel, tracks.max_yaw_accel)


@dataclass(frozen=True)
class ControllerParams:
    """``controller`` section of the nav file (tms_rp.tracked.config)."""

    frequency: float = 20.0
    desired_speed: float = 1.0
    reverse_speed: float = 0.5
    lookahead_time: float = 1.5
    min_lookahead: float = 1.0
    max_lookahead: float = 3.0
    rotate_to_heading_angle: float = 0.6
    rotate_speed: float = 0.3
    regulated_min_radius: float = 4.0
    approach_distance: float = 2.0
    min_approach_speed: float = 0.05
    heading_gain: float = 1.5
    stop_distance: float = 0.05
    yaw_goal_tolerance: float = 0.1

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"controller.{name} must be > 0, got {value!r}")
        if self.min_lookahead > self.max_lookahead:
            raise ValueError(f"controller.min_lookahead {self.min_lookahead} > max_lookahead {self.max_lookahead}")


@dataclass
class Command:
    """One control step: velocities and the readable state (Nav2 would publish the debug values)."""

    v: float
    w: float
    state: str
    distance_remaining: float
    done: bool = False
    debug: dict = field(default_factory=dict)


class TrackedPurePursuit:
    """Follows one path segment in one direction and (optionally) ends at a goal heading."""

    def __init__(self, params: ControllerParams, limits: Limits) -> None:
        self.params = params
        self.limits = limits
        self._path = np.zeros((0, 2))
        self._s = np.zeros(0)
        self._dir = 1
        self._goal_yaw: float | None = None
        self._idx = 0
        self._state = "idle"
        self._v = 0.0
        self._w = 0.0

    @property
    def state(self) -> str:
        return self._state

    def set_path(self, path: np.ndarray, direction: int, goal_yaw: float | None) -> None:
        """A new (N, 2) path to follow forward (``direction`` 1) or backwards (-1); ``goal_yaw`` None = position only.

        A path of one point (or of zero length) with a ``goal_yaw`` is a turn in place.
        """
        path = np.asarray(path, dtype=float).reshape(-1, 2)
        if path.shape[0] == 0 or not np.isfinite(path).all():
            raise ValueError("path must hold at least one finite point")
        if direction not in (1, -1):
            raise ValueError(f"direction must be 1 or -1, got {direction!r}")
        if path.shape[0] == 1:
            path = np.vstack([path, path])
        seg = np.hypot(*np.diff(path, axis=0).T)
        self._path, self._s = path, np.concatenate([[0.0], np.cumsum(seg)])
        self._dir, self._goal_yaw, self._idx = direction, goal_yaw, 0
        self._state = "align" if self._s[-1] > self.params.stop_distance else "final_rotate"

    def replace_path(self, path: np.ndarray) -> None:
        """Swap the path while driving (replanning) without re-aligning or resetting the velocity."""
        state = self._state
        self.set_path(path, self._dir, self._goal_yaw)
        if state in ("track", "final_rotate", "done") and self._state == "align":
            self._state = "track"

    def stop(self) -> None:
        """Forget the path; the next commands bring the machine to rest."""
        self._state = "idle"

    def compute(self, pose: tuple[float, float, float], dt: float) -> Command:
        """Velocity command for the estimated ``pose`` (x, y, yaw in map); ``dt`` is the control period."""
        x, y, yaw = pose
        p = self.params
        if self._state in ("idle", "done"):
            return self._limited(0.0, 0.0, dt, self._state, 0.0, done=self._state == "done")
        path, s = self._path, self._s
        # progress along the path (monotonic, windowed search)
        hi = min(len(path), self._idx + 400)
        d2 = (path[self._idx:hi, 0] - x) ** 2 + (path[self._idx:hi, 1] - y) ** 2
        self._idx += int(np.argmin(d2))
        remaining = float(s[-1] - s[self._idx] + math.sqrt(float(d2.min())))
        heading = wrap_angle(yaw + (math.pi if self._dir < 0 else 0.0))  # the virtual robot's heading
        gx, gy = path[-1]
        c, sn = math.cos(heading), math.sin(heading)
        goal_along = c * (gx - x) + sn * (gy - y)
        goal_dist = math.hypot(gx - x, gy - y)

        if self._state in ("align", "track"):
            if goal_dist < p.stop_distance or (self._state == "track" and goal_along < 0.0 and goal_dist < 1.0):
                self._state = "final_rotate"
            else:
                look = min(max(abs(self._v) * p.lookahead_time, p.min_lookahead), p.max_lookahead)
                target_s = min(s[self._idx] + look, s[-1])
                k = int(np.searchsorted(s, target_s))
                k = min(k, len(path) - 1)
                cx, cy = path[k]
                if goal_dist < look:  # carrot beyond the goal: aim at the goal itself
                    cx, cy = gx, gy
                dx, dy = cx - x, cy - y
                xr, yr = c * dx + sn * dy, -sn * dx + c * dy
                err = math.atan2(yr, xr)
                if self._state == "align" and abs(err) < 0.5 * p.rotate_to_heading_angle:
                    self._state = "track"
                if self._state == "align" or abs(err) > p.rotate_to_heading_angle:
                    self._state = "align"
                    w = math.copysign(
                        min(p.rotate_speed, self.limits.max_yaw_rate, max(0.05, abs(err) * p.heading_gain)), err
                    )
                    return self._limited(0.0, w, dt, "align", remaining, debug={"heading_error": err})
                l2 = max(xr * xr + yr * yr, 1e-6)
                kappa = 2.0 * yr / l2
                u = p.desired_speed if self._dir > 0 else p.reverse_speed
                u = min(u, self.limits.max_speed)
                if abs(kappa) > 1e-9 and 1.0 / abs(kappa) < p.regulated_min_radius:
                    u *= (1.0 / abs(kappa)) / p.regulated_min_radius
                if goal_dist < p.approach_distance:
                    u = max(u * goal_dist / p.approach_distance, p.min_approach_speed)
                u = min(
                    u,
                    math.sqrt(2.0 * 0.5 * self.limits.max_accel * max(goal_dist - p.stop_distance, 0.0))
                    + p.min_approach_speed,
                )
                w = u * kappa
                if abs(w) > self.limits.max_yaw_rate:
                    w = math.copysign(self.limits.max_yaw_rate, w)
                    u = abs(w / kappa)
                return self._limited(self._dir * u, w, dt, "track", remaining,
                                     debug={"carrot": (float(cx), float(cy)), "curvature": kappa})
        # final_rotate
        if self._goal_yaw is None:
            self._state = "done" if abs(self._v) < 1e-3 else "final_rotate"
            return self._limited(0.0, 0.0, dt, self._state, goal_dist, done=self._state == "done")
        err = wrap_angle(self._goal_yaw - yaw)
        if abs(err) < 0.5 * p.yaw_goal_tolerance and abs(self._w) < 0.05:
            self._state = "done"
            return self._limited(0.0, 0.0, dt, "done", goal_dist, done=True)
        w = math.copysign(min(p.rotate_speed, self.limits.max_yaw_rate, max(0.03, abs(err) * p.heading_gain)), err)
        if abs(err) < 0.5 * p.yaw_goal_tolerance:
            w = 0.0
        return self._limited(0.0, w, dt, "final_rotate", goal_dist, debug={"yaw_error": err})

    def brake(self, dt: float) -> Command:
        """Decelerate towards rest within the acceleration limits (used while the pose is stale)."""
        return self._limited(0.0, 0.0, dt, "hold", 0.0)

    def _limited(self, v: float, w: float, dt: float, state: str, remaining: float, *, done: bool = False,
                 debug: dict | None = None) -> Command:
        """Apply speed and acceleration limits relative to the last command (a velocity smoother)."""
        lim = self.limits
        v = max(-lim.max_speed, min(lim.max_speed, v))
        w = max(-lim.max_yaw_rate, min(lim.max_yaw_rate, w))
        dv, dw = lim.max_accel * dt, lim.max_yaw_accel * dt
        self._v = max(self._v - dv, min(self._v + dv, v))
        self._w = max(self._w - dw, min(self._w + dw, w))
        return Command(
            self._v, self._w, state, remaining, done and abs(self._v) < 1e-9 and abs(self._w) < 1e-9, debug or {}
        )
