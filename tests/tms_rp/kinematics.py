"""A kinematic tracked-vehicle model for controller tests: dead time, first-order lag and track slip.

Numbers default to config/machines/ic120.yaml ``hydraulics.tracks`` (dead 0.2 s, lag 0.4 s, slip 5 %,
yaw slip 15 %), i.e. what the MuJoCo plant models, so a controller that works here is not tuned on a
perfect integrator.
"""

from __future__ import annotations

import math
from collections import deque


class TrackedModel:
    def __init__(self, pose=(0.0, 0.0, 0.0), dt=0.05, dead_time=0.2, tau=0.4, slip=0.05, yaw_slip=0.15):
        self.x, self.y, self.yaw = pose
        self.dt, self.tau, self.slip, self.yaw_slip = dt, tau, slip, yaw_slip
        self.queue = deque([(0.0, 0.0)] * max(1, round(dead_time / dt)))
        self.v = self.w = 0.0

    def step(self, v_cmd: float, w_cmd: float) -> tuple[float, float, float]:
        self.queue.append((v_cmd, w_cmd))
        vc, wc = self.queue.popleft()
        a = self.dt / (self.tau + self.dt)
        self.v += a * (vc - self.v)
        self.w += a * (wc - self.w)
        v = self.v * (1 - self.slip)
        w = self.w * (1 - self.yaw_slip)
        self.x += v * self.dt * math.cos(self.yaw)
        self.y += v * self.dt * math.sin(self.yaw)
        self.yaw = (self.yaw + w * self.dt + math.pi) % (2 * math.pi) - math.pi
        return self.x, self.y, self.yaw
