"""The strict-priority hierarchy: higher levels are met exactly, lower ones only in their nullspace."""

from __future__ import annotations

import numpy as np
import pytest

from tms_rc.zx200.hqp import HierarchicalQP, LevelSpec

BOX = (np.vstack([np.eye(2), -np.eye(2)]), np.ones(4))  # |x_i| <= 1


def make():
    return HierarchicalQP(
        2, [LevelSpec("box", "ineq", 4), LevelSpec("high", "eq", 1), LevelSpec("low", "eq", 1), LevelSpec("least", "eq", 2)]
    )


def test_conflicting_tasks_higher_exact_lower_best_effort():
    h = make()
    # high: x0 = 0.5; low: x0 + x1 = 3 (conflicts with the box) -> best: x1 = 1 at the box edge
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [0.5]), (np.array([[1.0, 1.0]]), [3.0]), (np.eye(2), np.zeros(2))])
    assert r.x[0] == pytest.approx(0.5, abs=2e-4)
    assert r.x[1] == pytest.approx(1.0, abs=2e-4)
    assert r.slack["high"] < 1e-4 and r.slack["low"] == pytest.approx(1.5, abs=1e-3)


def test_weighted_sum_would_differ_but_hierarchy_does_not_bend():
    # high wants x0 = 0.5, low wants x0 = 2 (directly contradicting): x0 must stay 0.5, x1 free -> least motion 0
    h = make()
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [0.5]), (np.array([[1.0, 0.0]]), [2.0]), (np.eye(2), np.zeros(2))])
    assert r.x[0] == pytest.approx(0.5, abs=2e-4)
    assert abs(r.x[1]) < 1e-3
    assert not r.failed


def test_limits_hold_for_every_random_problem_and_warm_start_keeps_up():
    h = make()
    rng = np.random.default_rng(0)
    for _ in range(300):
        a_hi, a_lo = rng.normal(size=(1, 2)), rng.normal(size=(1, 2))
        b_hi, b_lo = rng.normal(scale=3, size=1), rng.normal(scale=3, size=1)
        r = h.solve([BOX, (a_hi, b_hi), (a_lo, b_lo), (np.eye(2), np.zeros(2))])
        assert np.all(np.abs(r.x) <= 1 + 2e-4), r
        # the high task is met exactly whenever it is feasible inside the box
        ref = HierarchicalQP(2, [LevelSpec("box", "ineq", 4), LevelSpec("high", "eq", 1)]).solve([BOX, (a_hi, b_hi)])
        assert abs(float((a_hi @ r.x)[0] - b_hi[0])) <= abs(float((a_hi @ ref.x)[0] - b_hi[0])) + 1e-3


def test_broken_lower_level_is_dropped_not_propagated():
    h = make()
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [0.5]), (np.array([[np.nan, 1.0]]), [1.0]), (np.eye(2), np.zeros(2))])
    assert "low" in r.failed
    assert r.x[0] == pytest.approx(0.5, abs=2e-4) and abs(r.x[1]) < 1e-3


def test_infeasible_inequality_level_keeps_higher_equality():
    # high: x0 = 0.9; low inequality x0 <= -1 (impossible together): x0 stays 0.9
    h = HierarchicalQP(2, [LevelSpec("box", "ineq", 4), LevelSpec("high", "eq", 1), LevelSpec("low", "ineq", 1)])
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [0.9]), (np.array([[1.0, 0.0]]), [-1.0])])
    assert r.x[0] == pytest.approx(0.9, abs=2e-4)
    assert r.slack["low"] == pytest.approx(1.9, abs=1e-3)


def test_bad_construction_is_refused():
    with pytest.raises(ValueError, match="kind"):
        HierarchicalQP(2, [LevelSpec("x", "soft", 1)])  # type: ignore[arg-type]
