"""Pass planning: from the sensed terrain and a design, the next cut of an excavator standing at a base pose.

One call of :meth:`PassPlanner.next_pass` looks at the terrain grid (the heightmaps' convention, see
:mod:`tms_rp.excavation.design`) and answers either a :class:`Pass` or no pass with the reason:

1. the error over the design area (:func:`~tms_rp.excavation.design.surface_error`); mean absolute error within
   ``tolerance``, its 95th percentile within ``tolerance_p95`` and its maximum within ``tolerance_max``: done;
2. the cells the bucket can cut: inside the design area, more than ``min_cut`` above the design, and reachable
   from the base pose at the height they would be cut to (the radial reach of the bucket tip at that height, from
   the machine description's kinematics with every joint ``joint_margin`` inside its limits, less ``reach_margin``;
   never nearer the swing axis than half the footprint length plus ``track_clearance``, so the tracks are not
   undermined); none: done, nothing reachable;
3. where the material goes: the reachable design cells most below the design (a window of ``dump_radius``
   around the cell with the largest deficit sum), when they can take at least ``min_fill_volume``; otherwise a
   spoil place outside the design area (its whole dump disc at least ``spoil_clearance`` from it, reachable, the
   lowest such ground);
4. the cut: the window of the bucket's width holding the most material above the design (at most
   ``max_pass_depth`` per cell) gives the seed cell (the next best seeds, up to ``seeds``, when its pass is
   smaller than ``min_pass_volume``); the pass runs along the radial line through it toward the
   machine (the bucket is dragged in), over the contiguous cuttable cells of a strip one bucket wide, at most
   ``max_pass_length`` long, starting at the far end, which the bucket must reach at the lowest the edge may go; a
   pass whose far end is out of reach at its edge height is not planned (the next seed is tried). With
   ``lateral_step`` the line is also moved sideways past the seed, the largest pass kept (a bucket's side along a
   wall). The edge path holds, along the line, the highest of the
   strip's cut-to heights (never below the design); its depth below the surface is bounded by ``max_pass_depth``
   and shrunk until the volume fits the bucket (heaped capacity times ``fill_factor``) and the dump place.

The pass carries its expected volume (bank m^3), the cells it cuts with their heights after it, and the dump
place with the heights the dumped material is planned to make there. Deterministic (ties go to the first cell in
image order); pure numpy; the machine's bucket and reach come from its description, nothing from literals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_model.machines import Machine
from tms_rp.excavation.design import (
    Design,
    DesignError,
    GridLike,
    Sampled,
    SurfaceError,
    cell_centres,
    distance_to_polygon,
    surface_error,
)

__all__ = ["PlannerSettings", "BasePose", "Pass", "Decision", "ReachBand", "PassPlanner"]


@dataclass(frozen=True)
class PlannerSettings:
    """What a pass may be and when the work is done (lengths [m], volumes [m^3])."""

    tolerance: float = 0.02  # stop when the mean absolute error over the design area is at most this ...
    tolerance_p95: float = 0.05  # ... and its 95th percentile at most this (a wide apron dilutes the mean) ...
    tolerance_max: float = 0.10  # ... and no cell further off than this (no patch left behind)
    min_cut: float = 0.02  # a cell less than this above the design is finished
    max_pass_depth: float = 0.3  # deepest cut of one pass below the surface
    max_pass_length: float = 3.0  # longest drag of one pass
    fill_factor: float = 1.0  # share of the bucket's heaped capacity one pass may carry
    min_pass_volume: float = 0.002  # a smaller pass is not worth a cycle: nothing left to cut
    reach_margin: float = 0.3  # kept inside the bucket tip's radial reach at the cut height
    track_clearance: float = 1.0  # kept beyond half the footprint length from the swing axis
    fill_min: float = 0.03  # a cell more than this below the design takes fill
    min_fill_volume: float = 0.01  # a fill place that takes less gets no bucket: the spoil place instead
    dump_radius: float = 1.0  # radius of the place one bucket is dumped over
    spoil_clearance: float = 1.0  # spoil (the whole dump disc) stays this far outside the design area
    reach_band: float = 0.2  # height band [m] of the reach table's rows
    #: [rad] the reach table's poses keep every front joint this far inside its limits (the arm planner's own margin
    #: for a dig target: a cell reached only with a joint at its limit is refused there)
    joint_margin: float = 0.0
    seeds: int = 8  # seed cells tried, best first, before the planner says nothing is worth a pass
    #: [m] each seed's band also tried with its line moved sideways by multiples of this, less than half the bucket
    #: width either way (the seed cell stays under the bucket), the largest pass kept; 0: on the seed cell only. A
    #: band centred on its seed crosses a wall beside it and a level sweep then cuts nothing there; moved, the
    #: bucket's side runs along the wall (a trench's end, or walls as far apart as the bucket is wide)
    lateral_step: float = 0.0
    #: plan what the arm's excavate does (tms_rp.arm.planner: the edge dragged level, the bucket's whole width):
    #: every cell the edge sweeps is cut to one edge height, never below the design of any of them, so the drag
    #: stops where a wall of the design would come under the bucket; False: the strip is clipped to the cuttable
    #: cells and the edge follows each bin's own height (the idealised digger of the tests; on the plant the
    #: subtask's level drag then cut the walls and the apron: tms_rp/excavation/README.md)
    level_sweep: bool = False
    #: dump into the design's low cells when they take a bucket (``fill``); False: always the spoil place, for a
    #: machine that dumps elsewhere (a record's fixed dump place): a fill place's room would cap every pass
    fill: bool = True

    def __post_init__(self) -> None:
        for name in ("tolerance", "tolerance_p95", "tolerance_max", "min_cut", "max_pass_depth", "max_pass_length",
                     "fill_factor", "min_pass_volume", "dump_radius", "reach_band"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise DesignError(f"planner settings: {name} must be > 0, got {value!r}")
        for name in ("reach_margin", "track_clearance", "fill_min", "min_fill_volume", "spoil_clearance",
                     "lateral_step"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise DesignError(f"planner settings: {name} must be >= 0, got {value!r}")


@dataclass(frozen=True)
class BasePose:
    """The excavator's ``base_link`` on the map: x, y [m], yaw [rad]; ``z`` [m] the ground it stands on (None =
    the terrain height under the swing axis)."""

    x: float
    y: float
    yaw: float
    z: float | None = None


@dataclass(frozen=True)
class Pass:
    """One cut and its dump. Points are map ``(x, y, z)``; ``start`` is the far end of the cut (bucket edge where
    it enters), ``end`` the near end (the drag goes toward the machine along ``direction``); ``path`` ``(N, 3)``
    the edge heights along the line; ``cells`` ``(K, 2)`` row/col of the cut cells, ``cut_to`` their heights
    after the pass; ``dump`` where the bucket is emptied, ``dump_kind`` ``fill`` (into the design) or ``spoil``
    (outside it), ``dump_cells`` / ``dump_to`` the planned heights there."""

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    direction: tuple[float, float]
    width: float
    depth: float
    volume: float
    path: np.ndarray = field(repr=False, compare=False)
    cells: np.ndarray = field(repr=False, compare=False)
    cut_to: np.ndarray = field(repr=False, compare=False)
    dump: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dump_kind: str = "spoil"
    dump_cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int), repr=False, compare=False)
    dump_to: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)

    @property
    def length(self) -> float:
        return math.dist(self.start[:2], self.end[:2])


@dataclass(frozen=True)
class Decision:
    """The planner's answer: ``cut`` the next pass, or None when done, with ``reason``; ``error`` the surface
    error it judged."""

    cut: Pass | None
    reason: str
    error: SurfaceError


@dataclass(frozen=True)
class ReachBand:
    """Radial reach of the bucket tip from the swing axis per height above the ground the machine stands on:
    rows ``heights`` [m], ``r_min`` / ``r_max`` [m] (NaN where no pose reaches that height)."""

    heights: np.ndarray
    r_min: np.ndarray
    r_max: np.ndarray

    @classmethod
    def of(cls, kin: ExcavatorKinematics, band: float, samples: int = 41, joint_margin: float = 0.0) -> ReachBand:
        """The tip's planar reach over the joint limits less ``joint_margin`` [rad] (boom, arm, bucket sampled
        ``samples`` each)."""
        lo, hi = kin.limits.lower + joint_margin, kin.limits.upper - joint_margin
        qb, qa, qk = np.meshgrid(*(np.linspace(lo[i], hi[i], samples) for i in (1, 2, 3)), indexing="ij")
        pb, pa, pk = qb + kin.c_boom, qb + qa + kin.c_arm, qb + qa + qk + kin.c_bucket
        x = kin.boom_foot[0] + kin.l_boom * np.cos(pb) + kin.l_arm * np.cos(pa) + kin.l_bucket * np.cos(pk)
        z = kin.boom_foot[1] - kin.l_boom * np.sin(pb) - kin.l_arm * np.sin(pa) - kin.l_bucket * np.sin(pk)
        x, z = x.ravel(), (z + kin.swing_origin[2]).ravel()
        heights = np.arange(math.floor(z.min() / band) * band, z.max() + band, band)
        r_min = np.full(len(heights), np.nan)
        r_max = np.full(len(heights), np.nan)
        for i, h in enumerate(heights):
            sel = np.abs(z - h) <= band / 2.0
            if sel.any():
                r_min[i], r_max[i] = float(np.abs(x[sel]).min()), float(x[sel].max())
        return cls(heights=heights, r_min=r_min, r_max=r_max)

    def limits(self, height: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(r_min, r_max)`` at each height (NaN outside the table)."""
        band = self.heights[1] - self.heights[0] if len(self.heights) > 1 else 1.0
        i = np.rint((np.asarray(height, float) - self.heights[0]) / band).astype(int)
        ok = (i >= 0) & (i < len(self.heights))
        ic = np.clip(i, 0, len(self.heights) - 1)
        return np.where(ok, self.r_min[ic], np.nan), np.where(ok, self.r_max[ic], np.nan)


