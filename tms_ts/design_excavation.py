"""Excavation to a stored design surface, pass by pass: the pure core of the design subtask (no rclpy, no store).

The subtask row (``tms_ts.subtask_specs``, the ``*_excavate_design`` row) reads a record naming a design (tms_db
collection ``design``), the excavator's base pose on the map and optionally a fixed dump point; the subtask server
then calls :meth:`DesignExcavation.step` once per pass with the newest stored design document and the newest sensed
terrain (the dynamic heightmap), and runs the goals it answers through the original's planning actions:

1. ``excavate`` (TmsRpZx200ExcavateSimple's ``position_with_angle``): the pass's far end, the bucket-tip point the
   arm penetrates to, raised by the arm planner's ``penetrate_depth`` (which it goes deeper) so that the edge
   reaches the pass's edge height; ``offset`` the pass's length (the arm planner drags radially toward the swing
   axis, the direction the pass planner cuts in); ``theta_w`` the record's entry edge angle;
2. ``change_pose`` (position_with_angle, ``pass_through``): the tip ``dump_height`` over the dump place, bucket
   closed (``DUMP_THETA_W``, the paper's release pose); over a fixed dump place (the record's) ``dump_height`` counts
   from the highest sensed ground within a bucket width of it when the terrain covers it, else from the record's
   ``dump_z``: the spoil heap grows there (3.2 m high after 31 passes of the trench, which buried a bucket opening
   at 1.5 m over the ground and failed the release);
3. ``release`` (TmsRpZx200ReleaseSimple): the swing angle of the dump place from the swing axis; the bucket opens.

Points of the goals are the excavator's base frame (as the original's targets): the map point moved by the base
pose (x, y, yaw; heights relative to the base's ``z``): the record's, or with ``base_measured`` the one the server
measured when the subtask began (:func:`base_from_swing_centre`). The step answers :class:`Done` instead when the pass
planner stops: ``ok`` when it says the surface is within tolerance (with the record's ``scope`` ``reachable`` also
when nothing reachable from the base is worth a pass: the tree moves the machine to its next base pose), else a
failure whose message names the design, the passes done and the planner's reason (nothing reachable, no place to
dump, ...). A cell a pass lowered by less than ``FUTILE_SHARE`` of what it planned there (judged on the next
terrain) counts as passed over; a cell passed over ``FUTILE_PASSES`` times is left out of the passes planned after it
(the planner's ``skip``: a strip the bucket does not reach into, at a wall or at the edge of its reach, would otherwise
be planned again and again until ``max_passes``), and the answers name how many were left. The cells a pass did
lower tell how deep the edge really went: the median of their heights after it less the heights planned; where that
is below the plan (the arm under the soil's load going deeper than asked: a cut below the design cannot be undone),
the excavate's edge is aimed that much higher in the passes after (``edge_offset``, half of each pass's median added,
between 0 and ``EDGE_OFFSET_MAX``); a pass left above its plan is cut again by the next one and lowers it no
further. A design document that is wrong, a terrain that does not cover the design's area, or more than
``max_passes`` passes end it as a failure naming the design too.
Machine-independent: the machine's description gives the bucket, the reach and the swing origin; the arm planner's
settings of its kind give ``penetrate_depth``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tms_common.errors import TmsError
from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_rp.arm.planner import load_planner_config
from tms_rp.excavation.design import Design, DesignError, GridLike, SurfaceError, cell_centres
from tms_rp.excavation.planner import BasePose, Pass, PassPlanner, PlannerSettings
from tms_ts.plans import POSITION_WITH_ANGLE, AnglePlan, ChangePosePlan, DesignPlan, ExcavatePlan

__all__ = ["DUMP_THETA_W", "DUMP_THETA_W_TOLERANCE", "Done", "PassGoals", "DesignExcavation", "base_from_swing_centre",
           "ground_top", "standing_pose", "to_base"]

#: [rad] the edge angle the bucket is carried over the dump place with (85 deg, bucket closed: the paper's release pose)
#: a cell a pass lowered by less than this share of the depth it planned there was passed over ...
FUTILE_SHARE = 0.2
#: ... and a cell passed over this many times is not planned again (by this run)
FUTILE_PASSES = 2
#: [m] the most the excavate's edge is aimed above a pass's planned height for the depth the cuts overshot
EDGE_OFFSET_MAX = 0.1
#: cells a pass lowered, at least, for its median to count
EDGE_CELLS_MIN = 20
DUMP_THETA_W = 1.483530
#: [rad] where that angle cannot be held over the dump place, the nearest holdable one within this
DUMP_THETA_W_TOLERANCE = 0.5


@dataclass(frozen=True)
class Done:
    """The design subtask ends: ``ok`` (within tolerance) or a failure; ``message`` names the design."""

    ok: bool
    message: str
    error: SurfaceError | None = None


@dataclass(frozen=True)
class PassGoals:
    """One pass as downstream goals, in order: (``what``, plan) with what ``excavate``, ``change_pose``,
    ``release``; ``cut`` the pass planned (map frame), ``number`` its count from 1."""

    goals: tuple[tuple[str, Any], ...]
    cut: Pass = field(repr=False)
    number: int
    error: SurfaceError = field(repr=False)


def to_base(base: BasePose, x: float, y: float, z: float) -> tuple[float, float, float]:
    """A map point in the base frame of an excavator whose base_link stands at ``base`` (z relative to ``base.z``)."""
    dx, dy = x - base.x, y - base.y
    c, s = math.cos(base.yaw), math.sin(base.yaw)
    return c * dx + s * dy, -s * dx + c * dy, z - (base.z or 0.0)


def _grid_key(terrain: GridLike) -> tuple:
    return (terrain.x_min, terrain.y_min, terrain.x_max, terrain.y_max, np.shape(terrain.z))


def base_from_swing_centre(machine: Any, x: float, y: float, yaw: float, z: float) -> BasePose:
    """The base pose (base_link on the map, ground ``z``) of an excavator whose swing centre stands at map (x, y)
    with heading ``yaw`` (what its RTK GNSS and azimuth report: com3_can's ``odom_pose``); the swing centre's offset
    from base_link comes from the machine's description."""
    o = ExcavatorKinematics(machine).swing_origin
    c, s = math.cos(yaw), math.sin(yaw)
    return BasePose(x - (c * o[0] - s * o[1]), y - (s * o[0] + c * o[1]), yaw, z)


#: [m] how far the measured swing centre may spread (1 sigma) while the base pose is measured: more is a machine that
#: moves (RTK noise is ~1 cm)
STANDING_SIGMA_M = 0.03
#: [rad] the same for the heading
STANDING_SIGMA_RAD = 0.01


def standing_pose(samples: list[tuple[float, float, float]], who: str) -> tuple[float, float, float]:
    """The mean (x, y, yaw) of pose samples of a machine standing still (yaw averaged on the circle); DesignError
    naming ``who`` when there are fewer than 3 or they spread like a machine that moves."""
    if len(samples) < 3:
        raise DesignError(f"{who}: {len(samples)} pose sample(s), at least 3 needed")
    a = np.asarray(samples, dtype=float)
    yaw = math.atan2(float(np.sin(a[:, 2]).mean()), float(np.cos(a[:, 2]).mean()))
    dyaw = np.angle(np.exp(1j * (a[:, 2] - yaw)))
    sx, sy, syaw = float(a[:, 0].std()), float(a[:, 1].std()), float(dyaw.std())
    if max(sx, sy) > STANDING_SIGMA_M or syaw > STANDING_SIGMA_RAD:
        raise DesignError(f"{who}: the machine is not standing still (1 sigma x {sx:.3f} m, y {sy:.3f} m, yaw "
                          f"{syaw:.4f} rad over {len(samples)} samples; at most {STANDING_SIGMA_M} m, "
                          f"{STANDING_SIGMA_RAD} rad)")
    return float(a[:, 0].mean()), float(a[:, 1].mean()), yaw


def ground_top(terrain: GridLike, x: float, y: float, radius: float) -> float | None:
    """The highest ``terrain`` cell whose centre is within ``radius`` of (x, y) (the heightmaps' convention: row 0
    the north edge); None when no cell centre is (the point outside the sensed terrain)."""
    z = np.asarray(terrain.z, dtype=float)
    xs, ys = cell_centres(terrain)
    near = (xs - x) ** 2 + (ys - y) ** 2 <= radius * radius
    vals = z[near & np.isfinite(z)]
    return float(vals.max()) if vals.size else None


class DesignExcavation:
    """One run of a design subtask (see the module docstring): call :meth:`step` with each fresh terrain."""

    def __init__(self, plan: DesignPlan, machine: Any, settings: PlannerSettings | None = None,
                 base: BasePose | None = None) -> None:
        self.plan = plan
        self.who = f"design {plan.design!r}"
        # the arm's excavate drags the edge level over the whole bucket width: the passes are planned as that sweep
        # (clipped strips cut the trench's walls and apron on the plant: tms_rp/excavation/README.md)
        # with the record's fixed dump place the bucket never fills the design's low cells, so their room must not
        # cap the passes (on the plant: 0.024 m3 a pass once the first passes had left 3 cm dips)
        try:
            arm = load_planner_config(machine.kind)
            # the reach the arm planner grants a dig target: joints its dig margin inside their limits (a pass beyond
            # it failed the excavate goal at 8.7 m: "no bucket angle keeps every joint 0.06 rad inside its limits")
            # each seed's band also moved sideways by half a cell of the sensed heightmaps (0.05 m), so the bucket's
            # side can run along a wall (a trench as wide as the bucket is cut in one band only so)
            settings = settings or PlannerSettings(level_sweep=True, fill=plan.dump is None,
                                                   joint_margin=float(arm.dig_joint_margin), lateral_step=0.025)
            self.planner = PassPlanner(machine, settings)
            self.penetrate_depth, self.curl_carry = float(arm.penetrate_depth), float(arm.curl_carry)
        except TmsError as exc:
            raise DesignError(f"{self.who}: machine {getattr(machine, 'kind', machine)!r} cannot excavate it: "
                              f"{exc}") from None
        if plan.base_measured and base is None:
            raise DesignError(f"{self.who}: the record asks for the measured base pose (base_measured); none given")
        if base is not None and not plan.base_measured:
            raise DesignError(f"{self.who}: the record fixes the base pose; a measured one is not taken beside it")
        b = plan.base
        self.base = base or BasePose(float(b["x"]), float(b["y"]), float(b["yaw"]), float(b.get("z", 0.0)))
        self.passes = 0
        self.volume = 0.0  # [m^3 bank] planned volume of the passes sent
        self.first_error: SurfaceError | None = None
        # the last pass sent, with its cells' heights then; per cell the passes that did not work it
        self._sent: tuple[Pass, np.ndarray, tuple] | None = None
        self._futile: np.ndarray | None = None
        self.edge_offset = 0.0  # [m] the excavate's edge aimed this far above each pass's planned height

    def _covered(self, design: Design, terrain: GridLike) -> str | None:
        xs = [p[0] for p in design.area]
        ys = [p[1] for p in design.area]
        if (min(xs) < terrain.x_min or max(xs) > terrain.x_max or min(ys) < terrain.y_min
                or max(ys) > terrain.y_max):
            return (f"{self.who}: its area x [{min(xs):g}, {max(xs):g}] y [{min(ys):g}, {max(ys):g}] is not inside "
                    f"the sensed terrain (dynamic heightmap id {self.plan.terrain_id}) x [{terrain.x_min:g}, "
                    f"{terrain.x_max:g}] y [{terrain.y_min:g}, {terrain.y_max:g}]")
        return None

    def summary(self) -> str:
        return f"{self.passes} pass(es), {self.volume:.3f} m3 planned moved"

    def step(self, design_doc: Any, terrain: GridLike) -> Done | PassGoals:
        """The next pass's goals for the newest ``design_doc`` and ``terrain``, or :class:`Done`."""
        try:
            design = Design.from_dict(design_doc)
        except DesignError as exc:
            return Done(False, f"{self.who}: the stored document is refused: {exc}")
        if design.name != self.plan.design:
            return Done(False, f"{self.who}: the stored document is named {design.name!r}")
        uncovered = self._covered(design, terrain)
        if uncovered:
            return Done(False, uncovered)
        skip = self._judge_last(terrain)
        try:
            decision = self.planner.next_pass(terrain, design, self.base, skip=skip)
        except DesignError as exc:
            return Done(False, f"{self.who}: {exc}")
        err = decision.error
        if self.first_error is None:
            self.first_error = err
        figures = (f"MAE {err.mae * 100:.2f} cm, p95 {err.p95 * 100:.2f} cm, max {err.max_abs * 100:.2f} cm, "
                   f"{err.cut_volume:.3f} m3 above and {err.fill_volume:.3f} m3 below the design")
        if skip is not None and skip.any():
            figures += (f"; {int(skip.sum())} cell(s) left after {FUTILE_PASSES} passes each lowered them by less "
                        f"than {FUTILE_SHARE:.0%} of the depth planned")
        if decision.cut is None:
            if decision.reason.startswith("within tolerance"):
                return Done(True, f"{self.who} done after {self.summary()}: {decision.reason}", err)
            if self.plan.scope == "reachable" and decision.reason.startswith("nothing reachable"):
                b = self.base
                return Done(True, f"{self.who}: the part reachable from the base at ({b.x:.2f}, {b.y:.2f}, yaw "
                                  f"{b.yaw:.3f}) done after {self.summary()} ({figures}): {decision.reason}", err)
            return Done(False, f"{self.who}: the pass planner stops after {self.summary()} ({figures}): "
                               f"{decision.reason}", err)
        if self.passes >= self.plan.max_passes:
            return Done(False, f"{self.who}: not within tolerance after max_passes = {self.plan.max_passes} "
                               f"({self.summary()}; {figures})", err)
        cut = decision.cut
        self.passes += 1
        self.volume += cut.volume
        z = np.asarray(terrain.z, dtype=float)
        self._sent = (cut, z[cut.cells[:, 0], cut.cells[:, 1]].copy(), _grid_key(terrain))
        return PassGoals(self._goals(cut, terrain), cut, self.passes, err)

    def _judge_last(self, terrain: GridLike) -> np.ndarray | None:
        """Count the cells the last pass passed over (``terrain`` is the one after it: lowered by less than
        ``FUTILE_SHARE`` of the depth it planned there); the cells counted ``FUTILE_PASSES`` times (None: none yet;
        a terrain of another grid starts the counts over)."""
        key = _grid_key(terrain)
        if self._futile is None or self._futile.shape != np.shape(terrain.z):
            self._futile = np.zeros(np.shape(terrain.z), dtype=int)
        sent, self._sent = self._sent, None
        if sent is not None and sent[2] == key:
            cut, before, _ = sent
            rows, cols = cut.cells[:, 0], cut.cells[:, 1]
            after = np.asarray(terrain.z, dtype=float)[rows, cols]
            planned, lowered = before - cut.cut_to, before - after
            meant = planned > self.planner.settings.min_cut
            over = meant & (lowered < FUTILE_SHARE * planned)
            np.add.at(self._futile, (rows[over], cols[over]), 1)
            worked = meant & ~over
            if worked.sum() >= EDGE_CELLS_MIN:  # where the edge went against where it was sent (+ = left above)
                above = float(np.median(after[worked] - cut.cut_to[worked]))
                self.edge_offset = float(np.clip(self.edge_offset - 0.5 * above, 0.0, EDGE_OFFSET_MAX))
        skip = self._futile >= FUTILE_PASSES
        return skip if skip.any() else None

    def _goals(self, cut: Pass, terrain: GridLike) -> tuple[tuple[str, Any], ...]:
        p = self.plan
        sx, sy, sz = to_base(self.base, *cut.start)
        # the curl and lift goes on cutting past the drag's end: drag that much shorter (at most half the pass), so a
        # band that ends at the design's wall is not carried into the apron beyond it
        drag = max(cut.length - self.curl_carry, 0.5 * cut.length)
        excavate = ExcavatePlan({"x": sx, "y": sy, "z": sz + self.penetrate_depth + self.edge_offset,
                                 "theta_w": p.theta_w, "offset": drag})
        if p.dump is not None:
            dx, dy = float(p.dump["x"]), float(p.dump["y"])
            dz = float(p.dump.get("z", cut.dump[2]))
            top = ground_top(terrain, dx, dy, self.planner.bucket_width)
            if top is not None:
                dz = max(dz, top)
        else:
            dx, dy, dz = cut.dump
        bx, by, bz = to_base(self.base, dx, dy, dz + p.dump_height)
        carry = ChangePosePlan(POSITION_WITH_ANGLE, pwa={"x": bx, "y": by, "z": bz, "theta_w": DUMP_THETA_W},
                               pass_through=True, theta_w_tolerance=DUMP_THETA_W_TOLERANCE)
        ox, oy = float(self.planner.kin.swing_origin[0]), float(self.planner.kin.swing_origin[1])
        release = AnglePlan("release", math.atan2(by - oy, bx - ox))
        return ("excavate", excavate), ("change_pose", carry), ("release", release)
