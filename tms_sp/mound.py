"""The mound processor: excavation target and SENSING_CHECK_MOUND_FLG from the mound's height grid.

Target choice (one call per sensing update):

1. ``height above ground`` h = max(z - ground_z, 0) on the grid; cells thinner than ``min_height``
   count as empty.
2. Score of each cell = soil volume within ``bucket_radius`` of it (a disk convolution of h) minus
   ``distance_penalty`` x its distance from the ZX200 swing axis, so the bucket goes where one pass
   fills it best and, at equal fill, to the nearer soil. Only cells in the reach annulus
   ``[reach_min, reach_max]`` are candidates.
3. The target is the bucket-tip point the excavation penetrates to: the best cell's (x, y) and
   ``z = surface - penetration_depth`` (not below ground). ``offset`` is the drag length towards the
   machine (shortened so the drag ends outside ``reach_min``). ``theta_w`` (bucket-edge angle to the
   x-y plane, positive = tip down) = local surface slope rising away from the machine + the attack
   angle, clipped to ``[theta_w_min, theta_w_max]``.

The mound is "present" (SENSING_CHECK_MOUND_FLG true) while the diggable volume in reach is at least
``min_volume`` and some cell stands ``min_height`` above ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from tms_sp.frames import Pose2D
from tms_sp.heightgrid import HeightGrid

__all__ = ["ExcavationParams", "ExcavationTarget", "MoundAssessment", "assess_mound"]


@dataclass(frozen=True)
class ExcavationParams:
    """Parameters of :func:`assess_mound` (config/tms_sp/sensing.yaml ``excavation``)."""

    reach_min: float = 4.0
    reach_max: float = 8.8
    bucket_radius: float = 0.5
    penetration_depth: float = 0.35
    drag_length: float = 1.5
    attack_angle: float = math.radians(45.0)
    theta_w_min: float = math.radians(20.0)
    theta_w_max: float = math.radians(80.0)
    distance_penalty: float = 0.05
    min_height: float = 0.15
    min_volume: float = 0.4
    ground_z: float = 0.0

    def __post_init__(self) -> None:
        problems = []
        if not 0 <= self.reach_min < self.reach_max:
            problems.append(f"reach_min {self.reach_min} must be >= 0 and < reach_max {self.reach_max}")
        for name in ("bucket_radius", "drag_length"):
            if not getattr(self, name) > 0:
                problems.append(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("penetration_depth", "min_height", "min_volume", "distance_penalty"):
            if getattr(self, name) < 0:
                problems.append(f"{name} must be >= 0, got {getattr(self, name)}")
        if not self.theta_w_min <= self.theta_w_max:
            problems.append(f"theta_w_min {self.theta_w_min} > theta_w_max {self.theta_w_max}")
        if problems:
            raise ValueError("ExcavationParams: " + "; ".join(problems))


@dataclass(frozen=True)
class ExcavationTarget:
    """Where the bucket tip penetrates (map frame) and how the cut is made."""

    x: float
    y: float
    z: float
    theta_w: float
    offset: float
    surface_z: float        # sensed surface height at (x, y)
    expected_volume: float  # [m^3] soil within the bucket footprint at the target

    def in_base(self, base: Pose2D) -> tuple[float, float, float]:
        """Target position in the ZX200 base frame (what the DB record and the planner use)."""
        p = base.from_map(np.array([self.x, self.y, self.z]))
        return float(p[0]), float(p[1]), float(p[2])

    def record_fields(self, base: Pose2D) -> dict[str, float | int]:
        """The ``position_with_angle`` payload of the excavation record (ZX200 base frame)."""
        bx, by, bz = self.in_base(base)
        return {"position_with_angle": 1, "x": bx, "y": by, "z": bz, "theta_w": self.theta_w, "offset": self.offset}


@dataclass(frozen=True)
class MoundAssessment:
    """What the mound processor concluded from one height grid."""

    volume_total: float      # [m^3] soil above ground in the sensed region
    volume_in_reach: float   # [m^3] diggable soil in the reach annulus
    max_height: float        # [m] highest soil above ground
    target: ExcavationTarget | None
    has_soil: bool           # SENSING_CHECK_MOUND_FLG


def _disk(radius_cells: int) -> np.ndarray:
    r = max(1, radius_cells)
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    return (xx * xx + yy * yy <= r * r).astype(float)


def assess_mound(grid: HeightGrid, swing_axis_xy: tuple[float, float], params: ExcavationParams) -> MoundAssessment:
    """Assess the mound on ``grid`` (map frame) for a ZX200 whose swing axis is at ``swing_axis_xy``."""
    spec = grid.spec
    h = np.clip(grid.z - params.ground_z, 0.0, None)
    h_dig = np.where(h >= params.min_height, h, 0.0)
    xg, yg = spec.centres()
    ax, ay = swing_axis_xy
    r = np.hypot(xg - ax, yg - ay)
    in_reach = (r >= params.reach_min) & (r <= params.reach_max)

    volume_total = float(h.sum() * spec.cell_area)
    volume_in_reach = float((h_dig * in_reach).sum() * spec.cell_area)
    max_height = float(h.max())
    has_soil = volume_in_reach >= params.min_volume and max_height >= params.min_height

    target = None
    candidates = in_reach & (h_dig > 0)
    if has_soil and candidates.any():
        footprint = _disk(int(round(params.bucket_radius / spec.resolution)))
        fill = ndimage.convolve(h_dig, footprint, mode="constant") * spec.cell_area
        score = np.where(candidates, fill - params.distance_penalty * r, -np.inf)
        row, col = np.unravel_index(int(np.argmax(score)), score.shape)
        tx, ty = float(xg[row, col]), float(yg[row, col])
        surface = float(grid.z[row, col])
        # Surface slope along "away from the machine" from the smoothed grid.
        smooth = ndimage.uniform_filter(grid.z, size=max(3, int(round(params.bucket_radius / spec.resolution))))
        gy, gx = np.gradient(smooth, spec.resolution)
        dist = max(float(r[row, col]), 1e-6)
        ux, uy = (tx - ax) / dist, (ty - ay) / dist
        rise = float(gx[row, col] * ux + gy[row, col] * uy)
        theta_w = min(max(math.atan(rise) + params.attack_angle, params.theta_w_min), params.theta_w_max)
        offset = max(0.0, min(params.drag_length, dist - params.reach_min))
        z = max(surface - params.penetration_depth, params.ground_z)
        target = ExcavationTarget(
            x=tx, y=ty, z=z, theta_w=theta_w, offset=offset, surface_z=surface, expected_volume=float(fill[row, col])
        )
    return MoundAssessment(
        volume_total=volume_total,
        volume_in_reach=volume_in_reach,
        max_height=max_height,
        target=target,
        has_soil=has_soil and target is not None,
    )
