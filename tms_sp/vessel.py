"""The vessel processor: load volume, SENSING_LOADED_FLG and the release target in a carrier's vessel.

Input is the vessel's height grid in the **vessel frame**: origin at the centre of the vessel floor,
x towards the carrier's front, y to its left, z up, vessel lowered (angle 0). The grid covers the inner
rectangle ``inner_length x inner_width``; heights are soil surface above the floor (0 = bare floor).

* load volume = sum of heights x cell area; fill = volume / heaped capacity; the vessel is *loaded*
  (SENSING_LOADED_FLG) when fill >= ``target_fill``, and stays so down to ``target_fill - loaded_hysteresis``.
* release target = the lowest part of the load (heights smoothed over about a bucket width), at
  least ``wall_margin`` from the walls, ties broken towards the vessel centre; the bucket tip goes
  ``clearance`` above the higher of the rim and the heap top, so successive passes spread the soil.

:func:`release_in_excavator` turns that vessel-frame point into the excavator's base-frame record
(``position_with_angle`` + ``theta_w``) and the swing angle (``target_angle``) of release_simple.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from tms_model.geometry import Pose2D
from tms_sp.heightgrid import GridSpec, HeightGrid

__all__ = ["VesselGeometry", "VesselParams", "VesselAssessment", "assess_vessel", "release_in_excavator"]


@dataclass(frozen=True)
class VesselGeometry:
    """A carrier's vessel, from its description's ``vessel`` (config/machines/<kind>.yaml)."""

    inner_length: float
    inner_width: float
    capacity: float                        # [m^3] heaped
    hinge_xyz: tuple[float, float, float]  # in the carrier's base_link
    floor_above_hinge: float
    rim_above_hinge: float

    @property
    def rim_above_floor(self) -> float:
        return self.rim_above_hinge - self.floor_above_hinge

    def origin_in_base(self) -> np.ndarray:
        """Vessel-frame origin (floor centre) in the carrier's base_link, vessel lowered."""
        hx, hy, hz = self.hinge_xyz
        return np.array([hx + self.inner_length / 2.0, hy, hz + self.floor_above_hinge])

    def grid_spec(self, resolution: float) -> GridSpec:
        return GridSpec(
            -self.inner_length / 2.0,
            -self.inner_width / 2.0,
            self.inner_length / 2.0,
            self.inner_width / 2.0,
            resolution,
        )


@dataclass(frozen=True)
class VesselParams:
    """Parameters of :func:`assess_vessel` (config/tms_sp/sensing.yaml ``vessel``)."""

    wall_margin: float = 0.45
    clearance: float = 0.6
    carry_theta_w: float = math.radians(85.0)
    target_fill: float = 0.8
    smooth_width: float = 0.5   # [m] box filter before picking the lowest spot
    #: [m] the previous release spot is kept unless another is at least this much lower: with an even
    #: load, 2 cm scan noise moved the lowest spot up to 1 m between scans, so the carry (reading
    #: target_release_pose) and the release (reading release_angle ~5 s later) aimed 0.05-0.1 rad apart
    #: and the release added a swing of its own (6 of 16 passes of a 3-cycle demo)
    release_hysteresis: float = 0.03
    #: fill fraction: a vessel found loaded stays loaded until its fill drops this far below ``target_fill``
    #: (a load that ended near the threshold flipped SENSING_LOADED_FLG 42 times in 2 min with scan noise,
    #: in a 3-cycle demo); a dump empties it well below
    loaded_hysteresis: float = 0.05

    def __post_init__(self) -> None:
        if not 0 < self.target_fill <= 1.5:
            raise ValueError(f"VesselParams: target_fill must be in (0, 1.5], got {self.target_fill}")
        if self.wall_margin < 0 or self.clearance < 0:
            raise ValueError(
                f"VesselParams: wall_margin/clearance must be >= 0, got {self.wall_margin}/{self.clearance}"
            )
        if not 0 <= self.loaded_hysteresis < self.target_fill:
            raise ValueError(
                f"VesselParams: loaded_hysteresis must be in [0, target_fill), got {self.loaded_hysteresis}"
            )
        if self.release_hysteresis < 0:
            raise ValueError(f"VesselParams: release_hysteresis must be >= 0, got {self.release_hysteresis}")


