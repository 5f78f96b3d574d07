"""Strict-priority hierarchical QP over joint velocities, solved as a sequence of OSQP problems.

Each level is a set of linear rows on the decision vector ``x`` (joint velocities): equality tasks
``A x = b`` or inequality tasks ``A x <= b``. Level ``k`` is solved as

    minimise  ||w||^2 + reg ||x||^2
    subject to  A_k x - w  (= b_k | <= b_k, w >= 0)
                A_j x  within what level j < k achieved   (equal to A_j x*_j, or <= max(b_j, A_j x*_j))

(an equality level's slack is eliminated before OSQP sees it: ``P = A^T A + reg I``, ``q = -A^T b``,
the same optimum with a better-conditioned problem), so a lower level can only use the freedom the
higher ones leave: it never disturbs them, and when it
is infeasible its slack ``w`` absorbs the conflict instead of bending a higher level (the HEAP
formulation: Jelavic et al., "Whole-body motion planning for walking excavators", and the
hierarchical optimisation it builds on). One OSQP instance per level is created once with a fixed
dense sparsity pattern and kept between control steps, so every solve is warm-started from the
previous step's solution.

Every level below the first stays feasible (z = 0, "keep x_star", always is), also when a level is left unmet
against the limits above it (a binding or initially violated collision damper):

- a row of a level above that an OSQP solution overshot within OSQP's eps (beyond the fix tolerance) is relaxed
  to the value that solution achieves, so the bounds handed down are never below what the levels above achieved;
- a level left unmet (slack above ``_UNMET`` fix tolerances) has its optimum on a face of the constraints: every
  row active there with a positive multiplier keeps its value at any of the level's optima (KKT), so those rows
  join the nullspace projector like an equality task's (without this the lower levels got a feasible set as thin
  as the fix tolerance, which OSQP answered with "primal infeasible" or ``max_iter``);
- an OSQP solve that ends unfinished (``max_iter``, inaccurate) gives its iterate shortened to keep every row
  above (``HqpResult.inexact``), or no step when that would not lower the level's objective.

Exact shortcuts keep a 100 Hz step cheap (measured figures: tms_rc/excavator/README.md):

- an inequality level whose rows already hold at x = 0 (and every level above it was satisfied at
  x = 0) has optimal slack 0, so it is not solved; an equality level met by the current x likewise;
- a level's QP is strictly convex, so when its *unconstrained* optimum already satisfies every
  constraint the levels above impose, that point is the optimum: it is computed in closed form
  (equality level: the regularised least-squares step, a 4x4 Cholesky solve; inequality level whose
  rows are the box ``[I; -I]``, as the velocity and position limits are: per joint, the box point
  nearest 0, pulled towards 0 by the regularisation) and checked against those constraints; only when one of them is
  active does OSQP solve
  the level. This is the same optimum OSQP converges to (without its ``eps`` error and iteration
  tail: a box level used to take up to ``max_iter`` iterations while the arm accelerates);
- every buffer is preallocated; each level's OSQP problem keeps one fixed sparsity pattern and gets
  new bounds and constraint values in place (``update_data_vec`` / ``update_data_mat`` on the
  low-level solver), and the matrix is only re-sent (KKT refactorisation) when its values changed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import osqp
from scipy import sparse
from scipy.linalg.lapack import dgesdd as _gesdd
from scipy.linalg.lapack import dposv as _posv

__all__ = ["LevelSpec", "HqpResult", "HierarchicalQP"]

_INF = float(osqp.constant("OSQP_INFTY"))
_SOLVED = osqp.SolverStatus.OSQP_SOLVED
_OK = (_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE)
_MAX_ITER = osqp.SolverStatus.OSQP_MAX_ITER_REACHED
EQ = "eq"
INEQ = "ineq"
#: a level whose slack exceeds this many fix tolerances is unmet: its active rows are pinned for the levels below
_UNMET = 10.0
#: a row is pinned when its multiplier exceeds this fraction of the level's largest ...
_PIN_DUAL = 1e-3
#: ... and its value is within this many fix tolerances of its bound (or beyond it)
_PIN_ACTIVE = 10.0


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
    #: levels whose QP optimum was found in closed form (unconstrained optimum inside every constraint)
    closed_form: list[str] = field(default_factory=list)
    #: levels whose OSQP solve ended unfinished (inaccurate or at max_iter): its iterate was shortened to keep
    #: every level above, and taken only where it lowered the level's objective
    inexact: list[str] = field(default_factory=list)


class HierarchicalQP:
    """Sequential strict-priority QP with one warm-started OSQP solver per level.

    Args:
        n: number of decision variables.
        levels: priority levels, highest first.
        eps: OSQP absolute and relative tolerances.
        max_iter: OSQP iteration cap per solve.
        regularisation: weight of ``||x||^2`` in every level (keeps each QP strictly convex).
        fix_tolerance: slack allowed when a solved level is imposed on the lower ones.
        polish: OSQP solution polishing.
        closed_form: take a level's unconstrained optimum when it meets every constraint of the
            levels above (exact; False = OSQP for every level that is not met at the current x).
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
        closed_form: bool = True,
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
        self._reg = regularisation
        self._closed_form = closed_form
        self._exact = True  # the last OSQP solve ended SOLVED (its multipliers are meaningful)
        box = np.vstack([np.eye(n), -np.eye(n)])
        # per level: the rows [I; -I] if an inequality level has that shape (its closed form applies)
        self._box = [box if lv.kind == INEQ and lv.rows == 2 * n else None for lv in levels]
        self._box_seen: list[bytes | None] = [None] * len(levels)  # bytes of the last rows found equal to it
        self._offsets_py = [int(o) for o in self._offsets]
        self._solvers: list[osqp.OSQP] = []
        self._slack_ax: list[np.ndarray] = []
        total = self._offsets_py[-1]
        self._a_all = np.zeros((total, n))  # this step's rows of every level, stacked
        self._b_all = np.zeros(total)
        self._hi_fixed = np.full(total, np.inf)  # upper bounds the solved inequality levels impose below
        self._eye = np.eye(n)
        self._lo: list[np.ndarray] = []
        self._hi: list[np.ndarray] = []
        self._ax: list[np.ndarray] = []
        self._ax_block: list[np.ndarray] = []  # view of _ax's dense part as (n, task rows), C order
        self._ax_sent: list[bytes | None] = []  # the values the solver holds (skip unchanged updates)
        settings = dict(
            eps_abs=eps, eps_rel=eps, max_iter=max_iter, polishing=polish, verbose=False, warm_starting=True,
            adaptive_rho=True, check_termination=10,
        )
        # upper triangle of a dense n x n matrix in CSC order (column by column): the P of equality levels
        self._triu = tuple(np.array(ix) for ix in zip(*[(i, j) for j in range(n) for i in range(j + 1)], strict=True))
        self._px_sent: list[bytes | None] = [None] * len(levels)
        for k, lv in enumerate(levels):
            s0, task_rows = self._offsets_py[k], self._offsets_py[k + 1]
            m = lv.rows
            if lv.kind == EQ:
                # Slack eliminated: ||A_eff z - b_eff||^2 + reg ||z||^2 = z^T (A_eff^T A_eff + reg I) z
                # - 2 b_eff^T A_eff z + const, so P = A_eff^T A_eff + reg I (dense upper triangle),
                # q = -A_eff^T b_eff, and the constraints are only the rows of the levels above (one
                # unbounded zero row for a first level). Same optimum as with the slack, better
                # conditioned for ADMM (4x fewer iterations on the position level while a limit binds).
                rows = max(s0, 1)
                indptr = np.arange(n + 1) * rows
                indices = np.tile(np.arange(rows), n)
                data = np.zeros(n * rows) if s0 == 0 else np.ones(n * rows)
                a = sparse.csc_matrix((np.ones(n * rows), indices, indptr), shape=(rows, n))
                p = sparse.triu(sparse.csc_matrix(np.ones((n, n))), format="csc")
                lo, hi = np.full(rows, -_INF), np.full(rows, _INF)
                q0 = np.zeros(n)
                slack_ax = np.zeros(0)
            else:
                # Columns 0..n-1: dense over the task rows; slack column i: -1 at its task row, +1 at its sign row.
                indptr_l = [0]
                indices_l: list[int] = []
                for _ in range(n):
                    indices_l.extend(range(task_rows))
                    indptr_l.append(len(indices_l))
                for i in range(m):
                    indices_l.extend([s0 + i, task_rows + i])
                    indptr_l.append(len(indices_l))
                slack_ax = np.tile([-1.0, 1.0], m)
                data = np.concatenate([np.ones(n * task_rows), slack_ax])
                a = sparse.csc_matrix((data, np.array(indices_l), np.array(indptr_l)), shape=(task_rows + m, n + m))
                p = sparse.diags(np.concatenate([np.full(n, regularisation), np.ones(m)])).tocsc()
                p = sparse.triu(p, format="csc")
                # lower bounds are constant (rows -inf, slack >= 0); upper ones are filled every step
                lo = np.full(task_rows + m, -_INF)
                lo[task_rows:] = 0.0
                hi = np.full(task_rows + m, _INF)
                q0 = np.zeros(n + m)
            solver = osqp.OSQP()
            solver.setup(p, q0, a, lo, hi, **settings)  # lo never changes: sent once, here
            self._solvers.append(solver)
            self._slack_ax.append(slack_ax)
            ax = data.copy()  # constraint values in CSC order: dense block column-major, then slack columns
            self._lo.append(lo)
            self._hi.append(hi)
            self._ax.append(ax)
            self._ax_block.append(ax[: n * max(s0 if lv.kind == EQ else task_rows, 1)].reshape(n, -1))
            self._ax_sent.append(None)

    @staticmethod
    def _shrink(proj: np.ndarray, a_eff: np.ndarray) -> tuple[np.ndarray, bool]:
        """Remove from the projector ``proj`` the directions the rows ``a_eff`` (= A @ proj) constrain.

        Returns the new projector (``proj`` itself when nothing changed) and whether it is zero.
        """
        if a_eff.shape[0] == 1:  # one row (theta_w): its direction, without an SVD (~20 us of numpy overhead)
            norm = _norm(a_eff[0])
            if norm <= 1e-9:
                return proj, False
            v1 = a_eff[0] / norm
            out = proj - np.outer(v1, v1)
            return (out, False) if np.abs(out).max() > 1e-9 else (np.zeros_like(proj), True)
        # LAPACK's SVD through scipy's thin wrapper: ~7 us instead of np.linalg.svd's ~18 us
        _, sv, vt, info = _gesdd(a_eff, full_matrices=0)
        if info != 0:
            _, sv, vt = np.linalg.svd(a_eff, full_matrices=False)
        rank = int(np.sum(sv > 1e-9 * max(1.0, float(sv[0]) if sv.size else 1.0)))
        if rank == 0:
            return proj, False
        v = vt[:rank].T
        out = proj - v @ v.T
        return (out, False) if np.abs(out).max() > 1e-9 else (np.zeros_like(proj), True)

    def solve(self, tasks: list[tuple[np.ndarray, np.ndarray]]) -> HqpResult:
        """Solve the hierarchy for this step's ``(A, b)`` per level (same order and shapes as ``levels``).

        Every buffer (stacked rows, OSQP bounds and constraint values) is preallocated in ``__init__``;
        a level's OSQP matrix is only re-sent (and its KKT system refactorised) when its values changed,
        e.g. never for the safety levels above the first equality level, whose rows are constant.
        """
        start = time.perf_counter()
        cpu_start = time.thread_time()
        if len(tasks) != len(self.levels):
            raise ValueError(f"expected {len(self.levels)} (A, b) pairs, got {len(tasks)}")
        n = self.n
        a_all, b_all, hi_fixed = self._a_all, self._b_all, self._hi_fixed
        offsets = self._offsets_py
        for k, (a, b) in enumerate(tasks):
            s0, s1 = offsets[k], offsets[k + 1]
            # arrays of the exact shape are copied as they are; anything else must reshape to it
            a_all[s0:s1] = a if type(a) is np.ndarray and a.shape == (s1 - s0, n) else np.reshape(a, (s1 - s0, n))
            b_all[s0:s1] = b if type(b) is np.ndarray and b.shape == (s1 - s0,) else np.reshape(b, s1 - s0)
        hi_fixed.fill(np.inf)
        # One check for all levels (a sum is finite only if every term is); per level only when it fails.
        all_finite = math.isfinite(a_all.sum()) and not math.isnan(b_all.sum())
        result = HqpResult(x=np.zeros(n))
        slack, solved = result.slack, result.solved
        # x = x_star + proj @ z: proj spans the nullspace of the equality levels solved so far, so a
        # lower level cannot move them (eliminated exactly, no degenerate equality rows for OSQP).
        x_star = np.zeros(n)
        x_zero = True  # x_star is still exactly 0 (skips the products with it)
        proj = self._eye
        proj_eye, proj_zero = True, False
        for k, lv in enumerate(self.levels):
            s0, s1 = offsets[k], offsets[k + 1]
            a, b = a_all[s0:s1], b_all[s0:s1]
            ineq = lv.kind == INEQ
            if not all_finite and (not np.isfinite(a).all() or np.isnan(b).any()):
                result.failed.append(lv.name)
                solved[lv.name] = False
                a.fill(0.0)  # its rows stay unbounded in the lower levels' QPs: zero, not NaN, values
                continue  # a broken level is dropped; the levels above stay imposed
            ax_star = None if x_zero else a @ x_star
            b_eff = b if x_zero else b - ax_star
            if (b_eff.min() >= 0.0) if ineq else (np.abs(b_eff).max() < 1e-12):
                # z = 0 (keep x_star) meets this level exactly and every level above: slack 0.
                slack[lv.name] = 0.0
                solved[lv.name] = False
                if ineq:
                    np.add(b, self._fix_tol, out=hi_fixed[s0:s1])
                elif k + 1 < len(self.levels) and not proj_zero:
                    proj, proj_zero = self._shrink(proj, a @ proj)
                    proj_eye = proj_eye and proj is self._eye
                continue
            if proj_zero:
                # no freedom left: this level is met as well as the higher ones allow
                if ineq:
                    slack[lv.name] = _norm(np.maximum(-b_eff, 0.0))
                    hi_fixed[s0:s1] = np.maximum(b, a @ x_star) + self._fix_tol
                else:
                    slack[lv.name] = _norm(b_eff)
                solved[lv.name] = False
                continue
            a_eff = a if proj_eye else a @ proj
            x_new = self._unconstrained_optimum(k, a, a_eff, b_eff, proj, proj_eye) if self._closed_form else None
            if x_new is not None:
                if not x_zero:
                    x_new += x_star
                if s0 and not (a_all[:s0] @ x_new <= hi_fixed[:s0]).all():
                    x_new = None  # a constraint of the levels above is active there: OSQP finds the optimum
            by_osqp = x_new is None
            if not by_osqp:
                result.closed_form.append(lv.name)
            else:
                z = self._osqp_solve(k, lv, a_eff, b_eff, proj, proj_eye, x_zero, x_star, result)
                if z is None:
                    solved[lv.name] = False
                    continue  # drop this level: x and the constraints of the higher levels are kept
                x_new = x_star + (z if proj_eye else proj @ z)
            x_star = x_new
            x_zero = False
            achieved = a @ x_star
            solved[lv.name] = True
            tol = self._fix_tol
            if by_osqp and s0:
                # OSQP meets the rows above within its own eps, which may exceed the fix tolerance: relax a row it
                # overshot to what this solution achieves (not more: no creep), so that x_star (z = 0) stays
                # feasible for every level below
                above = a_all[:s0] @ x_star
                over = above > hi_fixed[:s0]
                if over.any():
                    hi_fixed[:s0][over] = above[over]
            if ineq:
                level_slack = slack[lv.name] = _norm(np.maximum(achieved - b, 0.0))
                np.add(np.maximum(b, achieved), tol, out=hi_fixed[s0:s1])
            else:
                level_slack = slack[lv.name] = _norm(achieved - b)
            if k + 1 == len(self.levels):  # the last level's nullspace is never used
                continue
            unmet = by_osqp and self._exact and level_slack > _UNMET * tol
            pinned = self._pinned_rows(k, s0, s1, x_star) if unmet else None
            if pinned is not None:
                # a level left unmet: its optimum lies on a face of the higher levels' constraints (and, for an
                # inequality level, its violated rows are at their least violation). Every row active there with
                # a positive multiplier keeps its value at any optimum of this level (KKT), so it is an equality
                # for the levels below: taken into the nullspace like an equality task, instead of leaving the
                # lower levels a feasible set as thin as the fix tolerance (degenerate for OSQP)
                rows = pinned @ proj if not proj_eye else pinned
                proj, proj_zero = self._shrink(proj, np.vstack([a_eff, rows]) if not ineq else rows)
                proj_eye = proj_eye and proj is self._eye
            elif not ineq:
                proj, proj_zero = self._shrink(proj, a_eff)
                proj_eye = proj_eye and proj is self._eye
        result.x = x_star
        result.solve_time_s = time.perf_counter() - start
        result.solve_cpu_s = time.thread_time() - cpu_start
        return result


    def _pinned_rows(self, k: int, s0: int, s1: int, x_star: np.ndarray) -> np.ndarray | None:
        """Rows (of the levels above and, for an inequality level, its own) active at level ``k``'s OSQP optimum
        with a multiplier above ``_PIN_DUAL`` of the largest; None when there is none. A bound below the value
        such a row keeps is raised to it."""
        hi_fixed = self._hi_fixed
        end = s1 if self.levels[k].kind == INEQ else s0
        if not end:
            return None
        y = self._solvers[k]._solver.solution.y[:end]
        top = float(y.max())
        if not top > 0.0:
            return None
        rows = self._a_all[:end]
        value = rows @ x_star
        margin = hi_fixed[:end] - value
        if end > s0:  # the level's own rows: bound b (their hi_fixed was just set to the achieved value + tol)
            margin[s0:] = self._b_all[s0:end] - value[s0:]
        mask = (y > _PIN_DUAL * top) & (margin <= _PIN_ACTIVE * self._fix_tol)
        if not mask.any():
            return None
        hi_fixed[:end][mask] = np.maximum(hi_fixed[:end][mask], value[mask])
        return rows[mask]

    def _unconstrained_optimum(
        self, k: int, a: np.ndarray, a_eff: np.ndarray, b_eff: np.ndarray, proj: np.ndarray, proj_eye: bool
    ) -> np.ndarray | None:
        """Level ``k``'s optimal step ``proj @ z`` ignoring the levels above, when it has a closed form.

        Equality level: ``z = (A_eff^T A_eff + reg I)^-1 A_eff^T b_eff`` (the level's objective with the
        slack eliminated). Inequality level made of the rows ``[I; -I]`` (a box, as the velocity and
        position limits are) with no equality level above: per joint, 0 inside the box, else the edge
        shrunk by ``1 / (1 + reg)`` (where slack and regularisation balance); None for an inverted box
        and for any other inequality level. Returns None when there is no closed form.
        """
        n = self.n
        if self.levels[k].kind == EQ:
            gram = a_eff.T @ a_eff
            gram.flat[:: n + 1] += self._reg
            _, z, info = _posv(gram, a_eff.T @ b_eff)
            if info != 0 or not math.isfinite(z.sum()):
                return None
            return z if proj_eye else proj @ z
        box = self._box[k]
        if box is None or not proj_eye:
            return None
        key = a.tobytes()
        if key != self._box_seen[k]:
            if not np.array_equal(a, box):
                return None
            self._box_seen[k] = key
        upper, lower = b_eff[:n], -b_eff[n:]
        if not (lower <= upper).all():
            return None
        return np.where(upper < 0.0, upper, np.where(lower > 0.0, lower, 0.0)) * (1.0 / (1.0 + self._reg))

    def _osqp_solve(
        self, k: int, lv: LevelSpec, a_eff: np.ndarray, b_eff: np.ndarray, proj: np.ndarray, proj_eye: bool,
        x_zero: bool, x_star: np.ndarray, result: HqpResult,
    ) -> np.ndarray | None:
        """Solve level ``k``'s QP with its kept, warm-started OSQP instance; ``z`` or None if it failed."""
        n = self.n
        s0, s1 = self._offsets_py[k], self._offsets_py[k + 1]
        a_all, hi_fixed = self._a_all, self._hi_fixed
        hi, ax = self._hi[k], self._ax[k]
        # Rows of the levels above: z = 0 stays feasible for them (x_star is their accepted solution).
        if x_zero:
            np.minimum(hi_fixed[:s0], _INF, out=hi[:s0])
        else:
            np.minimum(hi_fixed[:s0] - a_all[:s0] @ x_star, _INF, out=hi[:s0])
        solver = self._solvers[k]._solver  # the low-level object: osqp.OSQP.update/solve add ~50 us per call
        if lv.kind == EQ:
            gram = a_eff.T @ a_eff
            gram.flat[:: n + 1] += self._reg
            solver.update_data_vec(q=-(a_eff.T @ b_eff), l=None, u=hi)
            px = gram[self._triu]
            rows = s0
        else:
            np.minimum(b_eff, _INF, out=hi[s0:s1])
            solver.update_data_vec(q=None, l=None, u=hi)
            px = None
            rows = s1
        # Constraint values, column-major (CSC of the dense block): (A[:rows] @ proj) in Fortran order.
        if rows:
            if proj_eye:
                ax[: n * rows] = a_all[:rows].ravel(order="F")
            else:
                np.dot(proj.T, a_all[:rows].T, out=self._ax_block[k])
        # re-send (and refactorise) only what changed: the safety rows above the first equality level never do
        a_key = ax.tobytes()
        a_new = a_key != self._ax_sent[k]
        p_key = None if px is None else px.tobytes()
        p_new = p_key != self._px_sent[k]
        if a_new or p_new:
            solver.update_data_mat(P_x=px if p_new else None, P_i=None, A_x=ax if a_new else None, A_i=None)
            self._ax_sent[k], self._px_sent[k] = a_key, p_key
        solver.solve()
        z = solver.solution.x[:n]
        status = solver.info.status_val
        self._exact = status == _SOLVED
        if status not in _OK and status != _MAX_ITER or not math.isfinite(z.sum()):
            result.failed.append(f"{lv.name} ({solver.info.status})")
            return None
        if not self._exact:
            z = self._clip(lv, z, a_eff, b_eff, proj, proj_eye, hi[:s0])
            result.inexact.append(f"{lv.name} ({solver.info.status})")
        return z

    def _clip(self, lv: LevelSpec, z: np.ndarray, a_eff: np.ndarray, b_eff: np.ndarray, proj: np.ndarray,
              proj_eye: bool, room: np.ndarray) -> np.ndarray:
        """An unfinished OSQP iterate ``z`` made safe: the longest step ``t z`` (0 <= t <= 1) that keeps every row
        of the levels above within ``room`` (their bounds less their values at x_star, >= 0: z = 0 is feasible),
        taken when it lowers the level's objective, else 0 (the levels above are never bent by an unfinished
        solve; the level keeps what the step achieves)."""
        s0 = room.size
        t = 1.0
        if s0:
            change = self._a_all[:s0] @ (z if proj_eye else proj @ z)
            up = change > 0.0
            if up.any():
                t = min(1.0, float((np.maximum(room[up], 0.0) / change[up]).min()))
        if t <= 0.0:
            return np.zeros_like(z)
        z = t * z
        r, r0 = a_eff @ z - b_eff, -b_eff
        if lv.kind == INEQ:
            r, r0 = np.maximum(r, 0.0), np.maximum(r0, 0.0)
        return z if float(r @ r) + self._reg * float(z @ z) < float(r0 @ r0) else np.zeros_like(z)

def _norm(v: np.ndarray) -> float:
    """Euclidean norm of a vector (what np.linalg.norm computes, without its ~2 us of dispatch)."""
    return math.sqrt(float(v @ v))