def _box_sum(a: np.ndarray, kr: int, kc: int) -> np.ndarray:
    """Sum of ``a`` over the ``(2 kr + 1) x (2 kc + 1)`` window around each cell (zero outside)."""
    p = np.pad(a, ((kr + 1, kr), (kc + 1, kc)))
    c = p.cumsum(0).cumsum(1)
    rows, cols = a.shape
    n, m = 2 * kr + 1, 2 * kc + 1
    return c[n:n + rows, m:m + cols] - c[:rows, m:m + cols] - c[n:n + rows, :cols] + c[:rows, :cols]


class PassPlanner:
    """Plans passes for one excavator (its description gives the bucket and the reach)."""

    def __init__(self, machine: Machine, settings: PlannerSettings | None = None) -> None:
        self.settings = settings or PlannerSettings()
        self.kin = ExcavatorKinematics(machine)
        bucket = machine.bucket
        assert bucket is not None  # ExcavatorKinematics refused a machine that is no excavator
        self.bucket_width = float(bucket.width)
        self.bucket_volume = float(bucket.capacity) * self.settings.fill_factor
        self.reach = ReachBand.of(self.kin, self.settings.reach_band, joint_margin=self.settings.joint_margin)
        self.min_radius = machine.footprint.length / 2.0 + self.settings.track_clearance
        self._cache: tuple[object, tuple, Sampled, np.ndarray] | None = None

    # ------------------------------------------------------------------ geometry
    def swing_axis(self, base: BasePose) -> np.ndarray:
        """Map ``(x, y)`` of the swing axis of the machine at ``base``."""
        c, s = math.cos(base.yaw), math.sin(base.yaw)
        ox, oy = float(self.kin.swing_origin[0]), float(self.kin.swing_origin[1])
        return np.array([base.x + c * ox - s * oy, base.y + s * ox + c * oy])

    def reachable(self, radius: np.ndarray, height: np.ndarray) -> np.ndarray:
        """True where a point ``radius`` [m] from the swing axis at ``height`` [m] above the machine's ground can
        be worked by the bucket tip (margins of the settings applied)."""
        r_min, r_max = self.reach.limits(height)
        m = self.settings.reach_margin
        with np.errstate(invalid="ignore"):
            return (radius >= np.maximum(r_min + m, self.min_radius)) & (radius <= r_max - m)

    def _sampled(self, design: Design, terrain: GridLike) -> tuple[Sampled, np.ndarray]:
        key = (terrain.x_min, terrain.y_min, terrain.x_max, terrain.y_max, np.shape(terrain.z))
        if self._cache is None or self._cache[0] is not design or self._cache[1] != key:
            s = design.sample(terrain)
            xc, yc = cell_centres(terrain)
            outside = np.where(s.inside, 0.0, distance_to_polygon(xc, yc, np.array(design.area)))
            self._cache = (design, key, s, outside)
        return self._cache[2], self._cache[3]

    # ------------------------------------------------------------------ the plan
    def next_pass(self, terrain: GridLike, design: Design, base: BasePose, skip: np.ndarray | None = None
                  ) -> Decision:
        """The next pass, or none with the reason (see the module docstring); ``skip`` (a boolean mask of the
        terrain's shape) marks cells not to plan a cut for (a caller's cells the machine could not cut)."""
        st = self.settings
        s, outside_dist = self._sampled(design, terrain)
        err = surface_error(design, terrain, sampled=s)
        if err.mae <= st.tolerance and err.p95 <= st.tolerance_p95 and err.max_abs <= st.tolerance_max:
            return Decision(None, f"within tolerance: MAE {err.mae * 100:.2f} cm <= {st.tolerance * 100:.2f} cm, "
                                  f"p95 {err.p95 * 100:.2f} cm <= {st.tolerance_p95 * 100:.2f} cm, "
                                  f"max {err.max_abs * 100:.2f} cm <= {st.tolerance_max * 100:.2f} cm", err)
        z = np.asarray(terrain.z, dtype=float)
        xc, yc = cell_centres(terrain)
        axis = self.swing_axis(base)
        ground = base.z if base.z is not None else _height_at(terrain, z, axis)
        radius = np.hypot(xc - axis[0], yc - axis[1])
        excess = z - s.target
        floor = np.maximum(s.target, z - st.max_pass_depth)
        cuttable = s.inside & (excess > st.min_cut) & self.reachable(radius, floor - ground)
        if skip is not None:
            cuttable &= ~skip
        if not cuttable.any():
            return Decision(None, f"nothing reachable to cut: {err.cut_volume:.3f} m3 above the design, none of it "
                                  f"more than {st.min_cut * 100:.1f} cm above and within reach of the base at "
                                  f"({base.x:.2f}, {base.y:.2f})", err)
        rows, cols = z.shape
        cx, cy = (terrain.x_max - terrain.x_min) / cols, (terrain.y_max - terrain.y_min) / rows

        dump = self._fill_place(s, z, radius, ground, xc, yc, cx, cy) if st.fill else None
        if dump is None:
            dump = self._spoil_place(s, z, radius, ground, outside_dist, xc, yc)
        if dump is None:
            return Decision(None, "no place to dump: no reachable design cell takes fill and no reachable ground lies "
                                  f"{st.spoil_clearance:.2f} m outside the design area", err)
        kind, target_rc, cap = dump
        cap = min(cap, self.bucket_volume)

        w = self.bucket_width
        material = np.where(cuttable, np.minimum(excess, st.max_pass_depth), 0.0)
        score = np.where(cuttable, _box_sum(material, int(w / 2.0 / cy), int(w / 2.0 / cx)), -1.0).ravel()
        order = np.argsort(-score, kind="stable")[:max(1, st.seeds)]
        cut, best = None, 0.0
        for seed in order[score[order] > 0]:
            cut = None
            rc = np.unravel_index(int(seed), z.shape)
            for shift in self._shifts():
                c = self._cut(s, z, excess, cuttable, axis, xc, yc, cx, cy, cap, rc, shift, ground)
                if c is not None and self._start_reachable(c[4], axis, ground) and (cut is None or c[3] > cut[3]):
                    cut = c
            best = max(best, 0.0 if cut is None else cut[3])
            if cut is not None and cut[3] >= st.min_pass_volume:
                break
        else:
            return Decision(None, f"nothing reachable worth a pass: the largest of {len(order)} tried is {best:.4f} "
                                  f"m3 < {st.min_pass_volume} m3", err)
        assert cut is not None
        sel, cut_to, depth, volume, path, u = cut
        dump_cells, dump_to = self._deposit(kind, target_rc, volume, s, z, xc, yc, cx * cy)
        r0, c0 = target_rc
        pick = np.argwhere(sel)
        return Decision(Pass(start=tuple(float(v) for v in path[0]), end=tuple(float(v) for v in path[-1]),
                             direction=(float(u[0]), float(u[1])), width=self.bucket_width, depth=depth,
                             volume=volume, path=path, cells=pick, cut_to=cut_to[sel],
                             dump=(float(xc[r0, c0]), float(yc[r0, c0]), float(z[r0, c0])), dump_kind=kind,
                             dump_cells=dump_cells, dump_to=dump_to),
                        f"cut {volume:.3f} m3, dump to {kind}", err)

    def _fill_place(self, s: Sampled, z: np.ndarray, radius: np.ndarray, ground: float, xc: np.ndarray,
                    yc: np.ndarray, cx: float, cy: float) -> tuple[str, tuple[int, int], float] | None:
        st = self.settings
        deficit = s.target - z
        takes = s.inside & (deficit > st.fill_min) & self.reachable(radius, s.target - ground)
        if not takes.any():
            return None
        d = np.where(takes, deficit, 0.0)
        score = np.where(takes, _box_sum(d, int(st.dump_radius / cy), int(st.dump_radius / cx)), -1.0)
        r, c = np.unravel_index(int(np.argmax(score)), score.shape)
        near = takes & (np.hypot(xc - xc[r, c], yc - yc[r, c]) <= st.dump_radius)
        capacity = float(np.sum(d[near])) * s.cell_area
        if capacity < st.min_fill_volume:
            return None
        return "fill", (int(r), int(c)), capacity

    def _spoil_place(self, s: Sampled, z: np.ndarray, radius: np.ndarray, ground: float, outside_dist: np.ndarray,
                     xc: np.ndarray, yc: np.ndarray) -> tuple[str, tuple[int, int], float] | None:
        st = self.settings
        ok = ~s.inside & (outside_dist >= st.spoil_clearance + st.dump_radius) & self.reachable(radius, z - ground)
        if not ok.any():
            return None
        idx = np.flatnonzero(ok)
        order = np.lexsort((radius.ravel()[idx], np.round(z.ravel()[idx], 4)))  # lowest ground, then nearest
        r, c = np.unravel_index(int(idx[order[0]]), z.shape)
        return "spoil", (int(r), int(c)), math.inf

    def _shifts(self) -> list[float]:
        """Sideways moves [m] of a seed's band line tried (``lateral_step``): none first, then outward both ways."""
        step, half = self.settings.lateral_step, self.bucket_width / 2.0
        if step <= 0.0:
            return [0.0]
        n = math.ceil(half / step) - 1
        return [0.0, *(sign * i * step for i in range(1, n + 1) for sign in (1.0, -1.0))]

    def _start_reachable(self, path: np.ndarray, axis: np.ndarray, ground: float) -> bool:
        """The far end of an edge path (the point the bucket penetrates to) within reach at its own height: the cells
        were judged at the heights they would be cut to, but the edge height is the strip's and the end lies half a
        cell beyond the cells (a far end 8.73 m out at the trench's depth failed the excavate goal, reached to
        8.72 m)."""
        r = np.hypot(path[:1, 0] - axis[0], path[:1, 1] - axis[1])
        return bool(self.reachable(r, path[:1, 2] - ground)[0])

    def _cut(self, s: Sampled, z: np.ndarray, excess: np.ndarray, cuttable: np.ndarray, axis: np.ndarray,
             xc: np.ndarray, yc: np.ndarray, cx: float, cy: float, cap: float, rc: tuple[Any, Any], shift: float = 0.0,
             ground: float = 0.0) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray, np.ndarray] | None:
        st = self.settings
        if st.level_sweep:
            return self._sweep(s, z, cuttable, axis, xc, yc, cx, cy, cap, rc, shift, ground)
        w = self.bucket_width
        seed, u, along, across = _drag_frame(xc, yc, axis, rc, shift)
        step = min(cx, cy)
        strip = cuttable & (np.abs(across) <= w / 2.0 + 1e-9)
        b = np.rint(along / step).astype(int)
        present = set(np.unique(b[strip]).tolist())
        lo = 0
        while lo - 1 in present:
            lo -= 1
        hi = 0
        while hi + 1 in present:
            hi += 1
        bins = max(1, int(st.max_pass_length / step))
        first = max(lo, -(bins - 1))
        last = min(hi, first + bins - 1)
        sel = strip & (b >= first) & (b <= last)
        ks = np.arange(first, last + 1)

        def plan(depth: float) -> tuple[np.ndarray, np.ndarray, float]:
            low = np.maximum(s.target, z - depth)
            edge = np.full(len(ks), -np.inf)
            np.maximum.at(edge, b[sel] - first, low[sel])
            edge = np.where(np.isfinite(edge), edge, np.nan)
            cut_to = z.copy()
            cut_to[sel] = np.minimum(z[sel], edge[b[sel] - first])
            return cut_to, edge, float(np.sum(z[sel] - cut_to[sel])) * s.cell_area

        depth, (cut_to, edge, volume) = _deepest_within(plan, st.max_pass_depth, cap)
        if volume <= 0.0:
            return None
        # the edge path: from the far end (first bin) toward the machine, one point per bin with cells
        ok = np.isfinite(edge)
        pts = seed[None, :] + (ks[ok] * step)[:, None] * u[None, :]
        path = np.column_stack([pts, edge[ok]])
        path = np.repeat(path, 2, axis=0) if len(path) == 1 else path  # one bin: its two edges, not one point
        # the cut's ends are the strip's outer cell edges
        path[0, :2] -= 0.5 * step * u
        path[-1, :2] += 0.5 * step * u
        return sel, cut_to, float(depth), volume, path, u

    def _sweep(self, s: Sampled, z: np.ndarray, cuttable: np.ndarray, axis: np.ndarray, xc: np.ndarray,
               yc: np.ndarray, cx: float, cy: float, cap: float, rc: tuple[Any, Any], shift: float = 0.0,
               ground: float = 0.0) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray, np.ndarray] | None:
        """The ``level_sweep`` pass from seed cell ``rc``: the bucket-wide band along the drag, its bins (one cell
        step along the drag) kept while each holds a cuttable cell and no cell whose floor (the design inside the
        area, the surface outside it) lies above the seed bin's; every cell of the band cut to one edge height,
        ``depth`` under the seed's surface and never under that floor, the depth shrunk to fit ``cap``."""
        st = self.settings
        w = self.bucket_width
        r, c = rc
        seed, u, along, across = _drag_frame(xc, yc, axis, rc, shift)
        step = min(cx, cy)
        band = np.abs(across) <= w / 2.0 + 1e-9
        b = np.rint(along / step).astype(int)
        floor_cell = np.where(s.inside, s.target, z)
        kb = b[band]
        k0 = int(kb.min())
        top = np.full(int(kb.max()) - k0 + 1, -np.inf)
        np.maximum.at(top, kb - k0, floor_cell[band])
        has_cut = np.zeros_like(top, dtype=bool)
        has_cut[b[band & cuttable] - k0] = True
        base_floor = top[-k0] + 1e-6
        # the lowest the edge can go; the bucket enters at a bin's far edge, half a cell beyond its cells, and must
        # reach it there (the cells were judged at their own heights): a band grown to the reach would fail the goal
        lowest = max(float(top[-k0]), float(z[r, c]) - st.max_pass_depth) - ground

        def ok(k: int) -> bool:
            i = k - k0
            return 0 <= i < len(top) and has_cut[i] and top[i] <= base_floor

        def enters(k: int) -> bool:
            edge = seed + (k - 0.5) * step * u
            return bool(self.reachable(np.array([math.dist(edge, axis)]), np.array([lowest]))[0])

        if not (ok(0) and enters(0)):
            return None
        lo = 0
        while ok(lo - 1) and enters(lo - 1):
            lo -= 1
        hi = 0
        while ok(hi + 1):
            hi += 1
        bins = max(1, int(st.max_pass_length / step))
        first = max(lo, -(bins - 1))
        last = min(hi, first + bins - 1)
        sel = band & (b >= first) & (b <= last)
        floor = float(np.max(floor_cell[sel]))
        surface = float(z[r, c])

        def plan(depth: float) -> tuple[np.ndarray, float, float]:
            level = max(floor, surface - depth)
            cut_to = z.copy()
            cut_to[sel] = np.minimum(z[sel], level)
            return cut_to, level, float(np.sum(z[sel] - cut_to[sel])) * s.cell_area

        depth, (cut_to, level, volume) = _deepest_within(plan, st.max_pass_depth, cap)
        if volume <= 0.0:
            return None
        ks = np.arange(first, last + 1)
        pts = seed[None, :] + (ks * step)[:, None] * u[None, :]
        path = np.column_stack([pts, np.full(len(ks), level)])
        path = np.repeat(path, 2, axis=0) if len(path) == 1 else path  # one bin: its two edges, not one point
        path[0, :2] -= 0.5 * step * u
        path[-1, :2] += 0.5 * step * u
        return sel, cut_to, float(depth), volume, path, u

    def _deposit(self, kind: str, target_rc: tuple[int, int], volume: float, s: Sampled, z: np.ndarray,
                 xc: np.ndarray, yc: np.ndarray, cell_area: float) -> tuple[np.ndarray, np.ndarray]:
        """The cells the dumped ``volume`` is planned to raise and their heights after it: fill brings the cells
        nearest the dump point up to the design in turn; spoil is spread evenly over the dump disc."""
        st = self.settings
        r0, c0 = target_rc
        dist = np.hypot(xc - xc[r0, c0], yc - yc[r0, c0])
        if kind == "fill":
            deficit = np.where(s.inside, s.target - z, 0.0)
            cand = np.flatnonzero(((deficit > 0) & (dist <= st.dump_radius)).ravel())
            cand = cand[np.lexsort((cand, dist.ravel()[cand]))]
            room = deficit.ravel()[cand] * cell_area
            before = np.concatenate([[0.0], np.cumsum(room)[:-1]])
            take = np.clip(volume - before, 0.0, room)
            keep = take > 0
            cells = cand[keep]
            heights = z.ravel()[cells] + take[keep] / cell_area
            left = volume - float(np.sum(take))
            if left > 1e-12:  # more than the place holds (the planner caps the pass at its capacity): on the point
                at = r0 * z.shape[1] + c0
                hit = np.flatnonzero(cells == at)
                if hit.size:
                    heights[hit[0]] += left / cell_area
                else:
                    cells = np.append(cells, at)
                    heights = np.append(heights, z[r0, c0] + left / cell_area)
        else:
            cells = np.flatnonzero((dist <= st.dump_radius).ravel())
            heights = z.ravel()[cells] + volume / (len(cells) * cell_area)
        rc = np.column_stack(np.unravel_index(cells, z.shape)).astype(int)
        return rc, heights


