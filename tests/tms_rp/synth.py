"""Synthetic IC120 trajectories for the localisation tests: truth, slipping odometry, noisy GNSS/azimuth."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Sample:
    t: float
    truth: tuple[float, float, float]
    odom: tuple[float, float, float]
    gnss: tuple[float, float]
    azimuth: float


def route_commands(duration: float, dt: float) -> list[tuple[float, float]]:
    """(v, w) per step: straight, left arc, reverse straight, turn on the spot, forward again."""
    out = []
    for k in range(int(duration / dt)):
        t = k * dt
        phase = (t % 60.0) / 60.0
        if phase < 0.3:
            out.append((1.0, 0.0))
        elif phase < 0.5:
            out.append((0.8, 0.15))
        elif phase < 0.7:
            out.append((-0.5, 0.0))
        elif phase < 0.8:
            out.append((0.0, 0.3))
        else:
            out.append((1.0, -0.05))
    return out


def simulate(duration: float = 120.0, dt: float = 0.1, *, gnss_sigma: float = 0.02, slip: float = 0.04,
             azimuth_sigma: float = 0.005, seed: int = 1) -> list[Sample]:
    """Ground truth from (v, w); odometry under-reports distance by ``slip`` with noise; GNSS has Gaussian noise."""
    rng = np.random.default_rng(seed)
    x = y = 0.0
    yaw = 0.3
    ox = oy = 0.0
    samples = []
    for k, (v, w) in enumerate(route_commands(duration, dt)):
        # truth
        x += v * dt * math.cos(yaw)
        y += v * dt * math.sin(yaw)
        yaw = (yaw + w * dt + math.pi) % (2 * math.pi) - math.pi
        # odometry: track slip (systematic + random), heading from the machine's azimuth sensor
        vm = v * (1.0 - slip) + rng.normal(0.0, 0.02)
        oyaw = yaw + rng.normal(0.0, 0.003)
        ox += vm * dt * math.cos(oyaw)
        oy += vm * dt * math.sin(oyaw)
        samples.append(Sample(
            t=(k + 1) * dt, truth=(x, y, yaw), odom=(ox, oy, oyaw),
            gnss=(x + rng.normal(0.0, gnss_sigma), y + rng.normal(0.0, gnss_sigma)),
            azimuth=yaw + rng.normal(0.0, azimuth_sigma),
        ))
    return samples
