"""Soil: the ground as a height field, plus the soil held by the bucket, the vessels and the blades.

Volume bookkeeping is exact by construction: every transfer moves a volume computed from the cells
it changes, so ``ground + bucket + vessels + blades`` stays equal to the initial ground volume (up to float
rounding). The ground volume is measured above a reference plane far below the surface.

* Cutting: while the bucket edge moves faster than ``cut_min_speed`` below the surface, the cells
  under the edge (``width`` across, the swept length along) are lowered to the edge height; the
  bucket takes that volume up to its free capacity (cells are cut proportionally less when full).
* Spilling: with the bucket open (tip angle below ``release_tip_angle``) and its edge above ground,
  the load leaves at ``capacity / spill_time`` per second (scaled by how far open). Soil landing over
  a carrier's vessel (lowered) becomes its load up to its capacity; the rest piles on the ground.
* Dumping: above ``dump_start_angle`` the vessel empties at ``capacity / dump_time`` per second (scaled
  by the angle) onto a pile ``dump_distance`` behind the hinge, along the vessel as its upper body is swung.
* Dozing: while a dozer moves faster than ``cut_min_speed`` with its blade edge below the surface, the cells
  under the edge are cut to the edge height into the blade's load up to its capacity; a blade lifted above the
  surface leaves its load in a pile ``spill_distance`` ahead of the edge.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sim_bridge.spec import SoilSpec

__all__ = ["HeightField", "SoilState"]


class HeightField:
    """A regular grid of ground heights (rows = y, cols = x), cell centres at ``x_min + (i + 0.5) res``."""

    def __init__(self, spec: SoilSpec) -> None:
        self.spec = spec
        self.res = spec.resolution
        self.nx = int(round(spec.size_x / self.res))
        self.ny = int(round(spec.size_y / self.res))
        self.x0 = spec.x_min
        self.y0 = spec.y_min
        self.cell_area = self.res * self.res
        xs = self.x0 + (np.arange(self.nx) + 0.5) * self.res
        ys = self.y0 + (np.arange(self.ny) + 0.5) * self.res
        self.xs, self.ys = xs, ys
        gx, gy = np.meshgrid(xs, ys)
        r = np.hypot(gx - spec.mound_center[0], gy - spec.mound_center[1])
        h = np.zeros_like(r)
        if spec.mound_height > 0 and spec.mound_base_radius > 0:
            rb, rt = spec.mound_base_radius, spec.mound_top_radius
            slope_part = np.clip((rb - r) / max(rb - rt, 1e-9), 0.0, 1.0)
            h = spec.mound_height * slope_part
        self.h = spec.ground_z + h
        self.datum = spec.ground_z - 10.0  # volume reference plane
        self._mound_mask: np.ndarray | None = None
        # The volumes are sums over the whole grid (90,000 cells on the fleet's site), asked for with every truth
        # message; the grid changes only in deposit() and cut(), which bump the version (nothing else writes h).
        self.version = 0
        self._sums: dict[str, tuple[int, float]] = {}

    def _cached(self, key: str, compute: Callable[[], float]) -> float:
        hit = self._sums.get(key)
        if hit is not None and hit[0] == self.version:
            return hit[1]
        value = compute()
        self._sums[key] = (self.version, value)
        return value

    def volume(self) -> float:
        """Ground volume above the datum [m^3]."""
        return self._cached("volume", lambda: float((self.h - self.datum).sum() * self.cell_area))

    def ground_soil_volume(self) -> float:
        """Soil above the original ground plane anywhere [m^3]: mound and piles, minus holes dug below it.

        ``ground_soil_volume() + bucket + vessel`` is conserved exactly.
        """
        return self._cached("ground", lambda: float((self.h - self.spec.ground_z).sum() * self.cell_area))

    def mound_volume(self) -> float:
        """Soil above the ground plane within ``mound_base_radius + mound_region_margin`` of the mound
        centre [m^3]: what is left to dig, without the dump piles elsewhere on the site."""
        spec = self.spec
        if self._mound_mask is None:
            gx, gy = np.meshgrid(self.xs, self.ys)
            radius = spec.mound_base_radius + spec.mound_region_margin
            self._mound_mask = np.hypot(gx - spec.mound_center[0], gy - spec.mound_center[1]) <= radius
        mask = self._mound_mask
        return self._cached("mound", lambda: float((self.h - spec.ground_z)[mask].sum() * self.cell_area))

    def index(self, x: float, y: float) -> tuple[int, int]:
        """(row, col) of the cell holding (x, y), clamped to the grid."""
        col = min(self.nx - 1, max(0, int((x - self.x0) / self.res)))
        row = min(self.ny - 1, max(0, int((y - self.y0) / self.res)))
        return row, col

    def height(self, x: float, y: float) -> float:
        r, c = self.index(x, y)
        return float(self.h[r, c])

    def window(self, x: float, y: float, radius: float) -> tuple[slice, slice]:
        r0, c0 = self.index(x - radius, y - radius)
        r1, c1 = self.index(x + radius, y + radius)
        return slice(r0, r1 + 1), slice(c0, c1 + 1)

    def deposit(self, x: float, y: float, volume: float, radius: float) -> None:
        """Spread ``volume`` evenly over the cells within ``radius`` of (x, y) (at least one cell)."""
        if volume <= 0.0:
            return
        self.version += 1
        rows, cols = self.window(x, y, radius)
        gx = self.xs[cols][None, :]
        gy = self.ys[rows][:, None]
        mask = (gx - x) ** 2 + (gy - y) ** 2 <= radius * radius
        n = int(mask.sum())
        if n == 0:
            r, c = self.index(x, y)
            self.h[r, c] += volume / self.cell_area
            return
        self.h[rows, cols] += mask * (volume / (n * self.cell_area))

    def cut(
        self,
        start: tuple[float, float],
        end: tuple[float, float],
        z: float,
        *,
        width: float,
        lateral: tuple[float, float],
        max_volume: float,
    ) -> float:
        """Lower the cells swept by a cutting edge to height ``z`` and return the volume removed.

        The edge is ``width`` long along the horizontal unit vector ``lateral`` and moved from ``start``
        to ``end`` (x, y) this step; the swept rectangle is at least one cell deep. When the cells hold
        more than ``max_volume`` above ``z``, each is cut proportionally less.
        """
        if max_volume <= 0.0:
            return 0.0
        mx, my = 0.5 * (start[0] + end[0]), 0.5 * (start[1] + end[1])
        dx, dy = end[0] - start[0], end[1] - start[1]
        lx, ly = lateral
        d_lat = dx * lx + dy * ly
        d_rad = -dx * ly + dy * lx
        half_across = 0.5 * (width + abs(d_lat))
        half_along = 0.5 * max(abs(d_rad), self.res)
        rows, cols = self.window(mx, my, max(half_across, half_along) + self.res)
        block = self.h[rows, cols]
        excess = block - z
        if not (excess > 0).any():
            return 0.0
        gx = self.xs[cols][None, :] - mx
        gy = self.ys[rows][:, None] - my
        across = gx * lx + gy * ly
        along = -gx * ly + gy * lx
        inside = (np.abs(along) <= half_along) & (np.abs(across) <= half_across)
        excess = np.where(inside & (excess > 0), excess, 0.0)
        available = float(excess.sum() * self.cell_area)
        if available <= 0.0:
            return 0.0
        frac = min(1.0, max_volume / available)
        self.version += 1
        self.h[rows, cols] = block - excess * frac
        return available * frac


@dataclass
class SoilState:
    """Soil held by the machines and the running totals, all in m^3.

    ``vessels`` holds every crawler carrier's load by machine name and ``blades`` every dozer blade's; ``vessel``
    is the load of ``carrier``, the paper's soil-carrying carrier.
    """

    bucket: float = 0.0
    dumped: float = 0.0  # total ever dumped from the vessels
    loaded: float = 0.0  # total ever landed in the vessels
    dug: float = 0.0  # total ever cut by the bucket
    vessels: dict[str, float] = field(default_factory=dict)
    #: total ever dumped per carrier (by machine name)
    dumped_by: dict[str, float] = field(default_factory=dict)
    #: total ever landed in each carrier's vessel (by machine name)
    loaded_by: dict[str, float] = field(default_factory=dict)
    blades: dict[str, float] = field(default_factory=dict)
    carrier: str = ""
    pushed: float = 0.0  # total ever cut by the blades

    @property
    def vessel(self) -> float:
        return self.vessels.get(self.carrier, 0.0)

    @vessel.setter
    def vessel(self, value: float) -> None:
        self.vessels[self.carrier] = value

    def held(self) -> float:
        """Soil off the ground: bucket, vessels and blades."""
        return self.bucket + sum(self.vessels.values()) + sum(self.blades.values())