def _height_at(grid: GridLike, z: np.ndarray, xy: np.ndarray) -> float:
    rows, cols = z.shape
    col = int(np.clip((xy[0] - grid.x_min) / ((grid.x_max - grid.x_min) / cols), 0, cols - 1))
    row = int(np.clip((grid.y_max - xy[1]) / ((grid.y_max - grid.y_min) / rows), 0, rows - 1))
    return float(z[row, col])


def _deepest_within(plan: Any, max_depth: float, cap: float) -> tuple[float, Any]:
    """``(depth, plan(depth))`` for the deepest depth up to ``max_depth`` whose volume (``plan(depth)[2]``) stays
    within ``cap`` (bisection to ~1e-12 of ``max_depth``; the volume grows with the depth)."""
    result = plan(max_depth)
    if result[2] <= cap:
        return max_depth, result
    lo, hi = 0.0, max_depth
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if plan(mid)[2] > cap:
            hi = mid
        else:
            lo = mid
    return lo, plan(lo)


def _drag_frame(xc: np.ndarray, yc: np.ndarray, axis: np.ndarray, rc: tuple[Any, Any], shift: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The radial drag through seed cell ``rc``'s centre moved ``shift`` [m] across (left positive) toward the
    swing ``axis``: that point, the unit direction, and every cell centre's distance along it and across it."""
    r, c = rc
    seed = np.array([xc[r, c], yc[r, c]])
    if shift:
        toward = axis - seed
        seed = seed + shift * np.array([-toward[1], toward[0]]) / float(np.hypot(*toward))
    toward = axis - seed
    u = toward / float(np.hypot(*toward))
    n = np.array([-u[1], u[0]])
    along = (xc - seed[0]) * u[0] + (yc - seed[1]) * u[1]
    across = (xc - seed[0]) * n[0] + (yc - seed[1]) * n[1]
    return seed, u, along, across
