"""Global planner: coarse-to-fine Dijkstra on a tracked machine's costmap (scipy.sparse.csgraph).

Pure-Python A* on a 2000 x 2000 grid (200 m at 0.1 m) cannot meet a 200 ms budget, so the search runs in
scipy's compiled Dijkstra on two small graphs instead of one huge one:

1. a connectivity check on the cached free-space labels (start and goal in different components ->
   :class:`NoValidPathError` at once, whatever the map size);
2. a coarse pass on blocks of ``coarse_factor`` x ``coarse_factor`` cells (block cost = worst cell, so a
   coarse path is conservative);
3. a fine pass at full resolution restricted to a corridor of ``corridor_width`` around the coarse path.

When the conservative coarse pass finds nothing although the two cells are connected (a passage
narrower than a block), the fine pass runs on the whole component. Edge weights are
``length * (1 + cost_weight * cost / 252)`` so the path keeps away from obstacles where it can.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from tms_rp.tracked.costmap import INSCRIBED, Costmap
from tms_rp.tracked.errors import GoalOccupiedError, GoalOutsideMapError, InvalidGoalError, NoValidPathError

__all__ = ["PlannerParams", "GridPlanner"]

_OFFSETS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


@dataclass(frozen=True)
class PlannerParams:
    """``planner`` section of the nav file (tms_rp.tracked.config)."""

    coarse_factor: int = 8
    corridor_width: float = 2.0
    cost_weight: float = 3.0
    goal_tolerance: float = 0.0
    replan_period: float = 3.0
    approach_length: float = 3.0

    def __post_init__(self) -> None:
        if int(self.coarse_factor) != self.coarse_factor or self.coarse_factor < 1:
            raise ValueError(f"planner.coarse_factor must be an integer >= 1, got {self.coarse_factor!r}")
        for name in ("corridor_width", "cost_weight", "goal_tolerance", "replan_period", "approach_length"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"planner.{name} must be >= 0, got {value!r}")


def _graph(cost: np.ndarray, nodes: np.ndarray, cost_weight: float, step: float) -> tuple[csr_matrix, np.ndarray]:
    """Sparse 8-connected graph over the flat cell indices ``nodes`` of ``cost`` (all assumed passable).

    Built directly in CSR form with 8 slots per node (no COO sort); a missing neighbour becomes a
    self-loop, which Dijkstra never uses.
    """
    h, w = cost.shape
    n = nodes.size
    index = np.full(h * w, -1, dtype=np.int32)
    index[nodes] = np.arange(n, dtype=np.int32)
    rows, cols = np.divmod(nodes, w)
    node_cost = cost.ravel()[nodes].astype(np.float32)
    self_ids = np.arange(n, dtype=np.int32)
    indices = np.empty((n, 8), dtype=np.int32)
    data = np.empty((n, 8), dtype=np.float64)
    scale = np.float32(0.5 * cost_weight / 252.0)
    for slot, (dr, dc) in enumerate(_OFFSETS):
        r2, c2 = rows + dr, cols + dc
        ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        j = np.full(n, -1, dtype=np.int32)
        j[ok] = index[(r2[ok] * w + c2[ok])]
        valid = j >= 0
        j = np.where(valid, j, self_ids)
        length = step * (math.sqrt(2.0) if dr and dc else 1.0)
        indices[:, slot] = j
        data[:, slot] = length * (1.0 + scale * (node_cost + node_cost[j]))
    graph = csr_matrix((data.ravel(), indices.ravel(), np.arange(0, 8 * n + 1, 8)), shape=(n, n))
    return graph, index


def _shortest(
    cost: np.ndarray, passable: np.ndarray, start: int, goal: int, cost_weight: float, step: float
) -> np.ndarray | None:
    """Flat cell indices of the cheapest path from ``start`` to ``goal`` over ``passable`` cells, or None."""
    nodes = np.flatnonzero(passable.ravel())
    graph, index = _graph(cost, nodes, cost_weight, step)
    s, g = index[start], index[goal]
    if s < 0 or g < 0:
        return None
    dist, pred = dijkstra(graph, directed=True, indices=int(s), return_predecessors=True)
    if not np.isfinite(dist[g]):
        return None
    chain = [int(g)]
    while chain[-1] != s:
        chain.append(int(pred[chain[-1]]))
    return nodes[np.array(chain[::-1])]


class GridPlanner:
    """Plans a collision-free centre path for the machine on a :class:`Costmap`."""

    def __init__(self, params: PlannerParams | None = None) -> None:
        self.params = params or PlannerParams()
        self.last_stats: dict = {}

    def plan(self, costmap: Costmap, start: tuple[float, float], goal: tuple[float, float]) -> np.ndarray:
        """(N, 2) world points from ``start`` to ``goal`` (both included).

        Raises:
            InvalidGoalError: start or goal outside the map or not finite.
            GoalOccupiedError: the goal (or the start) is in an obstacle or within the inscribed radius.
            NoValidPathError: start and goal are not connected.
        """
        omap = costmap.map
        for name, (x, y) in (("start", start), ("goal", goal)):
            if not (math.isfinite(x) and math.isfinite(y)):
                raise InvalidGoalError(f"{name} ({x}, {y}) is not finite")
            if omap.world_to_cell(x, y) is None:
                ox, oy = omap.origin
                sx, sy = omap.size_m
                raise GoalOutsideMapError(
                    f"{name} ({x:.2f}, {y:.2f}) is outside the map [{ox:.1f}, {ox + sx:.1f}] x [{oy:.1f}, "
                    f"{oy + sy:.1f}]"
                )
        blocked = costmap.blocked
        s_cell = omap.world_to_cell(*start)
        g_cell = omap.world_to_cell(*goal)
        assert s_cell is not None and g_cell is not None
        if blocked[g_cell]:
            g_cell = self._nearest_free(costmap, g_cell, self.params.goal_tolerance)
            if g_cell is None:
                what = (
                    "an obstacle"
                    if costmap.obstacles[omap.world_to_cell(*goal)]
                    else "the inflated footprint of an obstacle"
                )
                raise GoalOccupiedError(
                    f"goal ({goal[0]:.2f}, {goal[1]:.2f}) lies in {what} (cost {costmap.cost_at(*goal)})"
                )
        if blocked[s_cell]:
            s_cell = self._nearest_free(costmap, s_cell, 1.0)
            if s_cell is None:
                raise GoalOccupiedError(f"start ({start[0]:.2f}, {start[1]:.2f}) lies in an obstacle or its inflation")
        labels = costmap.labels
        if labels[s_cell] != labels[g_cell]:
            raise NoValidPathError(
                f"goal ({goal[0]:.2f}, {goal[1]:.2f}) is unreachable: not connected to the start ({start[0]:.2f}, "
                f"{start[1]:.2f})"
            )
        h, w = blocked.shape
        s_flat, g_flat = s_cell[0] * w + s_cell[1], g_cell[0] * w + g_cell[1]
        cells = self._coarse_to_fine(costmap, s_cell, g_cell, s_flat, g_flat)
        if cells is None:
            component = labels == labels[s_cell]
            cells = _shortest(costmap.cost, component, s_flat, g_flat, self.params.cost_weight, costmap.resolution)
            self.last_stats["fallback"] = True
        if cells is None:  # pragma: no cover - labels said connected
            raise NoValidPathError(f"no path from {start} to {goal}")
        rows, cols = np.divmod(cells, w)
        xs, ys = omap.cell_to_world(rows, cols)
        pts = np.column_stack([xs, ys])
        pts[0] = start
        pts[-1] = goal
        return pts

    def plan_with_approach(self, costmap: Costmap, start: tuple[float, float], goal: tuple[float, float, float],
                           direction: int) -> np.ndarray:
        """Like :meth:`plan`, but the last ``approach_length`` metres run straight along the goal heading.

        The machine then arrives aligned (backing straight into the loading point); when the straight
        approach is blocked or the leg is too short, the plain plan is returned.
        """
        length = self.params.approach_length
        gx, gy, gyaw = goal
        px, py = gx - direction * length * math.cos(gyaw), gy - direction * length * math.sin(gyaw)
        if length <= 0 or math.hypot(gx - start[0], gy - start[1]) < length + 1.0:
            return self.plan(costmap, start, (gx, gy))
        n = max(2, int(math.ceil(length / costmap.resolution)) + 1)
        seg = np.column_stack([np.linspace(px, gx, n), np.linspace(py, gy, n)])
        cells = [costmap.map.world_to_cell(x, y) for x, y in seg]
        if any(c is None or costmap.blocked[c] for c in cells[:-1]):
            return self.plan(costmap, start, (gx, gy))
        head = self.plan(costmap, start, (px, py))
        return np.vstack([head, seg[1:]])

    def _coarse_to_fine(self, costmap: Costmap, s_cell, g_cell, s_flat: int, g_flat: int) -> np.ndarray | None:
        k = int(self.params.coarse_factor)
        cost = costmap.cost
        h, w = cost.shape
        self.last_stats = {"fallback": False}
        if k > 1:
            hc, wc = -(-h // k), -(-w // k)
            padded = np.full((hc * k, wc * k), 0, dtype=np.uint8)
            padded[:h, :w] = cost
            coarse = padded.reshape(hc, k, wc, k).max(axis=(1, 3))
            cs = (s_cell[0] // k, s_cell[1] // k)
            cg = (g_cell[0] // k, g_cell[1] // k)
            passable = coarse < INSCRIBED
            passable[cs] = passable[cg] = True  # the blocks holding start and goal may touch inflation
            coarse_cells = _shortest(
                coarse,
                passable,
                cs[0] * wc + cs[1],
                cg[0] * wc + cg[1],
                self.params.cost_weight,
                k * costmap.resolution,
            )
            self.last_stats["coarse_nodes"] = int(passable.sum())
            if coarse_cells is None:
                return None
            corridor_c = np.zeros((hc, wc), dtype=bool)
            corridor_c.flat[coarse_cells] = True
            radius = max(1, math.ceil(self.params.corridor_width / (k * costmap.resolution)))
            corridor_c = ndimage.binary_dilation(corridor_c, iterations=radius)
            corridor = np.repeat(np.repeat(corridor_c, k, axis=0), k, axis=1)[:h, :w]
            passable_f = corridor & ~costmap.blocked
        else:
            passable_f = ~costmap.blocked
        passable_f.flat[s_flat] = passable_f.flat[g_flat] = True
        self.last_stats["fine_nodes"] = int(passable_f.sum())
        return _shortest(cost, passable_f, s_flat, g_flat, self.params.cost_weight, costmap.resolution)

    @staticmethod
    def _nearest_free(costmap: Costmap, cell: tuple[int, int], radius_m: float) -> tuple[int, int] | None:
        if radius_m <= 0:
            return None
        r = int(math.ceil(radius_m / costmap.resolution))
        r0, c0 = max(0, cell[0] - r), max(0, cell[1] - r)
        win = costmap.blocked[r0:cell[0] + r + 1, c0:cell[1] + r + 1]
        free = np.argwhere(~win)
        if free.size == 0:
            return None
        d2 = (free[:, 0] + r0 - cell[0]) ** 2 + (free[:, 1] + c0 - cell[1]) ** 2
        i = int(np.argmin(d2))
        if d2[i] > r * r:
            return None
        return int(free[i, 0] + r0), int(free[i, 1] + c0)
