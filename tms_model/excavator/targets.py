"""What an excavator arm is asked to reach: the planner produces these, the arm controller executes them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CartesianTarget", "JointTarget", "Target"]


@dataclass(frozen=True)
class JointTarget:
    """Move to joint angles ``q`` [rad] (the kind's front joint order) along a joint-space spline."""

    q: np.ndarray
    label: str = ""
    speed_scale: float = 1.0
    via: bool = False  # pass-through point: via_tolerance_* even when it is the last segment of the run
    # reached only once the measured arm is within tolerance too, not the prediction alone (a via point otherwise
    # passes on it): an excavate's approach (the swing lags) and its segments in the soil (the load slows the
    # cylinders below the predictor's model)
    measured: bool = False


@dataclass(frozen=True)
class CartesianTarget:
    """Move the bucket tip on a straight line to ``position`` [m] with edge angle ``theta_w`` [rad]."""

    position: np.ndarray
    theta_w: float
    label: str = ""
    speed_scale: float = 1.0
    via: bool = False  # pass-through point: via_tolerance_* even when it is the last segment of the run
    # reached only once the measured arm is within tolerance too, not the prediction alone (a via point otherwise
    # passes on it): an excavate's approach (the swing lags) and its segments in the soil (the load slows the
    # cylinders below the predictor's model)
    measured: bool = False


Target = JointTarget | CartesianTarget
