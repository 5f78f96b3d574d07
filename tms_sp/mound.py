"""The mound processor: excavation target and SENSING_CHECK_MOUND_FLG from the mound's height grid.

Target choice (one call per sensing update):

1. ``height above ground`` h = max(z - ground_z, 0) on the grid; cells thinner than ``min_height``
   count as empty. Candidates are the cells with soil in the reach annulus ``[reach_min, reach_max]``.
2. For each candidate, the cut the excavation would make there is simulated on the grid: the bucket
   (``2 bucket_radius`` wide) penetrates to ``surface - depth`` and is dragged level towards the machine
   by ``offset`` = ``drag_length`` (shortened so the drag ends outside ``reach_min``); the cut volume is
   the soil above that level in the swept strip. ``depth`` is the shallowest of
   ``penetration_depth .. max_penetration_depth`` whose cut fills ``bucket_volume`` (else the deepest):
   on a slope a level drag leaves the soil after a short way, so it must start deeper than on the top.
3. Cells whose cut is below ``min_cut`` are no targets: with the soil left only beyond a dug-out near side, the
   distance penalty made a cell at the foot (its drag cut short by ``reach_min``) win with almost nothing to
   cut, and the excavator went there pass after pass (27 near-empty passes in a fleet demo). No cell cutting
   ``min_cut`` -> no target, the mound counts as depleted.
4. Score = min(cut, bucket_volume) - ``distance_penalty`` x distance from the swing axis: the bucket goes
   where one pass fills it, and at equal fill to the nearer soil. The target is the best cell's (x, y)
   at ``z = surface - depth`` (not below ground); ``expected_volume`` is its cut. ``theta_w``
   (bucket-edge angle to the x-y plane, positive = tip down) = local surface slope rising away from the
   machine + the attack angle, clipped to ``[theta_w_min, theta_w_max]``.

The mound has soil (``has_soil``; SENSING_CHECK_MOUND_FLG false, as Table 7 of the seed paper defines the flag:
true = not enough soil) while the diggable volume in reach is at least ``min_volume`` and some cell stands
``min_height`` above ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from tms_model.geometry import Pose2D
from tms_sp.heightgrid import HeightGrid

__all__ = ["ExcavationParams", "ExcavationTarget", "MoundAssessment", "assess_mound"]


@dataclass(frozen=True)
class ExcavationParams:
    """Parameters of :func:`assess_mound` (config/tms_sp/sensing.yaml ``excavation``)."""

    reach_min: float = 4.0
    reach_max: float = 8.8
    bucket_radius: float = 0.5
    penetration_depth: float = 0.35
    max_penetration_depth: float = 0.35
    bucket_volume: float = 0.8
    depth_steps: int = 5
    drag_length: float = 1.5
    attack_angle: float = math.radians(45.0)
    theta_w_min: float = math.radians(20.0)
    theta_w_max: float = math.radians(80.0)
    distance_penalty: float = 0.05
    min_height: float = 0.15
    min_volume: float = 0.4
    ground_z: float = 0.0
    target_hysteresis: float = 0.0
    depleted_hysteresis: float = 0.0
    min_cut: float = 0.0

    def __post_init__(self) -> None:
        problems = []
        if not 0 <= self.reach_min < self.reach_max:
            problems.append(f"reach_min {self.reach_min} must be >= 0 and < reach_max {self.reach_max}")
        for name in ("bucket_radius", "drag_length"):
            if not getattr(self, name) > 0:
                problems.append(f"{name} must be > 0, got {getattr(self, name)}")
        if self.max_penetration_depth < self.penetration_depth:
            problems.append(
                f"max_penetration_depth {self.max_penetration_depth} < penetration_depth {self.penetration_depth}"
            )
        if not self.bucket_volume > 0 or self.depth_steps < 1:
            problems.append(
                f"bucket_volume must be > 0 and depth_steps >= 1, got {self.bucket_volume}, {self.depth_steps}"
            )
        for name in ("penetration_depth", "min_height", "min_volume", "distance_penalty", "target_hysteresis",
                     "depleted_hysteresis", "min_cut"):
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
        """Target position in the excavator base frame (what the DB record and the planner use)."""
        p = base.from_map(np.array([self.x, self.y, self.z]))
        return float(p[0]), float(p[1]), float(p[2])

    def record_fields(self, base: Pose2D) -> dict[str, float | int]:
        """The ``position_with_angle`` payload of the excavation record (excavator base frame)."""
        bx, by, bz = self.in_base(base)
        return {"position_with_angle": 1, "x": bx, "y": by, "z": bz, "theta_w": self.theta_w, "offset": self.offset}

    def approach_record_fields(self, base: Pose2D, height: float) -> dict[str, float | int]:
        """The ``position_with_angle`` payload of the approach record: the target ``height`` higher with the
        same edge angle, where the excavate's approach segment begins (excavator base frame)."""
        bx, by, bz = self.in_base(base)
        return {"position_with_angle": 1, "x": bx, "y": by, "z": bz + height, "theta_w": self.theta_w}


@dataclass(frozen=True)
class MoundAssessment:
    """What the mound processor concluded from one height grid."""

    volume_total: float      # [m^3] soil above ground in the sensed region
    volume_in_reach: float   # [m^3] diggable soil in the reach annulus
    max_height: float        # [m] highest soil above ground
    target: ExcavationTarget | None
    has_soil: bool           # not SENSING_CHECK_MOUND_FLG (Table 7: the flag is true when soil is lacking)



