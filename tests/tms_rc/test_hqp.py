"""The strict-priority hierarchy: higher levels are met exactly, lower ones only in their nullspace."""

from __future__ import annotations

import numpy as np
import pytest

from tms_rc.excavator.hqp import HierarchicalQP, LevelSpec

BOX = (np.vstack([np.eye(2), -np.eye(2)]), np.ones(4))  # |x_i| <= 1


def make():
    return HierarchicalQP(
        2,
        [
            LevelSpec("box", "ineq", 4),
            LevelSpec("high", "eq", 1),
            LevelSpec("low", "eq", 1),
            LevelSpec("least", "eq", 2),
        ],
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


def _random_hierarchy(rng, closed_form):
    """The controller's shape on 4 joints: a coupling (pump-like) inequality, two boxes, equality tasks."""
    n = 4
    levels = [
        LevelSpec("pump", "ineq", 2**n),
        LevelSpec("velocity", "ineq", 2 * n),
        LevelSpec("position", "ineq", 2 * n),
        LevelSpec("task_1", "eq", 1),
        LevelSpec("task_3", "eq", 3),
        LevelSpec("least", "eq", n),
    ]
    return HierarchicalQP(n, levels, closed_form=closed_form)


def _random_tasks(rng, u_prev):
    n = 4
    signs = np.array([[1.0 if (i >> j) & 1 else -1.0 for j in range(n)] for i in range(2**n)])
    flow = np.array([2.0, 6.6, 2.7, 1.7])
    a_step = 0.08
    hi = np.minimum(1.0, u_prev + a_step)
    lo = np.maximum(-1.0, u_prev - a_step)
    box = np.vstack([np.eye(n), -np.eye(n)])
    return [
        (signs * flow, np.full(2**n, 4.0)),
        (box, np.concatenate([hi, -lo])),
        (box, rng.uniform(0.05, 2.0, 2 * n)),
        (rng.normal(size=(1, n)), rng.normal(scale=0.1, size=1)),
        (rng.normal(size=(3, n)), rng.normal(scale=0.1, size=3)),
        (np.eye(n), np.zeros(n)),
    ]


def test_closed_form_gives_the_osqp_optimum_and_osqp_still_solves_active_levels():
    # Two hierarchies over the same sequence of problems (a closed loop: u_prev = last solution, so the
    # acceleration box often excludes 0): one takes the closed form where it is provably the optimum,
    # the other solves every level with OSQP. Same solution within OSQP's tolerance, same slacks.
    rng = np.random.default_rng(5)
    fast, ref = _random_hierarchy(rng, True), _random_hierarchy(rng, False)
    u_ref = np.zeros(4)  # both see the reference's last solution as u_prev
    used: set[str] = set()
    osqp_solved: set[str] = set()
    compared = 0
    for _ in range(300):
        tasks = _random_tasks(rng, u_ref)
        r, r0 = fast.solve(tasks), ref.solve(tasks)
        assert not r0.closed_form
        u_ref = r0.x
        if r.failed or r0.failed or r.inexact or r0.inexact:  # OSQP unfinished on a random level: not comparable
            continue
        compared += 1
        used.update(r.closed_form)
        osqp_solved.update(k for k, v in r.solved.items() if v and k not in r.closed_form)
        assert np.allclose(r.x, r0.x, atol=5e-3), (r.x, r0.x)
        for name, s in r.slack.items():
            assert s <= r0.slack.get(name, np.inf) + 5e-3, (name, s, r0.slack)
        # the limits hold (pump within its fix tolerance, box exactly up to the regularisation pull)
        flow = np.array([2.0, 6.6, 2.7, 1.7]) @ np.abs(r.x)
        assert flow <= 4.0 + 1e-3
    assert compared >= 240
    # both paths are exercised: closed form for boxes and equality tasks, OSQP when limits are active
    assert {"velocity", "task_1", "task_3"} <= used
    assert {"task_3"} <= osqp_solved


def test_closed_form_not_taken_when_a_higher_limit_is_active():
    # high box |x_i| <= 1; the task wants x0 = 3: its unconstrained optimum breaks the box -> OSQP, x0 = 1
    h = HierarchicalQP(2, [LevelSpec("box", "ineq", 4), LevelSpec("task", "eq", 1)])
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [3.0])])
    assert "task" not in r.closed_form and r.solved["task"]
    assert r.x[0] == pytest.approx(1.0, abs=2e-4)
    # inside the box the closed form is the optimum: x0 = 0.5 / (1 + reg)
    r = h.solve([BOX, (np.array([[1.0, 0.0]]), [0.5])])
    assert r.closed_form == ["task"]
    assert r.x[0] == pytest.approx(0.5 / (1 + 1e-4), abs=1e-9) and r.x[1] == 0.0


