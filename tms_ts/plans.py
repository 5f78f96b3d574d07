"""The typed planning goal data a subtask row builds from its record (``build``) and finishes from the machine's
state (``resolve``), then turns into its downstream goal (``goal``). One frozen dataclass per shape; poses are
``{x, y, z, qx, qy, qz, qw}`` mappings in frame ``map``."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["Plan", "ChangePosePlan", "ExcavatePlan", "AnglePlan", "SwingAlignPlan", "SamplePlan", "PosePlan",
           "PosesPlan", "DesignPlan", "JOINTS", "POSE", "POSITION_WITH_ANGLE"]

#: ChangePosePlan modes: a joint target, an end-effector pose, a bucket-tip position with its edge angle theta_w
JOINTS, POSE, POSITION_WITH_ANGLE = "joints", "pose", "position_with_angle"


@dataclass(frozen=True)
class ChangePosePlan:
    """Exactly one target by ``mode``: ``joints`` {name: rad}, ``pose`` {x..qw} or ``pwa`` {x, y, z, theta_w}.
    ``pass_through``: end at the target without waiting for rest; ``theta_w_tolerance`` [rad]: the nearest holdable
    edge angle within it where theta_w cannot be held (0: exact)."""

    mode: str
    joints: Mapping[str, float] | None = None
    pose: Mapping[str, float] | None = None
    pwa: Mapping[str, float] | None = None
    pass_through: bool = False
    theta_w_tolerance: float = 0.0


@dataclass(frozen=True)
class ExcavatePlan:
    """The cut's bucket-tip position, edge angle and ``offset`` (``pwa`` {x, y, z, theta_w, offset})."""

    pwa: Mapping[str, float]


@dataclass(frozen=True)
class AnglePlan:
    """One angle target [rad]: ``what`` is release (bucket), dump (vessel) or swing (vessel swing)."""

    what: str
    target_angle: float


@dataclass(frozen=True)
class SwingAlignPlan:
    """The vessel swing to 0 or pi, whichever is nearer; ``target_angle`` None until resolved from joint_states."""

    target_angle: float | None = None


@dataclass(frozen=True)
class SamplePlan:
    """One front joint to ``goal`` [rad]; ``joints`` (all front joints, the others where they are) once resolved."""

    joint: str
    goal: float
    joints: Mapping[str, float] | None = None


@dataclass(frozen=True)
class PosePlan:
    """One navigation goal pose."""

    pose: Mapping[str, float]


@dataclass(frozen=True)
class PosesPlan:
    """A pose sequence for ``what`` = follow_waypoints or navigate_through_poses."""

    what: str
    poses: tuple[Mapping[str, float], ...]


@dataclass(frozen=True)
class DesignPlan:
    """Excavation to a stored design surface: the ``design``'s name (tms_db collection ``design``), the excavator's
    ``base`` {x, y, yaw, z} on the map, the ``dump`` point {x, y} on the map (None: the pass planner's place), the
    bucket tip's height over the dump ground when it is emptied, the edge angle at entry ``theta_w`` [rad], at most
    ``max_passes`` passes, the dynamic terrain's DATA_ID ``terrain_id``. ``base_measured``: the base's x, y, yaw are
    the machine's own pose when the subtask starts (``base`` then holds ``z`` only); ``scope`` ``design``: done when
    the whole design is within tolerance, ``reachable``: done when nothing reachable from this base is worth a pass
    (one of several base poses, each a subtask of the tree)."""

    design: str
    base: Mapping[str, float]
    dump: Mapping[str, float] | None
    dump_height: float
    theta_w: float
    max_passes: int
    terrain_id: int
    base_measured: bool = False
    scope: str = "design"


Plan = ChangePosePlan | ExcavatePlan | AnglePlan | SwingAlignPlan | SamplePlan | PosePlan | PosesPlan | DesignPlan
