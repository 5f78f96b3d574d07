"""A pure-Python hydraulic joint model: per-joint command dead time followed by a first-order lag.

Used by the unit tests and the benchmark to exercise the arm controller without ROS or MuJoCo, and
documented as the plant model the controller's dead-time compensation assumes. Joint positions are
*not* clamped, so a controller that violates a limit is caught.
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["LagDeadTimePlant"]


class LagDeadTimePlant:
    """``velocity' = (command(t - dead_time) - velocity) / lag``; ``q' = velocity``.

    Args:
        dt: integration step [s] (the controller period).
        dead_time_s: per-joint dead time [s].
        lag_s: per-joint first-order time constant [s].
        q0: initial joint positions [rad].
    """

    def __init__(self, dt: float, dead_time_s: np.ndarray, lag_s: np.ndarray, q0: np.ndarray) -> None:
        self.dt = float(dt)
        self.q = np.array(q0, dtype=float)
        self.v = np.zeros_like(self.q)
        self._delay_steps = [int(round(float(d) / dt)) for d in dead_time_s]
        self._lag = np.maximum(np.asarray(lag_s, dtype=float), 1e-9)
        self._queues = [deque([0.0] * n, maxlen=n + 1) for n in self._delay_steps]

    def step(self, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply one command (joint velocities) for ``dt``; returns the new (q, velocity)."""
        applied = np.empty_like(self.q)
        for i, queue in enumerate(self._queues):
            queue.append(float(command[i]))
            applied[i] = queue.popleft()
        alpha = 1.0 - np.exp(-self.dt / self._lag)
        self.v = self.v + alpha * (applied - self.v)
        self.q = self.q + self.v * self.dt
        return self.q.copy(), self.v.copy()
