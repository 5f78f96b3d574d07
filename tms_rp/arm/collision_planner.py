"""Collision-aware excavator arm planning: the ``_plan`` variants of change_pose and excavate_simple.

:class:`CollisionPlanner` takes the targets :class:`~tms_rp.arm.planner.ArmPlanner` plans and validates, and
checks every configuration along them, densely (no joint moves more than ``path_step_rad`` between two checked
configurations), against the padded collision objects (:mod:`tms_rp.arm.collision`), the way the arm controller
executes them: a joint target as a straight line in joint space (all joints on one spline), a Cartesian target as a
straight tip line with the edge angle turning linearly (the IK of every sample).

* The start pose, and the end of every target, in collision: refused (:class:`CollisionError`, naming the object,
  its record and the link).
* A joint-space segment (change_pose's moves, excavate's approach) whose path collides is replaced by a detour:
  the direct line if it is free, else *over* the object, lowest lift level first (a blend of the start / goal front
  with the carry front of the config): one apex half way (raise while swinging in, lower while swinging out) if
  that is free, else raise, carry across at that height and lower onto the goal, the raise and the lower swinging
  as far as stays free. The carry keeps ``detour_margin`` more
  clearance (tracking error); every via corner is checked cut by the controller's via tolerance. Where the short
  swing has no detour, the long way round is tried. No detour: refused naming the object that blocks.
* A change_pose straight tip line that collides is replaced by the joint-space detour to its end; excavate's dig
  phases (penetrate, drag, curl, lift) are never re-planned: if they collide the goal is refused.

Pure Python; the action servers live in :mod:`tms_if_opera.nodes.zx200_planner`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from tms_model.excavator.codes import PlanningError
from tms_model.excavator.targets import CartesianTarget, JointTarget
from tms_rp.arm.collision import ArmCollisionModel, CollisionError, CollisionObject, Contact
from tms_rp.arm.planner import ArmPlanner

__all__ = ["CollisionPlanner", "Scene", "PathReport"]

Target = JointTarget | CartesianTarget


@dataclass(frozen=True)
class Scene:
    """What one goal is planned against: the objects and the link padding (configured default + record)."""

    objects: list[CollisionObject]
    padding: dict[str, float]


@dataclass
class PathReport:
    """What the last plan did (for the node's log and the tests): detours inserted, configurations checked,
    smallest clearance along the planned path [m] (inf: nothing within ArmCollisionModel.FAR)."""

    detours: list[str]
    checked: int = 0
    min_clearance: float = math.inf


def _order(n: int) -> list[int]:
    """0..n-1, coarse first (stride 16, 8, 4, 2, 1): a colliding path is usually found out in a few checks."""
    seen, out = set(), []
    for stride in (16, 8, 4, 2, 1):
        for i in range(0, n, stride):
            if i not in seen:
                seen.add(i)
                out.append(i)
    return out


class CollisionPlanner:
    """Collision-aware planning on top of :class:`ArmPlanner` (see the module docstring)."""

    def __init__(self, planner: ArmPlanner, model: ArmCollisionModel, via_tolerance_rad: float = 0.05) -> None:
        self.planner = planner
        self.kin = planner.kin
        self.model = model
        self.cfg = model.cfg
        self.via_tolerance_rad = via_tolerance_rad
        self.report = PathReport([])

    # ------------------------------------------------------------------ sampling and checks
    def _steps(self, delta: np.ndarray) -> int:
        return max(1, int(math.ceil(float(np.max(np.abs(delta))) / self.cfg.path_step_rad)))

    def joint_line(self, q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
        """Configurations from ``q_a`` to ``q_b`` (both included) on the joint-space line."""
        n = self._steps(q_b - q_a)
        s = np.linspace(0.0, 1.0, n + 1)[:, None]
        return q_a[None, :] + s * (q_b - q_a)[None, :]

    def tip_line(self, q_a: np.ndarray, target: CartesianTarget) -> np.ndarray:
        """Configurations along a straight tip line from the tip at ``q_a`` to ``target`` (edge angle linear)."""
        p_a, th_a = self.kin.tip_position(q_a), self.kin.theta_w(q_a)
        q_b = self.kin.ik_position_with_angle(target.position, target.theta_w, check_limits=False)
        n = max(self._steps(q_b - q_a), int(math.ceil(float(np.linalg.norm(target.position - p_a)) / 0.02)))
        out = [q_a]
        for s in np.linspace(0.0, 1.0, n + 1)[1:]:
            try:
                q = self.kin.ik_position_with_angle(
                    p_a + s * (target.position - p_a), th_a + s * (target.theta_w - th_a), check_limits=False
                )
            except PlanningError:
                continue  # the controller's own checks stop the arm there; nothing to check against objects
            q[0] = out[-1][0] + math.remainder(q[0] - out[-1][0], 2 * math.pi)
            out.append(q)
        return np.array(out)

    def end_q(self, q_from: np.ndarray, target: Target) -> np.ndarray:
        if isinstance(target, JointTarget):
            return np.asarray(target.q, dtype=float)
        q = self.kin.ik_position_with_angle(target.position, target.theta_w)
        q[0] = q_from[0] + math.remainder(q[0] - q_from[0], 2 * math.pi)
        return q

    def first_hit(self, qs: np.ndarray, scene: Scene, margin: float = 0.0) -> Contact | None:
        """The first (coarse-to-fine) configuration of ``qs`` in collision, or None when all are free."""
        for i in _order(len(qs)):
            self.report.checked += 1
            c = self.model.contact(qs[i], scene.objects, scene.padding, margin)
            if c.clearance < 0.0:
                return c
        return None

    def free(self, q_a: np.ndarray, q_b: np.ndarray, scene: Scene, margin: float = 0.0) -> Contact | None:
        """None when the joint-space line ``q_a`` -> ``q_b`` is free (with ``margin``), else the contact found."""
        return self.first_hit(self.joint_line(q_a, q_b), scene, margin)

    def free_inner(self, q_a: np.ndarray, q_b: np.ndarray, scene: Scene, margin: float,
                   near: float = 0.15) -> Contact | None:
        """As :meth:`free`, ``margin`` kept except within ``near`` [rad, every joint] of the ends (a goal or start
        beside an object has less)."""
        qs = self.joint_line(q_a, q_b)
        inner = np.array([min(np.max(np.abs(q - q_a)), np.max(np.abs(q - q_b))) > near for q in qs])
        return self.first_hit(qs[inner], scene, margin) if inner.any() else None

    def min_clearance(self, qs: Iterable[np.ndarray], scene: Scene) -> float:
        return min((self.model.contact(q, scene.objects, scene.padding).clearance for q in qs), default=math.inf)

    # ------------------------------------------------------------------ detours
    def _corner_cut_free(self, a: np.ndarray, corner: np.ndarray, b: np.ndarray, scene: Scene) -> bool:
        """The controller leaves a via corner once within ``via_tolerance_rad``: check the chord it may cut."""
        tol = self.via_tolerance_rad

        def towards(p: np.ndarray) -> np.ndarray:
            d = float(np.max(np.abs(p - corner)))
            return corner + (p - corner) * min(1.0, tol / d) if d > 1e-9 else corner

        return self.free(towards(a), towards(b), scene) is None

    def _carry(self) -> np.ndarray:
        lim = self.kin.limits
        m = self.planner.cfg.limit_margin
        return np.clip(np.asarray(self.cfg.carry_front, dtype=float), lim.lower[1:] + m, lim.upper[1:] - m)

    def _over(self, q_a: np.ndarray, q_b: np.ndarray, scene: Scene) -> list[np.ndarray] | None:
        """Raise, carry across, lower (see the module docstring); the waypoints after ``q_a`` or None."""
        carry = self._carry()
        margin = self.cfg.detour_margin
        levels = max(1, self.cfg.lift_levels)
        swing = q_b[0] - q_a[0]
        for level in range(1, levels + 1):
            lam = level / levels
            front_a = q_a[1:] + lam * (carry - q_a[1:])
            front_b = q_b[1:] + lam * (carry - q_b[1:])
            # one apex half way: raise while swinging in, lower while swinging out (2 segments, 1 via corner)
            apex = np.r_[q_a[0] + swing / 2, (front_a + front_b) / 2]
            if (self.free(q_a, apex, scene) is None and self.free(apex, q_b, scene) is None
                    and self.free_inner(q_a, apex, scene, margin) is None
                    and self.free_inner(apex, q_b, scene, margin) is None
                    and self._corner_cut_free(q_a, apex, q_b, scene)):
                return [apex, q_b]
            w1, w2 = np.r_[q_a[0], front_a], np.r_[q_b[0], front_b]
            if self.free(w1, w2, scene, margin) is not None:
                continue  # not high enough to carry across
            if self.free(q_a, w1, scene) is not None or self.free(w2, q_b, scene) is not None:
                continue
            # swing while raising / lowering, as far as it stays free: the carry then is shorter
            for frac in (0.4, 0.25, 0.1):
                cand = np.r_[q_a[0] + frac * swing, front_a]
                if self.free(q_a, cand, scene) is None and self.free(cand, w2, scene, margin) is None:
                    w1 = cand
                    break
            for frac in (0.4, 0.25, 0.1):
                cand = np.r_[q_b[0] - frac * swing, front_b]
                if (abs(cand[0] - q_a[0]) >= abs(w1[0] - q_a[0]) and self.free(cand, q_b, scene) is None
                        and self.free(w1, cand, scene, margin) is None):
                    w2 = cand
                    break
            if self._corner_cut_free(q_a, w1, w2, scene) and self._corner_cut_free(w1, w2, q_b, scene):
                return [w1, w2, q_b]
        return None

    def joint_path(self, q_a: np.ndarray, q_b: np.ndarray, scene: Scene, what: str) -> list[np.ndarray]:
        """Waypoints after ``q_a`` to ``q_b`` whose joint-space lines are free; CollisionError if none is found."""
        q_a, q_b = np.asarray(q_a, dtype=float), np.asarray(q_b, dtype=float)
        blocked = self.free(q_a, q_b, scene)
        if blocked is None:
            return [q_b]
        variants = [q_b]
        if math.isinf(self.kin.limits.lower[0]):  # continuous swing: the long way round too
            other = q_b.copy()
            other[0] += -2 * math.pi if q_b[0] > q_a[0] else 2 * math.pi
            variants.append(other)
        for k, goal in enumerate(variants):
            if k > 0 and self.free(q_a, goal, scene) is None:
                self.report.detours.append(f"{what}: swung the long way round, clear of {blocked.obj.describe()}")
                return [goal]
            path = self._over(q_a, goal, scene)
            if path is not None:
                way = " the long way round" if k else ""
                self.report.detours.append(f"{what}: over {blocked.obj.describe()}{way}")
                return path
        raise CollisionError(f"{what}: no collision-free path: the direct one is blocked by {blocked.obj.describe()} "
                             f"({blocked.describe()}), and no detour over it (lifted up to the carry front "
                             f"{np.round(self._carry(), 3).tolist()}) or the long way round is free")

    # ------------------------------------------------------------------ targets
    def secure(self, targets: list[Target], q_start: np.ndarray, scene: Scene,
               replaceable: Callable[[Target], bool]) -> list[Target]:
        """``targets`` with every colliding replaceable segment replaced by a free detour (see the module docstring)."""
        q = np.asarray(q_start, dtype=float)
        start = self.model.contact(q, scene.objects, scene.padding)
        if start.clearance < 0.0:
            raise CollisionError(f"start pose {np.round(q, 3).tolist()} is in collision: {start.describe()}")
        out: list[Target] = []
        for target in targets:
            q_end = self.end_q(q, target)
            end = self.model.contact(q_end, scene.objects, scene.padding)
            if end.clearance < 0.0:
                raise CollisionError(f"{target.label}: target {self._where(target, q_end)} is in collision: "
                                     f"{end.describe()}")
            qs = self.joint_line(q, q_end) if isinstance(target, JointTarget) else self.tip_line(q, target)
            hit = self.first_hit(qs, scene)
            if hit is None:
                out.append(target)
            elif replaceable(target):
                path = self.joint_path(q, q_end, scene, target.label)
                for w in path[:-1]:
                    out.append(JointTarget(w, target.label, speed_scale=target.speed_scale, via=True))
                out.append(JointTarget(path[-1], target.label, speed_scale=target.speed_scale, via=target.via))
                q_end = path[-1]
            else:
                raise CollisionError(f"{target.label}: the segment's path is in collision: {hit.describe()}")
            q = q_end
        return out

    def _where(self, target: Target, q: np.ndarray) -> str:
        if isinstance(target, CartesianTarget):
            return f"(tip {np.round(target.position, 3).tolist()}, theta_w {target.theta_w:.3f})"
        return f"(joints {np.round(q, 3).tolist()})"

    def path_of(self, targets: list[Target], q_start: np.ndarray) -> np.ndarray:
        """Every checked configuration of ``targets`` from ``q_start``, as the controller runs them (for tests)."""
        q = np.asarray(q_start, dtype=float)
        parts = [q[None, :]]
        for t in targets:
            qs = self.joint_line(q, self.end_q(q, t)) if isinstance(t, JointTarget) else self.tip_line(q, t)
            parts.append(qs[1:])
            q = qs[-1]
        return np.concatenate(parts)

    # ------------------------------------------------------------------ goals
    def change_pose(self, scene: Scene, *, current_q: np.ndarray | None, **goal: Any) -> list[Target]:
        """change_pose_plan: :meth:`ArmPlanner.change_pose` (same goal, same validation), made collision-free."""
        if current_q is None:
            raise PlanningError("change_pose_plan needs the arm's joint state to plan from; none received")
        self.report = PathReport([])
        targets = self.planner.change_pose(current_q=current_q, **goal)
        secured = self.secure(targets, current_q, scene, replaceable=lambda _t: True)
        secured = self.planner._label(secured, "moving") if len(secured) != len(targets) else secured
        if targets[-1].via and not secured[-1].via:
            secured[-1] = replace(secured[-1], via=True)
        self.report.min_clearance = self.min_clearance(self.path_of(secured, current_q), scene)
        return secured

    def excavate(self, scene: Scene, position: Any, theta_w: float, offset: float,
                 current_q: np.ndarray | None) -> list[Target]:
        """excavate_simple_plan: :meth:`ArmPlanner.excavate`, its approach made collision-free, its dig checked."""
        if current_q is None:
            raise PlanningError("excavate_simple_plan needs the arm's joint state to plan from; none received")
        self.report = PathReport([])
        targets = self.planner.excavate(position, theta_w, offset)
        q0 = np.asarray(current_q, dtype=float)
        approach = np.array(targets[0].q, dtype=float)
        approach[0] = q0[0] + math.remainder(approach[0] - q0[0], 2 * math.pi)  # the short way from where the arm is
        targets[0] = replace(targets[0], q=approach)
        secured = self.secure(targets, current_q, scene, replaceable=lambda t: t.label == "approach")
        self.report.min_clearance = self.min_clearance(self.path_of(secured, current_q), scene)
        return secured
