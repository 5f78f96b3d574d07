"""Excavator arm kinematics: a pinocchio model built from any excavator kind's description.

The chain is base_link -swing(z)-> body_link -boom(y)-> boom_link -arm(y)-> arm_link -bucket(y)->
bucket_link, with the bucket tip (``bucket_tip_xyz``) as an operational frame, as the zx200_ros2 URDF
has it; joint origins, limits and the tip come from ``config/machines/<kind>.yaml`` (see
:mod:`tms_model.machines`). Pinocchio gives forward kinematics and the Jacobians of the bucket tip and
the bucket pin that the arm controller uses.

theta_w (the seed paper's bucket-edge angle to the ground plane) is the angle of the bucket pin ->
bucket tip line below the horizontal x-y plane, in the vertical plane of the front: 0 = edge
horizontal pointing away from the machine, +pi/2 = tip straight down, negative = tip above the pin.
Because boom, arm and bucket all turn about parallel y axes, theta_w = boom + arm + bucket + c
(c = 0 for the ZX200, whose zero pose is "everything straight and horizontal"), so its Jacobian is
the constant row [0, 1, 1, 1].

Inverse kinematics of (tip position, theta_w) is closed-form: swing from the tip bearing (with the
front's lateral offset), then a planar two-link problem for boom and arm to the bucket pin. Failures
name the distance and the reachable range, or the joint and its limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from tms_common.errors import ConfigError
from tms_model.excavator.codes import InvalidGoalError, JointLimitError, OutOfReachError
from tms_model.machines import EXCAVATOR, Machine, load_machine
from tms_model.site import load_site

__all__ = ["JOINTS", "ExcavatorKinematics", "JointLimits", "load_kinematics", "site_excavator_kind"]

# The front joints of every excavator kind, in COM3 bus / joint_states order (the names the URDF and the
# COM3 relay use; a kind's YAML lists them in this order under front_joints).
JOINTS = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")


@dataclass(frozen=True)
class JointLimits:
    """Position [rad] (lower/upper, +-inf for the continuous swing), velocity [rad/s], acceleration [rad/s^2]."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    def violation(self, q: np.ndarray, margin: float = 0.0) -> tuple[int, float, tuple[float, float]] | None:
        """First joint outside its limits (index, value, (lower, upper)) or None."""
        for i in range(len(self.lower)):
            if q[i] < self.lower[i] - margin or q[i] > self.upper[i] + margin:
                return i, float(q[i]), (float(self.lower[i]), float(self.upper[i]))
        return None