@dataclass(frozen=True)
class VesselAssessment:
    """What the vessel processor concluded from one height grid (vessel frame)."""

    volume: float            # [m^3] soil in the vessel
    fill: float              # volume / capacity
    loaded: bool             # SENSING_LOADED_FLG
    release_xyz: tuple[float, float, float]  # bucket-tip release point, vessel frame
    lowest_height: float     # smoothed load height at the release point [m above floor]


def assess_vessel(grid: HeightGrid, geom: VesselGeometry, params: VesselParams,
                  previous_xy: tuple[float, float] | None = None, was_loaded: bool = False) -> VesselAssessment:
    """Load volume, loaded flag and release point from the vessel's height grid.

    ``was_loaded``: the previous assessment's flag; loaded then holds down to ``target_fill -
    loaded_hysteresis``.

    ``previous_xy`` (vessel frame) is the release spot chosen before: it stays the release point unless
    another allowed spot scores at least ``params.release_hysteresis`` lower.
    """
    spec = grid.spec
    h = np.clip(grid.z, 0.0, None)
    volume = float(h.sum() * spec.cell_area)
    fill = volume / geom.capacity
    xg, yg = spec.centres()
    half_l = geom.inner_length / 2.0 - params.wall_margin
    half_w = geom.inner_width / 2.0 - params.wall_margin
    allowed = (np.abs(xg) <= max(half_l, spec.resolution / 2)) & (np.abs(yg) <= max(half_w, spec.resolution / 2))
    size = max(1, int(round(params.smooth_width / spec.resolution)))
    smooth = ndimage.uniform_filter(h, size=size, mode="nearest")
    # Prefer the centre at (nearly) equal height: 1 cm per metre off-centre.
    score = np.where(allowed, smooth + 0.01 * np.hypot(xg, yg), np.inf)
    row, col = np.unravel_index(int(np.argmin(score)), score.shape)
    if previous_xy is not None:
        prev = np.unravel_index(int(np.argmin(np.hypot(xg - previous_xy[0], yg - previous_xy[1]))), score.shape)
        if np.isfinite(score[prev]) and score[prev] - score[row, col] < params.release_hysteresis:
            row, col = prev
    tip_z = max(geom.rim_above_floor, float(h.max())) + params.clearance
    return VesselAssessment(
        volume=volume,
        fill=fill,
        loaded=fill >= params.target_fill - (params.loaded_hysteresis if was_loaded else 0.0),
        release_xyz=(float(xg[row, col]), float(yg[row, col]), tip_z),
        lowest_height=float(smooth[row, col]),
    )


def release_in_excavator(
    release_xyz: tuple[float, float, float],
    carrier: Pose2D,
    excavator: Pose2D,
    geom: VesselGeometry,
    swing_axis_in_base: tuple[float, float] = (0.0, 0.0),
    carry_theta_w: float = math.radians(85.0),
) -> tuple[dict[str, float | int], dict[str, float]]:
    """Vessel-frame release point -> (``target_release_pose`` fields, ``release_angle`` fields).

    The first dict is ``position_with_angle:1`` + x,y,z (excavator base frame) + theta_w; the second is
    ``{"target_angle": swing angle [rad]}`` pointing the front at the release point (swing + = CCW).
    """
    in_carrier = geom.origin_in_base() + np.asarray(release_xyz, dtype=float)
    in_map = carrier.to_map(in_carrier)
    in_ex = excavator.from_map(in_map)
    swing = math.atan2(in_ex[1] - swing_axis_in_base[1], in_ex[0] - swing_axis_in_base[0])
    pose = {
        "position_with_angle": 1,
        "x": float(in_ex[0]),
        "y": float(in_ex[1]),
        "z": float(in_ex[2]),
        "theta_w": float(carry_theta_w),
    }
    return pose, {"target_angle": float(swing)}

