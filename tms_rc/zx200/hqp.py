"""Strict-priority hierarchical QP over joint velocities, solved as a sequence of OSQP problems.

Each level is a set of linear rows on the decision vector ``x`` (joint velocities): equality tasks
``A x = b`` or inequality tasks ``A x <= b``. Level ``k`` is solved as

    minimise  ||w||^2 + reg ||x||^2
    subject to  A_k x - w  (= b_k | <= b_k, w >= 0)
                A_j x  within what level j < k achieved   (equal to A_j x*_j, or <= max(b_j, A_j x*_j))

so a lower level can only use the freedom the higher ones leave: it never disturbs them, and when it
is infeasible its slack ``w`` absorbs the conflict instead of bending a higher level (the HEAP
formulation: Jelavic et al., "Whole-body motion planning for walking excavators", and the
hierarchical optimisation it builds on). One OSQP instance per level is created once with a fixed
dense sparsity pattern and kept between control steps, so every solve is warm-started from the
previous step's solution.

Two exact shortcuts keep a 100 Hz step cheap: an inequality level whose rows already hold at x = 0
(and every level above it was satisfied at x = 0) has optimal slack 0, so it is not solved; and the
first equality level with a zero target under such levels has solution x = 0.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import osqp
from scipy import sparse

__all__ = ["LevelSpec", "HqpResult", "HierarchicalQP"]

_INF = float(osqp.constant("OSQP_INFTY"))
_OK = (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
EQ = "eq"
INEQ = "ineq"


@dataclass(frozen=True)
class LevelSpec:
    """One priority level: its name, kind ("eq" | "ineq") and number of rows."""

    name: str
    kind: Literal["eq", "ineq"]
    rows: int


@dataclass
class HqpResult:
    """Solution ``x`` plus, per level, the slack norm and whether a QP was actually solved."""

    x: np.ndarray
    slack: dict[str, float] = field(default_factory=dict)
    solved: dict[str, bool] = field(default_factory=dict)
    failed: list[str] = field(default_factory=list)
    solve_time_s: float = 0.0
    #: CPU time of this thread in the solve (excludes time the OS gave other processes: on a loaded
    #: machine the wall time's tail is preemption, not work)
    solve_cpu_s: float = 0.0


class HierarchicalQP:
    """Sequential strict-priority QP with one warm-started OSQP solver per level.

    Args:
        n: number of decision variables.
        levels: priority levels, highest first.
        eps: OSQP absolute and relative tolerances.
        max_iter: OSQP iteration cap per solve.
        regularisation: weight of ``||x||^2`` in every level (keeps each QP strictly convex).
        fix_tolerance: slack allowed when a solved level is imposed on the lower ones.
    """

    def __init__(
        self,
        n: int,
        levels: list[LevelSpec],
        *,
        eps: float = 1e-5,
        max_iter: int = 1000,
        regularisation: float = 1e-4,
        fix_tolerance: float = 1e-4,
        polish: bool = False,
    ) -> None:
        if n <= 0 or not levels:
            raise ValueError(f"HierarchicalQP needs n > 0 and at least one level, got n={n}, levels={levels}")
        for lv in levels:
            if lv.kind not in (EQ, INEQ) or lv.rows <= 0:
                raise ValueError(f"level {lv.name!r}: kind must be 'eq' or 'ineq' and rows > 0, got {lv}")
        self.n = n
        self.levels = list(levels)
        self._offsets = np.cumsum([0] + [lv.rows for lv in levels])
        self._fix_tol = fix_tolerance
        self._solvers: list[osqp.OSQP] = []
        self._slack_ax: list[np.ndarray] = []
        settings = dict(
            eps_abs=eps, eps_rel=eps, max_iter=max_iter, polishing=polish, verbose=False, warm_starting=True,
            adaptive_rho=True, check_termination=10,
        )
        for k, lv in enumerate(levels):
            task_rows = int(self._offsets[k + 1])
            m = lv.rows
            # Columns 0..n-1: dense over the task rows; slack column i: -1 at its task row, +1 at its sign row.
            indptr = [0]
            indices: list[int] = []
            for _ in range(n):
                indices.extend(range(task_rows))
                indptr.append(len(indices))
            for i in range(m):
                indices.extend([int(self._offsets[k]) + i, task_rows + i])
                indptr.append(len(indices))
            slack_ax = np.tile([-1.0, 1.0], m)
            data = np.concatenate([np.ones(n * task_rows), slack_ax])
            a = sparse.csc_matrix((data, np.array(indices), np.array(indptr)), shape=(task_rows + m, n + m))
            p = sparse.diags(np.concatenate([np.full(n, regularisation), np.ones(m)])).tocsc()
            p = sparse.triu(p, format="csc")
            big = np.full(task_rows + m, np.inf)
            solver = osqp.OSQP()
            solver.setup(p, np.zeros(n + m), a, -big, big, **settings)
            self._solvers.append(solver)
            self._slack_ax.append(slack_ax)

    @staticmethod
    def _shrink(proj: np.ndarray, a_eff: np.ndarray) -> np.ndarray:
        """Remove from the projector ``proj`` the directions the rows ``a_eff`` (= A @ proj) constrain."""
        if a_eff.shape[0] == 1:  # one row (theta_w): its direction, without an SVD (~20 us of numpy overhead)
            norm = float(np.sqrt(a_eff[0] @ a_eff[0]))
            if norm <= 1e-9:
                return proj
            v1 = a_eff[0] / norm
            out = proj - np.outer(v1, v1)
            return out if np.abs(out).max() > 1e-9 else np.zeros_like(proj)
        _, sv, vt = np.linalg.svd(a_eff, full_matrices=False)
        rank = int(np.sum(sv > 1e-9 * max(1.0, float(sv[0]) if sv.size else 1.0)))
        if rank == 0:
            return proj
        v = vt[:rank].T
        out = proj - v @ v.T
        return out if np.abs(out).max() > 1e-9 else np.zeros_like(proj)

    def solve(self, tasks: list[tuple[np.ndarray, np.ndarray]]) -> HqpResult:
        """Solve the hierarchy for this step's ``(A, b)`` per level (same order and shapes as ``levels``)."""
        start = time.perf_counter()
        cpu_start = time.thread_time()
        if len(tasks) != len(self.levels):
            raise ValueError(f"expected {len(self.levels)} (A, b) pairs, got {len(tasks)}")
        n = self.n
        total = int(self._offsets[-1])
        a_all = np.zeros((total, n))
        lo_fixed = np.full(total, -np.inf)
        hi_fixed = np.full(total, np.inf)
        for k, (lv, (a, _b)) in enumerate(zip(self.levels, tasks, strict=True)):
            a = np.asarray(a, dtype=float).reshape(lv.rows, n)
            a_all[self._offsets[k] : self._offsets[k + 1]] = a
        result = HqpResult(x=np.zeros(n))
        # x = x_star + proj @ z: proj spans the nullspace of the equality levels solved so far, so a
        # lower level cannot move them (eliminated exactly, no degenerate equality rows for OSQP).
        x_star = np.zeros(n)
        proj = np.eye(n)
        for k, (lv, (_, b)) in enumerate(zip(self.levels, tasks, strict=True)):
            b = np.asarray(b, dtype=float).reshape(lv.rows)
            s0, s1 = int(self._offsets[k]), int(self._offsets[k + 1])
            a = a_all[s0:s1]
            if not np.isfinite(a).all() or np.isnan(b).any():
                result.failed.append(lv.name)
                result.solved[lv.name] = False
                continue  # a broken level is dropped; the levels above stay imposed
            b_eff = b - a @ x_star
            a_eff = a @ proj
            if ((b_eff >= 0.0).all() if lv.kind == INEQ else (np.abs(b_eff) < 1e-12).all()):
                # z = 0 (keep x_star) meets this level exactly and every level above: slack 0.
                result.slack[lv.name] = 0.0
                result.solved[lv.name] = False
                if lv.kind == INEQ:
                    hi_fixed[s0:s1] = b + self._fix_tol
                else:
                    proj = self._shrink(proj, a_eff)
                continue
            if not proj.any():
                # no freedom left: this level is met as well as the higher ones allow
                result.slack[lv.name] = float(np.linalg.norm(b_eff if lv.kind == EQ else np.maximum(-b_eff, 0.0)))
                result.solved[lv.name] = False
                if lv.kind == INEQ:
                    hi_fixed[s0:s1] = np.maximum(b, a @ x_star) + self._fix_tol
                continue
            m = lv.rows
            lo = np.concatenate([lo_fixed[:s0], b_eff if lv.kind == EQ else np.full(m, -np.inf)])
            # z = 0 stays feasible for the levels above (x_star is their accepted solution).
            hi = np.concatenate([hi_fixed[:s0] - a_all[:s0] @ x_star, b_eff])
            if lv.kind == INEQ:
                lo = np.concatenate([lo, np.zeros(m)])
                hi = np.concatenate([hi, np.full(m, np.inf)])
            else:
                lo = np.concatenate([lo, np.full(m, -np.inf)])
                hi = np.concatenate([hi, np.full(m, np.inf)])
            ax = np.concatenate([(a_all[:s1] @ proj).ravel(order="F"), self._slack_ax[k]])
            # The low-level solver object: osqp.OSQP.update/solve add ~50 us of Python per call.
            solver = self._solvers[k]._solver
            solver.update_data_vec(q=None, l=np.maximum(lo, -_INF), u=np.minimum(hi, _INF))
            solver.update_data_mat(P_x=None, P_i=None, A_x=ax, A_i=None)
            solver.solve()
            status = solver.info.status_val
            z = np.array(solver.solution.x[:n], dtype=float)
            if status not in _OK or not np.isfinite(z).all():
                result.failed.append(f"{lv.name} ({solver.info.status})")
                result.solved[lv.name] = False
                continue  # drop this level: x and the constraints of the higher levels are kept
            x_star = x_star + proj @ z
            achieved = a @ x_star
            result.solved[lv.name] = True
            if lv.kind == INEQ:
                result.slack[lv.name] = float(np.linalg.norm(np.maximum(achieved - b, 0.0)))
                hi_fixed[s0:s1] = np.maximum(b, achieved) + self._fix_tol
            else:
                result.slack[lv.name] = float(np.linalg.norm(achieved - b))
                proj = self._shrink(proj, a_eff)
        x = x_star
        result.x = x
        result.solve_time_s = time.perf_counter() - start
        result.solve_cpu_s = time.thread_time() - cpu_start
        return result