class ExcavatorKinematics:
    """Pinocchio model of an excavator front plus closed-form IK; joint order is the kind's front joints.

    Args:
        machine: the kind's description (``load_machine(kind)``); must be an excavator.
    """

    def __init__(self, machine: Machine) -> None:
        machine.require(EXCAVATOR)
        assert machine.bucket is not None
        self.machine = machine
        self.kind = machine.kind
        self.joints = machine.joint_names
        if self.joints != JOINTS:
            raise ConfigError(f"{machine.source}: front_joints must be {list(JOINTS)}, got {list(self.joints)}")
        tip = np.array(machine.bucket.tip_xyz)
        origins, pitches = [], []
        lower, upper, vel, acc = [], [], [], []
        model = pin.Model()
        model.name = machine.kind
        parent = 0
        bodies = ("body", "boom", "arm", "bucket")
        for joint, body in zip(machine.joints, bodies, strict=True):
            xyz = np.array(joint.origin_xyz)
            rpy = np.array(joint.origin_rpy)
            placement = pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)
            jmodel = pin.JointModelRZ() if joint.axis == (0.0, 0.0, 1.0) else pin.JointModelRY()
            parent = model.addJoint(parent, jmodel, placement, joint.name)
            mass = float(machine.masses.get(body, 1.0))
            model.appendBodyToJoint(parent, pin.Inertia.FromSphere(mass, 0.5), pin.SE3.Identity())
            origins.append(xyz)
            pitches.append(float(rpy[1]))
            lower.append(-math.inf if joint.lower is None else joint.lower)
            upper.append(math.inf if joint.upper is None else joint.upper)
            vel.append(joint.velocity)
            acc.append(joint.acceleration)
        bucket_joint = model.getJointId(JOINTS[3])
        self.tip_frame = model.addFrame(
            pin.Frame("bucket_tip", bucket_joint, pin.SE3(np.eye(3), tip), pin.FrameType.OP_FRAME)
        )
        self.pin_frame = model.addFrame(
            pin.Frame("bucket_pin", bucket_joint, pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
        self.model = model
        self.data = model.createData()
        self.limits = JointLimits(np.array(lower), np.array(upper), np.array(vel), np.array(acc))
        self.home = np.array([machine.home_pose[n] for n in JOINTS])

        # Planar parameters of the front in the body (post-swing) x-z plane.
        swing_o, boom_o, arm_o, bucket_o = origins
        self.swing_origin = swing_o
        self.boom_foot = np.array([boom_o[0], boom_o[2]])
        self.lateral = float(boom_o[1] + arm_o[1] + bucket_o[1] + tip[1])
        self.l_boom = float(math.hypot(arm_o[0], arm_o[2]))
        self.l_arm = float(math.hypot(bucket_o[0], bucket_o[2]))
        self.l_bucket = float(math.hypot(tip[0], tip[2]))
        p1 = pitches[1]
        p2 = p1 + pitches[2]
        p3 = p2 + pitches[3]
        # c_k: angle below horizontal of link k's pin-to-pin vector when its joints are all zero.
        self.c_boom = p1 + math.atan2(-arm_o[2], arm_o[0])
        self.c_arm = p2 + math.atan2(-bucket_o[2], bucket_o[0])
        self.c_bucket = p3 + math.atan2(-tip[2], tip[0])
        self.bucket_pitch0 = p3  # pitch of bucket_link at q = 0
        self.tip_local = tip

    def envelope(self, samples: int = 81) -> dict[str, float]:
        """Working range over the joint limits, as a spec sheet states it [m].

        ``max_reach``: largest horizontal distance swing axis -> bucket tip; ``max_depth``: deepest tip
        below the ground (base_link z = 0), positive down; ``max_height``: highest tip. Evaluated on a
        ``samples``-per-joint grid of boom/arm/bucket in the front's plane (closed-form planar chain).
        """
        qb, qa, qk = np.meshgrid(
            *(np.linspace(self.limits.lower[i], self.limits.upper[i], samples) for i in (1, 2, 3)), indexing="ij"
        )
        phi_b = qb + self.c_boom
        phi_a = qb + qa + self.c_arm
        phi_k = qb + qa + qk + self.c_bucket
        x = self.boom_foot[0] + self.l_boom * np.cos(phi_b) + self.l_arm * np.cos(phi_a) + self.l_bucket * np.cos(phi_k)
        z = self.boom_foot[1] - self.l_boom * np.sin(phi_b) - self.l_arm * np.sin(phi_a) - self.l_bucket * np.sin(phi_k)
        z = z + self.swing_origin[2]
        return {"max_reach": float(np.max(x)), "max_depth": float(-np.min(z)), "max_height": float(np.max(z))}

    # ------------------------------------------------------------------ forward kinematics
    def forward(self, q: np.ndarray) -> None:
        """Update joint placements, frame placements and Jacobians of the internal data for ``q``."""
        pin.computeJointJacobians(self.model, self.data, np.asarray(q, dtype=float))
        pin.updateFramePlacements(self.model, self.data)

    def tip_position(self, q: np.ndarray) -> np.ndarray:
        """Bucket tip position in base_link [m]."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tip_frame].translation.copy()

    def side_view(self, q: np.ndarray) -> np.ndarray:
        """The front in its own vertical plane: (radial, height) [m] of boom foot, arm pin, bucket pin, tip.

        Swing is ignored (the plane turns with it); the small lateral offsets do not show in a side view.
        """
        q0 = np.asarray(q, dtype=float).copy()
        q0[0] = 0.0
        pin.framesForwardKinematics(self.model, self.data, q0)
        pts = [self.data.oMi[self.model.getJointId(name)].translation for name in JOINTS[1:]]
        pts.append(self.data.oMf[self.tip_frame].translation)
        return np.array([[p[0], p[2]] for p in pts])

    def tip_pose(self, q: np.ndarray) -> pin.SE3:
        """Pose of the bucket tip frame (bucket_end_link) in base_link."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return pin.SE3(self.data.oMf[self.tip_frame])

    def theta_w(self, q: np.ndarray) -> float:
        """Bucket-edge angle below the ground plane [rad] (see module docstring)."""
        return float(q[1] + q[2] + q[3] + self.c_bucket)

    @staticmethod
    def theta_w_jacobian() -> np.ndarray:
        """d theta_w / dq, a constant row."""
        return np.array([0.0, 1.0, 1.0, 1.0])

    def jacobians(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(tip position, tip linear Jacobian 3x4, pin position, pin linear Jacobian 3x4), world-aligned."""
        self.forward(q)
        ref = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        jt = pin.getFrameJacobian(self.model, self.data, self.tip_frame, ref)[:3]
        jp = pin.getFrameJacobian(self.model, self.data, self.pin_frame, ref)[:3]
        return (
            self.data.oMf[self.tip_frame].translation.copy(),
            jt,
            self.data.oMf[self.pin_frame].translation.copy(),
            jp,
        )

    # ------------------------------------------------------------------ inverse kinematics
    def ik_position_with_angle(self, position: np.ndarray, theta_w: float, *, check_limits: bool = True) -> np.ndarray:
        """Joint angles that put the bucket tip at ``position`` (base_link) with edge angle ``theta_w``.

        Raises:
            InvalidGoalError: NaN or infinite input.
            OutOfReachError: the bucket pin would be outside the boom+arm annulus (message: distance, range).
            JointLimitError: the unique solution needs a joint outside its limits (message: joint, limit).
        """
        x, y, z = (float(v) for v in position)
        if not all(math.isfinite(v) for v in (x, y, z, theta_w)):
            raise InvalidGoalError(f"position/theta_w must be finite, got x={x}, y={y}, z={z}, theta_w={theta_w}")
        swing, radial = self._swing_radial(x, y)
        zb = z - self.swing_origin[2]
        pin_x = radial - self.l_bucket * math.cos(theta_w)
        pin_z = zb + self.l_bucket * math.sin(theta_w)
        ddx, ddz = pin_x - self.boom_foot[0], pin_z - self.boom_foot[1]
        dist = math.hypot(ddx, ddz)
        lo, hi = abs(self.l_boom - self.l_arm), self.l_boom + self.l_arm
        if not lo <= dist <= hi:
            raise OutOfReachError(
                f"bucket pin would be {dist:.3f} m from the boom foot; reachable {lo:.3f} .. {hi:.3f} m "
                f"(tip ({x:.3f}, {y:.3f}, {z:.3f}), theta_w {theta_w:.3f} rad)"
            )
        cos_b = (dist**2 - self.l_boom**2 - self.l_arm**2) / (2 * self.l_boom * self.l_arm)
        beta = math.acos(max(-1.0, min(1.0, cos_b)))
        phi_d = math.atan2(-ddz, ddx)
        phi_boom = phi_d - math.atan2(self.l_arm * math.sin(beta), self.l_boom + self.l_arm * math.cos(beta))
        qb = phi_boom - self.c_boom
        qa = beta + self.c_boom - self.c_arm
        qk = theta_w - self.c_bucket - qb - qa
        # theta_w is an angle: take the 2*pi branch of the bucket joint that lies within its limits.
        for turn in (0.0, 2 * math.pi, -2 * math.pi):
            if self.limits.lower[3] <= qk + turn <= self.limits.upper[3]:
                qk += turn
                break
        q = np.array([swing, qb, qa, qk])
        if check_limits:
            self.check_joint_limits(q, what=f"target ({x:.3f}, {y:.3f}, {z:.3f}) theta_w {theta_w:.3f}")
        return q

    def _swing_radial(self, x: float, y: float) -> tuple[float, float]:
        dx, dy = x - self.swing_origin[0], y - self.swing_origin[1]
        r2 = dx * dx + dy * dy
        if r2 <= self.lateral**2 + 1e-9:
            raise OutOfReachError(f"target is {math.sqrt(r2):.3f} m from the swing axis: on the axis, unreachable")
        radial = math.sqrt(r2 - self.lateral**2)
        swing = math.atan2(dy, dx) - math.atan2(self.lateral, radial)
        return math.atan2(math.sin(swing), math.cos(swing)), radial

    def swing_for(self, position: np.ndarray) -> float:
        """Swing angle that puts the front's plane through ``position`` (x, y used)."""
        return self._swing_radial(float(position[0]), float(position[1]))[0]

    def check_joint_limits(self, q: np.ndarray, what: str = "target", margin: float = 1e-9) -> None:
        """Raise :class:`JointLimitError` naming the first joint of ``q`` outside its limits."""
        bad = self.limits.violation(q, margin)
        if bad is not None:
            i, value, (lo, hi) = bad
            raise JointLimitError(
                f"{what}: {JOINTS[i]} would be {value:.4f} rad, outside its limits [{lo:.4f}, {hi:.4f}] rad"
            )

    def pose_to_position_with_angle(
        self, position: np.ndarray, quaternion_xyzw: np.ndarray, *, tolerance: float = 0.035
    ) -> tuple[np.ndarray, float]:
        """Convert a bucket-tip pose (bucket_end_link orientation) to (position, theta_w).

        The 4-DOF front can only pitch the bucket in the plane its swing gives: roll must be ~0 and the
        yaw must be the swing angle that reaches the position (within ``tolerance`` rad).
        """
        quat = np.asarray(quaternion_xyzw, dtype=float)
        pos = np.asarray(position, dtype=float)
        if quat.shape != (4,) or not np.all(np.isfinite(quat)) or not np.all(np.isfinite(pos)):
            raise InvalidGoalError(f"pose must be finite: position {pos.tolist()}, orientation {quat.tolist()}")
        norm = float(np.linalg.norm(quat))
        if abs(norm - 1.0) > 0.01:
            raise InvalidGoalError(f"pose orientation quaternion has norm {norm:.4f}, expected 1")
        rot = pin.Quaternion(quat[3], quat[0], quat[1], quat[2]).normalized().toRotationMatrix()
        swing = self.swing_for(pos)
        rel = pin.rpy.rpyToMatrix(0.0, 0.0, swing).T @ rot  # should be a pure pitch about y
        pitch = math.atan2(rel[0, 2], rel[0, 0])
        error = float(np.linalg.norm(rel - pin.rpy.rpyToMatrix(0.0, pitch, 0.0)))
        if error > tolerance:
            raise OutOfReachError(
                f"orientation unreachable: the bucket at this position can only pitch about the front's y axis "
                f"(swing {swing:.3f} rad, no roll); the requested orientation is {error:.3f} away from any such "
                f"(4-DOF front; tolerance {tolerance})"
            )
        theta_w = float(pitch - self.bucket_pitch0 + self.c_bucket)
        # theta_w = boom + arm + bucket spans more than pi (about -1.2 .. 5.0 rad with the limits): a pitch
        # is only defined mod 2 pi, so pick the representative in the window the joints can reach
        # (wrapping to (-pi, pi] turned a 3.2 rad pose into -3.07 rad: the arm chased it and timed out).
        lo = float(np.sum(self.limits.lower[1:])) - 0.1
        theta_w = lo + math.fmod(theta_w - lo, 2.0 * math.pi) % (2.0 * math.pi)
        return pos, theta_w


def load_kinematics(kind: str | None = None, path: str | Path | None = None) -> ExcavatorKinematics:
    """A new model of excavator ``kind`` (from ``config/machines/<kind>.yaml`` or ``path``); no kind: the kind of
    the site's first excavator (:func:`site_excavator_kind`).

    The description is parsed once per file; the pinocchio data is per instance (not thread-safe to share).
    """
    return ExcavatorKinematics(load_machine(kind or site_excavator_kind(), path))


def site_excavator_kind() -> str:
    """The kind of the first machine of ``config/site.yaml`` ``machines:`` whose description is an excavator."""
    site = load_site()
    for machine in site.machines.values():
        if load_machine(machine.kind).type == EXCAVATOR:
            return machine.kind
    raise ConfigError(f"{site.source}: machines: no excavator on the site")