def test_box_level_closed_form_is_the_nearest_point_and_inverted_box_goes_to_osqp():
    h = HierarchicalQP(2, [LevelSpec("box", "ineq", 4)])
    # box 0.2 <= x0 <= 0.5, -0.3 <= x1 <= 0.4: nearest point to 0 is (0.2, 0), pulled in by the regularisation
    r = h.solve([(BOX[0], np.array([0.5, 0.4, -0.2, 0.3]))])
    assert r.closed_form == ["box"]
    assert r.x == pytest.approx([0.2 / (1 + 1e-4), 0.0], abs=1e-12)
    ref = HierarchicalQP(2, [LevelSpec("box", "ineq", 4)], closed_form=False).solve(
        [(BOX[0], np.array([0.5, 0.4, -0.2, 0.3]))]
    )
    assert r.x == pytest.approx(ref.x, abs=2e-4)
    # inverted box (0.5 <= x0 <= 0.2): no closed form, OSQP balances the two slacks at the middle
    r = h.solve([(BOX[0], np.array([0.2, 1.0, -0.5, 1.0]))])
    assert "box" not in r.closed_form and r.solved["box"]
    assert r.x[0] == pytest.approx(0.35, abs=2e-3)


def test_unmet_level_against_a_coupling_limit_never_leaves_a_lower_level_infeasible():
    """A damper row the flow limit cannot always meet (as a binding or initially violated collision pair) and an
    equality task pushed against both: the unmet level's optimum lies on a face of the limits, met by OSQP only
    within its eps. Every lower level must still be solvable (the levels above relaxed to what they achieved, the
    rows active at the unmet optimum kept for the levels below), and the limits must hold. Before that, about
    40 % of these steps ended "primal infeasible" / "maximum iterations reached" on the levels below."""
    n = 4
    signs = np.array([[1.0 if (i >> j) & 1 else -1.0 for j in range(n)] for i in range(2**n)])
    flow = signs * np.array([1.0, 3.2, 2.0, 1.5])
    levels = [LevelSpec("flow", "ineq", 2**n), LevelSpec("damper", "ineq", 1), LevelSpec("task", "eq", 1),
              LevelSpec("low", "eq", 3), LevelSpec("least", "eq", n)]
    tol = 1e-5
    h = HierarchicalQP(n, levels, eps=1e-6, fix_tolerance=tol, regularisation=1e-6, max_iter=2000)
    rng = np.random.default_rng(0)
    unmet = 0
    for _ in range(100):
        damper = (rng.normal(size=(1, n)), np.array([rng.uniform(-0.2, 0.5)]))
        task = (rng.normal(size=(1, n)), np.array([rng.normal(scale=3.0)]))
        tasks = [(flow, np.ones(2**n)), damper, task, (rng.normal(size=(3, n)), rng.normal(size=3)),
                 (np.eye(n), np.zeros(n))]
        r = h.solve(tasks)
        assert not r.failed, r.failed
        assert (flow @ r.x).max() <= 1.0 + 3 * tol  # the highest level holds (fix tolerance per level below)
        # the levels below never bent the damper or the task: their slack is what the hierarchy cut there gives
        top = HierarchicalQP(n, levels[:3], eps=1e-6, fix_tolerance=tol, regularisation=1e-6).solve(tasks[:3])
        assert r.slack["damper"] <= top.slack["damper"] + 1e-4
        assert r.slack["task"] <= top.slack["task"] + 1e-3
        unmet += r.slack["task"] > 1e-3
    assert unmet > 30  # the task was cut by the limits on many steps: the case really ran