def _level_cuts(
    z: np.ndarray, spec, rows: np.ndarray, cols: np.ndarray, dist: np.ndarray,  # GridSpec
    swing_axis_xy: tuple[float, float], params: ExcavationParams,
) -> tuple[np.ndarray, np.ndarray]:
    """(depth, cut volume) per candidate cell: a level drag towards the machine at ``surface - depth``.

    The swept strip is sampled at the grid resolution (``bucket`` wide, ``offset`` long, starting at the
    cell); each sample stands for one cell area. Depth is the shallowest step that fills the bucket.
    """
    res = spec.resolution
    xg0, yg0 = spec.x_min + (cols + 0.5) * res, spec.y_min + (rows + 0.5) * res
    ux, uy = (xg0 - swing_axis_xy[0]) / np.maximum(dist, 1e-6), (yg0 - swing_axis_xy[1]) / np.maximum(dist, 1e-6)
    length = np.clip(np.minimum(params.drag_length, dist - params.reach_min), 0.0, None)
    along = np.arange(0.0, params.drag_length + 1e-9, res)
    half = params.bucket_radius
    across = np.arange(-half + res / 2, half, res)
    px = xg0[:, None, None] - ux[:, None, None] * along[None, :, None] - uy[:, None, None] * across[None, None, :]
    py = yg0[:, None, None] - uy[:, None, None] * along[None, :, None] + ux[:, None, None] * across[None, None, :]
    ci = np.clip(((px - spec.x_min) / res).astype(int), 0, spec.nx - 1)
    ri = np.clip(((py - spec.y_min) / res).astype(int), 0, spec.ny - 1)
    swept = z[ri, ci]  # fancy indexing: a copy
    # samples beyond a cell's drag length take no part: as low as can be, they never stand above a level
    swept[~np.broadcast_to(along[None, :, None] <= length[:, None, None], swept.shape)] = -np.inf
    surface = z[rows, cols]
    depths = np.linspace(params.penetration_depth, params.max_penetration_depth, params.depth_steps)
    # Shallowest depth first; a cell leaves the search at the first depth that fills the bucket, so each
    # deeper step works on the cells still short (the sensing node runs this on every mound scan).
    pick = np.full(len(rows), len(depths) - 1)
    cut = np.zeros(len(rows))
    left = np.arange(len(rows))
    area = res * res
    for k, d in enumerate(depths):
        level = np.maximum(surface[left] - d, params.ground_z)
        above = swept[left]  # fancy indexing: a copy, worked on in place
        np.subtract(above, level[:, None, None], out=above)
        np.maximum(above, 0.0, out=above)
        cuts = above.sum(axis=(1, 2)) * area
        full = cuts >= params.bucket_volume
        done = full if k < len(depths) - 1 else np.ones_like(full)
        pick[left[done]] = k
        cut[left[done]] = cuts[done]
        left = left[~done]
        if not left.size:
            break
    return depths[pick], cut


def assess_mound(
    grid: HeightGrid, swing_axis_xy: tuple[float, float], params: ExcavationParams,
    previous_xy: tuple[float, float] | None = None, was_depleted: bool = False,
) -> MoundAssessment:
    """Assess the mound on ``grid`` (map frame) for an excavator whose swing axis is at ``swing_axis_xy``.

    ``previous_xy`` (map frame): the target chosen before. Its cell stays the target while its score on this
    grid is within ``params.target_hysteresis`` of the best one: on a noisy scan several cells score
    nearly alike, and without the band the best one jumped from scan to scan (up to 2.3 m sideways, on 14
    of 19 consecutive scans at the plant's 2 cm noise), so the tree's return went to one target and the
    excavate read another.

    ``was_depleted``: the previous assessment found no diggable soil; the mound then counts as diggable again
    only from ``min_volume + depleted_hysteresis`` (scan noise at ``min_volume`` flipped
    SENSING_CHECK_MOUND_FLG back and forth after the tree had read it false and ended the work).
    """
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
    min_volume = params.min_volume + (params.depleted_hysteresis if was_depleted else 0.0)
    has_soil = volume_in_reach >= min_volume and max_height >= params.min_height

    target = None
    candidates = in_reach & (h_dig > 0)
    rows = cols = np.empty(0, dtype=np.intp)
    if has_soil and candidates.any():
        rows, cols = np.nonzero(candidates)
        depth, cut = _level_cuts(grid.z, spec, rows, cols, r[rows, cols], swing_axis_xy, params)
        worth = cut >= params.min_cut  # step 3 of the module docstring
        rows, cols, depth, cut = rows[worth], cols[worth], depth[worth], cut[worth]
    if rows.size:
        score = np.minimum(cut, params.bucket_volume) - params.distance_penalty * r[rows, cols]
        best = int(np.argmax(score))
        if previous_xy is not None:
            kr, kc = spec.index_of(*previous_xy)
            kept = np.nonzero((rows == kr) & (cols == kc))[0]
            if kept.size and score[kept[0]] >= score[best] - params.target_hysteresis:
                best = int(kept[0])
        row, col = int(rows[best]), int(cols[best])
        chosen_depth, fill = float(depth[best]), float(cut[best])
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
        z = max(surface - chosen_depth, params.ground_z)
        target = ExcavationTarget(
            x=tx, y=ty, z=z, theta_w=theta_w, offset=offset, surface_z=surface, expected_volume=fill
        )
    return MoundAssessment(
        volume_total=volume_total,
        volume_in_reach=volume_in_reach,
        max_height=max_height,
        target=target,
        has_soil=has_soil and target is not None,
    )
