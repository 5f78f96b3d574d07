"""Cubic Hermite spline references and HEAP's PID position feedback (eq. 36) for the cylinder-space IK.

HEAP's inverse-kinematics arm controller (Jud et al. 2021, "HEAP - The autonomous walking excavator", sec. 4.3.2)
takes the desired end-effector velocity

    v_d = v_ref + K_P e + K_I int(e) dt + K_D e_dot,      e = x_ref - x            (HEAP eq. 36)

where ``x_ref`` and ``v_ref`` are read from cubic Hermite splines through the trajectory's knots (position and
velocity given at each knot: the standard basis p(s) = h00 p0 + h10 T m0 + h01 p1 + h11 T m1 on each interval of
length T, h00 = 2s^3 - 3s^2 + 1, h10 = s^3 - 2s^2 + s, h01 = -2s^3 + 3s^2, h11 = s^3 - s^2). The spline is
scipy's :class:`scipy.interpolate.CubicHermiteSpline` (made for exactly this), its derivative taken once.

- :class:`HermiteReference`: position and velocity at time t of a vector-valued spline (tip x, y, z, and theta_w
  as a fourth column if wanted); before the first knot and after the last it holds that knot at zero velocity.
- :class:`Pid`: eq. 36's feedback with anti-windup: the integral is clamped per axis to ``i_limit``, an axis
  integrates only while its error is inside ``i_zone`` (a large transient, e.g. a start off the reference, does
  not charge it), and nothing is integrated on a step the caller marks ``hold`` (conditional integration: the IK
  hierarchy gave way, a limit and not the error is what holds the tip back, so integrating would only wind up).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicHermiteSpline

__all__ = ["HermiteReference", "Pid"]


class HermiteReference:
    """A vector reference through knots ``(t_k, p_k, v_k)``: cubic Hermite on each interval (C1 at the knots).

    Args:
        times: knot times [s], strictly increasing, at least 2.
        positions: (k, d) or (k,) knot positions.
        velocities: knot velocities, same shape as ``positions``.
    """

    def __init__(self, times, positions, velocities) -> None:
        t = np.asarray(times, dtype=float)
        p = np.asarray(positions, dtype=float)
        v = np.asarray(velocities, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"HermiteReference needs at least 2 knot times, got {t.tolist()}")
        if p.shape[0] != t.size or v.shape != p.shape:
            raise ValueError(f"knots: {t.size} times, positions {p.shape}, velocities {v.shape} do not match")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise ValueError("knot times, positions and velocities must be finite")
        if not np.all(np.diff(t) > 0.0):
            raise ValueError(f"knot times must be strictly increasing, got {t.tolist()}")
        self.times = t
        self.positions = p
        self.velocities = v
        self._spline = CubicHermiteSpline(t, p, v, axis=0)
        self._deriv = self._spline.derivative()
        self._hold = np.zeros(p.shape[1:])

    @classmethod
    def through(cls, times, positions, velocities=None) -> HermiteReference:
        """Knots without velocities: zero at the ends, finite differences of the neighbours inside
        (Catmull-Rom: ``v_k = (p_k+1 - p_k-1) / (t_k+1 - t_k-1)``); given ``velocities`` are taken as they are."""
        t = np.asarray(times, dtype=float)
        p = np.asarray(positions, dtype=float)
        if velocities is None:
            v = np.zeros_like(p)
            if t.size > 2:
                span = (t[2:] - t[:-2]).reshape((-1,) + (1,) * (p.ndim - 1))
                v[1:-1] = (p[2:] - p[:-2]) / span
            velocities = v
        return cls(t, p, velocities)

    @property
    def start(self) -> float:
        return float(self.times[0])

    @property
    def end(self) -> float:
        return float(self.times[-1])

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) at time ``t`` [s]; outside the knots the end knot held still."""
        if t < self.times[0]:
            return self.positions[0].copy(), self._hold.copy()
        if t > self.times[-1]:
            return self.positions[-1].copy(), self._hold.copy()
        return self._spline(t), self._deriv(t)


class Pid:
    """``u = feedforward + kp e + ki int(e) + kd e_dot`` per axis (HEAP eq. 36), with anti-windup.

    Anti-windup: the integral of each axis stays within ``+-i_limit`` (so ``ki`` contributes at most
    ``ki * i_limit``), an axis integrates only while ``|error| <= i_zone``, and :meth:`update` with ``hold=True``
    leaves it unchanged (conditional integration).

    Args:
        kp, ki, kd: gains [1/s], [1/s^2], [-] for a position error in, a velocity out.
        dt: control period [s].
        i_limit: bound of the integral per axis [error unit x s]; inf = unclamped.
        dim: number of axes.
        i_zone: an axis integrates only while its error is within this [error unit]; inf = always.
    """

    def __init__(self, kp: float, ki: float, kd: float, dt: float, i_limit: float = math.inf, dim: int = 3,
                 i_zone: float = math.inf) -> None:
        if dt <= 0.0 or i_limit < 0.0 or dim <= 0 or i_zone < 0.0:
            raise ValueError(f"Pid needs dt > 0, i_limit >= 0, i_zone >= 0, dim > 0; got dt={dt}, i_limit={i_limit}, "
                             f"i_zone={i_zone}, dim={dim}")
        self.kp, self.ki, self.kd, self.dt, self.i_limit = float(kp), float(ki), float(kd), float(dt), float(i_limit)
        self.i_zone = float(i_zone)
        self.integral = np.zeros(dim)
        self._out = np.zeros(dim)

    def reset(self) -> None:
        """Forget the integral (a new motion)."""
        self.integral.fill(0.0)

    def update(self, error, error_rate, feedforward, *, hold: bool = False) -> np.ndarray:
        """The command for this step (a buffer overwritten by the next call: copy to keep).

        Args:
            error: ``x_ref - x``.
            error_rate: ``v_ref - v`` (or the error's finite difference).
            feedforward: ``v_ref``.
            hold: do not integrate this step (the output is not achieved: a limit holds the motion).
        """
        if not hold:
            e = np.asarray(error, dtype=float)
            if math.isfinite(self.i_zone):
                e = np.where(np.abs(e) <= self.i_zone, e, 0.0)
            self.integral += self.dt * e
            if math.isfinite(self.i_limit):
                np.clip(self.integral, -self.i_limit, self.i_limit, out=self.integral)
        out = self._out
        np.multiply(self.kp, error, out=out)
        out += feedforward
        if self.ki:
            out += self.ki * self.integral
        if self.kd:
            out += self.kd * np.asarray(error_rate, dtype=float)
        return out
