"""Closed-loop runs of NavigatorCore against the kinematic tracked model (used by tests and the bench)."""

from __future__ import annotations

import math

from tests.tms_rp.kinematics import TrackedModel
from tms_model.site import load_site
from tms_rp.tracked.navigator import NavigatorCore


def site_points() -> dict:
    return {k: (p.x, p.y, p.yaw) for k, p in load_site().points.items()}


def paper_legs(points: dict) -> list[list[tuple[float, float, float]]]:
    """To the loading point P1 (reached in reverse) and on to the dumping point P5 (turn at P3)."""
    return [[points["P2"], points["P1"]], [points["P2"], points["P3"], points["P4"], points["P5"]]]


def drive(nav: NavigatorCore, model: TrackedModel, poses, *, yaw_at_each: bool = False, max_time: float = 400.0,
          on_step=None) -> tuple[str, list[tuple[float, float, float]], object]:
    """Run one goal to completion; returns (status, truth trace, last NavStep)."""
    nav.start(poses, yaw_at_each=yaw_at_each)
    t = 0.0
    trace = []
    step = None
    while t < max_time:
        pose = (model.x, model.y, model.yaw)
        if on_step is not None:
            on_step(t, nav)
        step = nav.step(pose, t, model.dt)
        trace.append(model.step(step.v, step.w))
        t += model.dt
        if step.status != "RUNNING":
            break
    # let the machine come to rest
    for _ in range(40):
        s = nav.step((model.x, model.y, model.yaw), t, model.dt)
        model.step(s.v, s.w)
    return (step.status if step else "NONE"), trace, step


def pose_error(model: TrackedModel, goal) -> tuple[float, float]:
    return math.hypot(model.x - goal[0], model.y - goal[1]), abs(
        (model.yaw - goal[2] + math.pi) % (2 * math.pi) - math.pi
    )
