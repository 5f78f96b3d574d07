"""Excavator arm motion planning: planning goals -> validated controller targets, rejected before any motion.

* :meth:`ArmPlanner.change_pose` — joint angles, bucket-tip poses or position + theta_w targets (a big
  swing goes joint-space to the IK solution first, then a straight tip line to the goal);
* :meth:`ArmPlanner.excavate` — approach above the target, penetrate, drag towards the machine by
  ``offset``, curl and lift clear (one segment, as an operator curls while raising the boom; or curl,
  then lift);
* :meth:`ArmPlanner.release` — swing to the target angle (front held), open (dump) the bucket with its
  tip held over the release point.

Every target is checked here (finite, non-empty, reachable, inside the joint limits, above the
ground limit); failures raise :class:`~tms_model.excavator.codes.PlanningError` subclasses whose message
names the joint or the distance. The targets are consumed by :class:`tms_rc.excavator.controller.ArmController`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import read_schema, setting
from tms_model.excavator.codes import InvalidGoalError, JointLimitError, PlanningError
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.excavator.targets import CartesianTarget, JointTarget
from tms_model.geometry import wrap_angle

__all__ = ["PlannerConfig", "load_planner_config", "planner_config_path", "ArmPlanner"]


@dataclass(frozen=True)
class PlannerConfig:
    """Excavation/release geometry of an excavator kind (``config/tms_rp/<kind>_planner.yaml``)."""

    approach_height: float = setting(lo=0.0, doc="[m] the excavate's first point: the bucket tip this far above "
                                     "the target (sensing's approach record reads it: tms_sp.config)")
    penetrate_depth: float = 0.0
    drag_end_theta_w: float = 1.6
    drag_default: float = 1.0
    curl_theta_w: float = 2.6
    lift_height: float = 1.5
    curl_during_lift: float = 1.0
    release_open_bucket: float = -0.5
    release_theta_w: float = 0.3
    release_swing_in_open: float = 0.05
    joint_space_swing: float = 0.35
    dig_speed_scale: float = 0.5
    limit_margin: float = 0.005
    dig_joint_margin: float = 0.06
    continue_window_rad: float = 0.5
    curl_carry: float = setting(0.0, lo=0.0, doc="[m] how far past the drag's end the curl and lift still carries the "
                                "edge through the soil (measured: the design subtask ends its drags this much short "
                                "of a wall)")
    dig_measured: bool = setting(False, doc="the excavate's approach, penetrate and drag are reached only once the "
                                 "measured arm is there too, not on the prediction alone (the swing still lags at the "
                                 "approach; the soil's load slows the cylinders below the controller's model): the "
                                 "edge enters where planned and cuts to depth, the passes take longer")
    release_measured: bool = setting(False, doc="the release's open is reached only once the measured bucket is open, "
                                     "not on the prediction alone: the load is out before the next goal swings the "
                                     "bucket back (what an open bucket still holds falls along the way: over a "
                                     "design's apron on the plant)")


def planner_config_path(kind: str) -> Path:
    """``config/tms_rp/<kind>_planner.yaml``: the planning geometry of an excavator kind."""
    return Path(config_path("tms_rp", f"{kind}_planner.yaml"))


def load_planner_config(kind: str, path: str | Path | None = None) -> PlannerConfig:
    """The planning geometry of excavator ``kind`` (or of the file ``path``), read with :mod:`tms_common.schema`:
    unknown keys and non-numbers are errors naming the file, line and key.

    A file with ``base: <file name beside it>`` holds only the keys it changes in that file (a scenario's choices
    over the kind's planning file, which stays the one place for the rest); the base may not have a base itself.
    """
    file = Path(path) if path is not None else planner_config_path(kind)
    data, where = load_yaml(file)
    if not (isinstance(data, dict) and "base" in data):
        return read_schema(PlannerConfig, data, where)
    base_file = file.parent / str(data["base"])
    base_data, base_where = load_yaml(base_file)
    if isinstance(base_data, dict) and "base" in base_data:
        raise ConfigError(f"{base_file}: the base of {file} has a base of its own; one level only")
    read_schema(PlannerConfig, base_data, base_where)  # the base on its own, its errors with its lines
    # then the base with the changes, read with this file's lines: an error now is in one of the changes
    changes = {k: v for k, v in data.items() if k != "base"}
    return read_schema(PlannerConfig, {**base_data, **changes}, where)


def _finite(values: Any, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.size == 0:
        raise InvalidGoalError(f"{what} is empty")
    if not np.all(np.isfinite(arr)):
        raise InvalidGoalError(f"{what} contains NaN or infinity: {arr.tolist()}")
    return arr


class ArmPlanner:
    """Turns planning goals into controller targets after validating every one of them."""

    def __init__(self, kin: ExcavatorKinematics, cfg: PlannerConfig | None = None, ground_min_z: float = -2.5) -> None:
        self.kin = kin
        self.cfg = cfg or load_planner_config(kin.machine.kind)
        self.ground_min_z = ground_min_z

    # ------------------------------------------------------------------ validation helpers
    def _check_joints(self, q: np.ndarray, what: str) -> np.ndarray:
        self.kin.check_joint_limits(q, what=what)
        return q

    def _cartesian(self, position: Any, theta_w: float, what: str, **kw: Any) -> CartesianTarget:
        pos = _finite(position, f"{what} position")
        if pos.shape != (3,):
            raise InvalidGoalError(f"{what} position must have 3 coordinates, got {pos.tolist()}")
        th = float(_finite([theta_w], f"{what} theta_w")[0])
        if pos[2] < self.ground_min_z:
            raise InvalidGoalError(
                f"{what}: tip z {pos[2]:.3f} m is below the ground/dig limit {self.ground_min_z:.3f} m "
                f"({self.ground_min_z - pos[2]:.3f} m too deep)"
            )
        self.kin.ik_position_with_angle(pos, th)  # raises OutOfReachError / JointLimitError with the reason
        return CartesianTarget(pos, th, **kw)

    # ------------------------------------------------------------------ goals
    def change_pose(
        self,
        *,
        joint_names: list[str] | None = None,
        joint_points: list[list[float]] | None = None,
        poses: list[tuple[list[float], list[float]]] | None = None,
        positions_with_angle: list[tuple[list[float], float]] | None = None,
        current_q: np.ndarray | None = None,
        pass_through: bool = False,
        theta_w_tolerance: float = 0.0,
    ) -> list[JointTarget | CartesianTarget]:
        """Targets of one change_pose goal; exactly one of the three forms must be non-empty.

        ``pass_through`` makes the last target a via point too: the goal ends once the commands already
        sent bring the arm there (the controller's via tolerance, no wait for rest), for a goal the next
        one continues from (the paper tree's carry over the vessel, followed by the release).

        ``theta_w_tolerance`` [rad] (pose / position_with_angle targets): where the edge angle cannot be held
        at a target, the nearest holdable one (:meth:`feasible_theta_w`, as the excavate's approach picks it)
        if it lies within the tolerance; 0 = exactly the requested angle or the goal is rejected.

        Joint points may name a subset of the joints (others are held at ``current_q``); unknown names
        (other than the IK dummy ``bucket_end_joint``, which is ignored) are rejected.
        """
        given = [bool(joint_points), bool(poses), bool(positions_with_angle)]
        if sum(given) == 0:
            raise InvalidGoalError("change_pose goal is empty: no trajectory point, pose or position_with_angle")
        if sum(given) > 1:
            raise InvalidGoalError("change_pose goal mixes trajectory, pose_sequence and position_with_angle_sequence")
        tolerance = float(_finite([theta_w_tolerance], "theta_w_tolerance")[0])
        if tolerance < 0:
            raise InvalidGoalError(f"theta_w_tolerance {tolerance} rad is negative")
        targets: list[JointTarget | CartesianTarget] = []
        if joint_points:
            names = list(joint_names or [])
            for name in names:
                if name not in JOINTS and name != "bucket_end_joint":
                    raise InvalidGoalError(f"trajectory joint name {name!r} is not a front joint of the "
                                           f"{self.kin.machine.kind} {JOINTS}")
            base = np.asarray(current_q if current_q is not None else self.kin.home, dtype=float)
            for k, point in enumerate(joint_points):
                vals = _finite(point, f"trajectory point {k + 1}")
                if len(vals) != len(names):
                    raise InvalidGoalError(
                        f"trajectory point {k + 1} has {len(vals)} positions for {len(names)} joint names"
                    )
                q = base.copy()
                for name, v in zip(names, vals, strict=True):
                    if name in JOINTS:
                        q[JOINTS.index(name)] = v
                targets.append(JointTarget(self._check_joints(q, f"trajectory point {k + 1}"), f"joint pose {k + 1}"))
                base = q
        else:
            if poses:
                tips = [self.kin.pose_to_position_with_angle(_finite(pos, f"pose {k + 1} position"),
                                                             _finite(quat, f"pose {k + 1} orientation"))
                        for k, (pos, quat) in enumerate(poses)]
                what = "pose"
            else:
                tips = list(positions_with_angle or [])
                what = "position_with_angle"
            q_prev = None if current_q is None else _finite(current_q, "current joint state")
            swung = False
            for k, (pos, th) in enumerate(tips):
                if tolerance > 0:
                    th = self._angle_within(pos, th, tolerance, f"{what} {k + 1}")
                final = self._cartesian(pos, th, f"{what} {k + 1}", label=f"{what.split('_')[0]} {k + 1}")
                q_goal = self.kin.ik_position_with_angle(final.position, final.theta_w)
                swung = (
                    q_prev is not None
                    and abs(math.remainder(q_goal[0] - q_prev[0], 2 * math.pi)) > self.cfg.joint_space_swing
                )
                if swung:
                    # A big swing: joint-space motion to the IK solution (as MoveIt plans a pose goal), the
                    # straight tip line only for the final approach. A straight line across a swing is
                    # slow (the tip speed limit over the whole chord) and cuts past the cab.
                    q_goal[0] = q_prev[0] + math.remainder(q_goal[0] - q_prev[0], 2 * math.pi)
                    targets.append(JointTarget(self._check_joints(q_goal, f"{what} {k + 1}"), final.label, via=True))
                targets.append(final)
                q_prev = q_goal
            if pass_through and swung:
                # the joint-space move already ends at the goal's IK pose; the straight final approach is
                # there for the goal precision, which a pass-through goal does not wait for (it would
                # only add its 0.5 s minimum duration)
                targets.pop()
        if pass_through:
            targets[-1] = replace(targets[-1], via=True)
        return self._label(targets, "moving")

    def _angle_within(self, position: Any, theta_w: float, tolerance: float, what: str) -> float:
        """The holdable edge angle nearest ``theta_w`` at ``position``; JointLimitError if it is further than
        ``tolerance`` (OutOfReachError if no angle reaches the point)."""
        pos = _finite(position, f"{what} position")
        th = float(_finite([theta_w], f"{what} theta_w")[0])
        if pos.shape != (3,):
            raise InvalidGoalError(f"{what}: position must have 3 coordinates, got {pos.tolist()}")
        held = self.feasible_theta_w(pos, th)
        if abs(held - th) > tolerance:
            raise JointLimitError(
                f"{what}: theta_w {th:.3f} rad cannot be held at {pos.round(3).tolist()}; the nearest holdable "
                f"angle {held:.3f} rad is {abs(held - th):.3f} rad off, more than theta_w_tolerance {tolerance:.3f}"
            )
        return held

    def end_joints(self, targets: list[JointTarget | CartesianTarget]) -> np.ndarray:
        """The joint angles the last of ``targets`` puts the arm at (IK of a Cartesian one)."""
        last = targets[-1]
        if isinstance(last, JointTarget):
            return np.asarray(last.q, dtype=float).copy()
        return self.kin.ik_position_with_angle(last.position, last.theta_w, check_limits=False)

    def pass_through_end(self, targets: list[JointTarget | CartesianTarget]) -> np.ndarray | None:
        """Where a goal of ``targets`` that succeeded leaves the arm going, if it ends at a pass-through
        point (its last target is a via point), for :meth:`start_state`; None if it ends at rest."""
        return self.end_joints(targets) if targets[-1].via else None

    def start_state(self, measured_q: np.ndarray | None, pass_through_end: np.ndarray | None) -> np.ndarray | None:
        """The joint state to plan the next goal from.

        A goal that ended at a pass-through point (excavate's lift, release's open, a ``pass_through``
        change_pose) ended before the arm got there: the measured joints still lag by the commands in
        flight (on the swing ~1.3 s of dead time and lag, 0.2-0.3 rad at the end of a carry), while the
        controller starts the next goal's first segment from where they will be. Planning from the lagging
        measurement would aim the release's open from a front pose the arm is leaving and add a swing
        back. So the next plan starts from that end point, as long as every measured joint is within
        ``continue_window_rad`` of it (the arm is on its way there); otherwise from the measurement.
        """
        if pass_through_end is None or measured_q is None:
            return measured_q
        d = np.asarray(measured_q, dtype=float) - pass_through_end
        d[0] = math.remainder(float(d[0]), 2 * math.pi)
        if float(np.max(np.abs(d))) <= self.cfg.continue_window_rad:
            return np.asarray(pass_through_end, dtype=float).copy()
        return measured_q

    @staticmethod
    def _label(targets: list, prefix: str) -> list:
        n = len(targets)
        return [type(t)(**{**t.__dict__, "label": f"{prefix} {i + 1}/{n}"}) for i, t in enumerate(targets)]

    def _holds(self, position: np.ndarray, theta_w: float, joint_margin: float) -> bool:
        try:
            q = self.kin.ik_position_with_angle(position, theta_w, check_limits=False)
        except PlanningError:
            return False
        return self.kin.limits.violation(q, margin=-joint_margin) is None  # margin < 0: inside

    def feasible_theta_w(self, position: np.ndarray, theta_w: float) -> float:
        """``theta_w`` moved to the nearest angle the arm can hold at ``position`` with every joint at least
        ``limit_margin`` inside its limits (the controller keeps its own margin from the limits).

        Raises OutOfReachError / JointLimitError (with the reason) when no angle reaches the point.
        """
        m = self.cfg.dig_joint_margin
        if self._holds(position, theta_w, m):
            return float(theta_w)
        grid = np.arange(-math.pi / 2, 3 * math.pi / 2, 0.005)
        ok = np.array([th for th in grid if self._holds(position, float(th), m)])
        if ok.size == 0:
            self.kin.ik_position_with_angle(position, theta_w)  # raises with the reason
            raise JointLimitError(f"no bucket angle keeps every joint {m} rad inside its limits at {position.tolist()}")
        return float(ok[np.argmin(np.abs(ok - theta_w))])

    def excavate(self, position: Any, theta_w: float, offset: float = 0.0) -> list[JointTarget | CartesianTarget]:
        """approach -> penetrate -> drag -> curl + lift (or curl -> lift) at one excavation target, all validated.

        ``position`` is the bucket-tip point the excavation penetrates to (the excavator's base frame; tms_sp
        writes ``surface - penetration_depth``), ``penetrate_depth`` of the config goes that much deeper.
        ``theta_w`` is the edge angle at entry (approach and penetrate); where the arm cannot hold that
        angle at the point it is moved to the nearest reachable one (the excavation still happens at the
        requested point). The drag runs ``offset`` (or ``drag_default``) towards the machine while the
        edge turns to at least ``drag_end_theta_w`` (the bucket keeps its soil once out of the ground),
        then the bucket curls to ``curl_theta_w`` and lifts ``lift_height``: in one segment with
        ``curl_during_lift`` (the edge angle stays above the spill angle from the drag on, so nothing falls
        out; 2.1 s less per pass in ``python -m tests.bench load_pass``), else curl in place, then lift.
        """
        cfg = self.cfg
        pos = _finite(position, "excavate position")
        if pos.shape != (3,):
            raise InvalidGoalError(f"excavate position must have 3 coordinates, got {pos.tolist()}")
        th = float(_finite([theta_w], "excavate theta_w")[0])
        drag = float(_finite([offset], "excavate offset")[0]) or cfg.drag_default
        if drag < 0:
            raise InvalidGoalError(f"excavate offset {drag} is negative (drag length towards the machine)")
        radial = pos[:2] - self.kin.swing_origin[:2]
        dist = float(np.linalg.norm(radial))
        if dist < 1e-6:
            raise InvalidGoalError("excavate position is on the swing axis")
        inward = -radial / dist
        bottom = pos - np.array([0.0, 0.0, cfg.penetrate_depth])
        if bottom[2] < self.ground_min_z:
            raise InvalidGoalError(
                f"excavate: tip z {bottom[2]:.3f} m is below the ground/dig limit {self.ground_min_z:.3f} m"
            )
        above = bottom + np.array([0.0, 0.0, cfg.approach_height])
        dragged = bottom + np.append(inward * drag, 0.0)
        lifted = dragged + np.array([0.0, 0.0, cfg.lift_height])
        th_in = self.feasible_theta_w(bottom, th)
        th_above = self.feasible_theta_w(above, th_in)
        th_drag = self.feasible_theta_w(dragged, max(th_in, cfg.drag_end_theta_w))
        th_curl = self.feasible_theta_w(dragged, cfg.curl_theta_w)
        th_lift = self.feasible_theta_w(lifted, th_curl)
        dig = cfg.dig_speed_scale
        measured = cfg.dig_measured  # approach, penetrate and drag reached on the measured arm too
        q_above = self.kin.ik_position_with_angle(above, th_above)  # reason names joint/distance
        # lift clear is a pass-through point: the carry (next goal) goes on from where the arm will be
        lift = self._cartesian(lifted, th_lift, "lift", label="curl and lift" if cfg.curl_during_lift else "lift",
                               speed_scale=dig, via=True)
        curl = (
            [] if cfg.curl_during_lift else [self._cartesian(dragged, th_curl, "curl", label="curl", speed_scale=dig)]
        )
        return [
            JointTarget(q_above, "approach", measured=measured),
            self._cartesian(bottom, th_in, "penetrate", label="penetrate", speed_scale=dig, measured=measured),
            self._cartesian(dragged, th_drag, "drag", label="drag", speed_scale=dig, measured=measured),
            *curl,
            lift,
        ]

    def release(self, target_angle: float, current_q: np.ndarray) -> list[JointTarget | CartesianTarget]:
        """swing to ``target_angle`` with the front as it is, then open the bucket (dump).

        The bucket opens with its tip held where the swing left it (edge angle down to ``release_theta_w``,
        the rest of the front compensating), as an operator pulls the arm in while dumping: a bucket opened
        on its own joint sweeps its tip about a metre outwards and drops much of the load beyond a
        1.75 m wide vessel. Where the tip cannot be held, the bucket opens on its joint to
        ``release_open_bucket``. When the arm is already within ``release_swing_in_open`` of the angle
        (the carry left it over the vessel), there is no separate swing: the open segment swings the rest.
        """
        ang = float(_finite([target_angle], "release target_angle")[0])
        q = _finite(current_q, "current joint state").copy()
        q[0] = wrap_angle(ang)
        lim = self.kin.limits
        m = self.cfg.limit_margin
        q[1:] = np.clip(q[1:], lim.lower[1:] + m, lim.upper[1:] - m)
        tip = self.kin.tip_position(q)
        try:
            th_open = self.feasible_theta_w(tip, self.cfg.release_theta_w)
        except PlanningError:
            th_open = None
        if th_open is not None and th_open < self.kin.theta_w(q):
            # Joint-space (all joints on one spline, so the boom's low acceleration paces the bucket) to
            # the IK pose that has the tip where it was; pass-through precision: the soil only has to
            # land in the vessel, and it goes on falling while the next goal's swing is in its dead time.
            q_open = self.kin.ik_position_with_angle(tip, th_open)
            open_ = JointTarget(q_open, "open", via=True, measured=self.cfg.release_measured)
            if self._swing_only_nudges(current_q, q):
                return [open_]  # already over the vessel (the carry put it there): the open does the rest
            return [JointTarget(q, "swing", via=True), open_]
        opened = q.copy()
        opened[3] = max(self.cfg.release_open_bucket, lim.lower[3] + m)
        open_ = JointTarget(self._check_joints(opened, "open"), "open", measured=self.cfg.release_measured)
        return [open_] if self._swing_only_nudges(current_q, q) else [JointTarget(q, "swing"), open_]

    def _swing_only_nudges(self, current_q: Any, swung: np.ndarray) -> bool:
        """The release's swing moves the swing less than ``release_swing_in_open`` and nothing else: the
        open segment can carry it (a separate swing segment costs its minimum duration and, in the stack, the
        swing's dead time; a bigger swing must end before the bucket opens, or soil falls on the way)."""
        cur = np.asarray(current_q, dtype=float)
        return (abs(math.remainder(swung[0] - cur[0], 2 * math.pi)) <= self.cfg.release_swing_in_open
                and bool(np.allclose(swung[1:], cur[1:], atol=1e-9)))
