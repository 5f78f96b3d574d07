"""Rigid-body model of an excavator's front for the inverse-dynamics controller (:mod:`tms_rc.excavator.id_hqp`).

The chain is the one of :mod:`tms_model.excavator.kinematics` (swing(z) -> boom(y) -> arm(y) -> bucket(y), joint
origins, limits and the bucket tip from the machine description ``config/machines/<kind>.yaml``), rebuilt here
with inertias: that module gives every link a placeholder (a 0.5 m sphere centred on its joint), fine for
kinematics but not for dynamics, so the dynamic model is a second pinocchio model of the same description
(kinematic results are identical: same joints, same frames).

Inertias (an assumption; the description gives masses and boxes only): each link's mass (``masses:`` of the
description, read through :func:`tms_model.machines.load_machine`; never the plant's ``config/sim/*``) is a
**uniform box**, the link's box of the description (``link_boxes:``, :class:`tms_model.machines.LinkBox`: full
lengths along the link frame's axes, centred at its offset in the link frame; the box the plant's link is): body
(the upper structure, on the swing joint), boom, arm and bucket. The base/undercarriage is the fixed world.
Cylinders, hoses and the bucket linkage have no mass of their own (their mass is in the links').

The actuator map (HEAP eq. 14, by virtual work): tau_i = g_i f_i, actuator speed v_i = g_i qd_i with
g_i = dl_i/dq_i [m/rad] of each front cylinder (:func:`tms_model.cylinders.moment_arm`, the description's pins
and four-bar) and, for the swing motor, g_0 = its displacement per swing radian [m^3/rad] (the description's
``cylinders.swing.displacement_per_rad``, reduction included): its "force" is the port pressure difference [Pa]
and its "speed" the oil flow [m^3/s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from tms_common.errors import ConfigError
from tms_model.cylinders import Cylinder, moment_arm
from tms_model.excavator.kinematics import JOINTS
from tms_model.machines import EXCAVATOR, Machine

__all__ = ["Actuator", "FrontDynamics", "G"]

N = len(JOINTS)
G = 9.81
_BODIES = ("body", "boom", "arm", "bucket")


@dataclass(frozen=True)
class Actuator:
    """One joint's drive for the ID: area per unit actuator speed in each direction (cylinder: cap side when
    extending, rod side when retracting [m^2]; swing motor: 1, its speed is already a flow), the force range
    [-relief * rod_area, relief * cap_area] (motor: +-relief [Pa]) and whether it draws on the main pumps."""

    name: str
    area_extend: float
    area_retract: float
    force_max: float
    force_min: float
    on_pump: bool
    cylinder: Cylinder | None = None  # None: the swing motor (constant displacement)
    displacement: float = 0.0  # [m^3/rad] swing motor only
    origin: tuple[float, float] = (0.0, 0.0)  # the joint's (x, z) and pitch in its parent, what moment_arm takes
    pitch: float = 0.0


class FrontDynamics:
    """M(q), h(q, qd) (Coriolis + centrifugal + gravity), bucket-tip Jacobian and J̇·qd, the actuator map.

    One instance per controller (the pinocchio data is reused: not thread-safe to share). Joint order
    :data:`~tms_model.excavator.kinematics.JOINTS`; positions in base_link.
    """

    def __init__(self, machine: Machine) -> None:
        machine.require(EXCAVATOR)
        if machine.joint_names != JOINTS:
            raise ConfigError(f"{machine.source}: front_joints must be {list(JOINTS)}")
        if machine.cylinders is None or machine.cylinders.swing is None or machine.bucket is None:
            raise ConfigError(f"{machine.source}: the ID controller needs cylinders (with swing) and a bucket")
        missing = [b for b in _BODIES if b not in machine.masses]
        if missing:
            raise ConfigError(f"{machine.source}: masses: no mass for {missing}")
        missing = [j.child for j in machine.joints if j.child not in machine.link_boxes]
        if missing:
            raise ConfigError(f"{machine.source}: link_boxes: no box for {missing}")
        self.machine = machine
        tip = np.array(machine.bucket.tip_xyz, dtype=float)
        origins = [np.array(j.origin_xyz, dtype=float) for j in machine.joints]
        model = pin.Model()
        model.name = machine.kind
        model.gravity = pin.Motion(np.array([0.0, 0.0, -G]), np.zeros(3))
        parent = 0
        for k, (joint, body) in enumerate(zip(machine.joints, _BODIES, strict=True)):
            placement = pin.SE3(pin.rpy.rpyToMatrix(*joint.origin_rpy), origins[k])
            jmodel = pin.JointModelRZ() if joint.axis == (0.0, 0.0, 1.0) else pin.JointModelRY()
            parent = model.addJoint(parent, jmodel, placement, joint.name)
            box = machine.link_boxes[joint.child]  # a uniform box of the link's mass, axes along the link frame
            inertia = pin.Inertia.FromBox(float(machine.masses[body]), *box.size)
            model.appendBodyToJoint(parent, inertia, pin.SE3(np.eye(3), np.array(box.offset, dtype=float)))
        self.tip_frame = model.addFrame(
            pin.Frame("bucket_tip", model.getJointId(JOINTS[3]), pin.SE3(np.eye(3), tip), pin.FrameType.OP_FRAME)
        )
        self.pin_frame = model.addFrame(
            pin.Frame("bucket_pin", model.getJointId(JOINTS[3]), pin.SE3.Identity(), pin.FrameType.OP_FRAME)
        )
        self.model = model
        self.data = model.createData()
        self._zero = np.zeros(N)
        self._tip_jac = np.zeros((6, N))
        self._pin_jac = np.zeros((6, N))
        # actuators in JOINTS order
        cyl = machine.cylinders
        swing = cyl.swing
        relief = swing.relief_mpa * 1e6
        acts = [Actuator(JOINTS[0], 1.0, 1.0, relief, -relief, on_pump=machine.drives[JOINTS[0]].flow_at_limit > 0.0,
                         displacement=swing.displacement_per_rad)]
        by_joint = {c.joint: c for c in cyl.all}
        for joint in machine.joints[1:]:
            c = by_joint.get(joint.name)
            if c is None:
                raise ConfigError(f"{machine.source}: cylinders: no cylinder drives {joint.name}")
            acts.append(Actuator(
                joint.name, c.cap_area, c.rod_area, cyl.relief_pa * c.cap_area, -cyl.relief_pa * c.rod_area,
                on_pump=machine.drives[joint.name].flow_at_limit > 0.0, cylinder=c,
                origin=(joint.origin_xyz[0], joint.origin_xyz[2]), pitch=joint.origin_rpy[1],
            ))
        self.actuators = tuple(acts)
        self._gains = np.zeros(N)
        self._fmax = np.array([a.force_max for a in self.actuators])
        self._fmin = np.array([a.force_min for a in self.actuators])
        self._m = np.zeros((N, N))
        self._lower_ix = np.tril_indices(N, -1)

    # ------------------------------------------------------------------ dynamics
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """M(q) [kg m^2] (symmetric, a new array)."""
        m = pin.crba(self.model, self.data, np.asarray(q, dtype=float))
        return np.triu(m) + np.triu(m, 1).T

    def nonlinear(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """h(q, qd) = C(q, qd) qd + g(q) [N m] (a new array)."""
        return pin.nonLinearEffects(self.model, self.data, np.asarray(q, dtype=float),
                                    np.asarray(qd, dtype=float)).copy()

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """g(q) [N m]: the joint torques that hold the front still (a new array)."""
        return pin.computeGeneralizedGravity(self.model, self.data, np.asarray(q, dtype=float)).copy()

    def update(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Compute everything of one control step at (q, qd): read it with :meth:`terms`.

        M, h, the tip and pin frame Jacobians (6 x 4, base_link-aligned) and J̇·qd of both points, one pass each.
        """
        model, data = self.model, self.data
        pin.forwardKinematics(model, data, q, qd, self._zero)
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._tip_jac[:] = pin.getFrameJacobian(model, data, self.tip_frame, lwa)
        self._pin_jac[:] = pin.getFrameJacobian(model, data, self.pin_frame, lwa)
        self._tip_acc = pin.getFrameClassicalAcceleration(model, data, self.tip_frame, lwa).linear
        self._pin_acc = pin.getFrameClassicalAcceleration(model, data, self.pin_frame, lwa).linear
        self._m[:] = pin.crba(model, data, q)
        self._m[self._lower_ix] = self._m.T[self._lower_ix]  # crba may fill the upper triangle only
        self._h = pin.nonLinearEffects(model, data, q, qd)

    def terms(self) -> tuple[np.ndarray, np.ndarray]:
        """(M, h) of the last :meth:`update` (buffers overwritten by the next update: copy to keep)."""
        return self._m, self._h

    def tip(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, 6 x 4 Jacobian [linear; angular], J̇·qd linear) of the bucket tip at the last update."""
        return self.data.oMf[self.tip_frame].translation, self._tip_jac, self._tip_acc

    def bucket_pin(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, 6 x 4 Jacobian, J̇·qd linear) of the bucket pin at the last update."""
        return self.data.oMf[self.pin_frame].translation, self._pin_jac, self._pin_acc

    def tip_position(self, q: np.ndarray) -> np.ndarray:
        """Bucket tip in base_link [m] (a new array)."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tip_frame].translation.copy()

    def tip_jacobian(self, q: np.ndarray) -> np.ndarray:
        """3 x 4 position Jacobian of the bucket tip in base_link axes (a new array)."""
        q = np.asarray(q, dtype=float)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return pin.getFrameJacobian(self.model, self.data, self.tip_frame,
                                    pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3].copy()

    def tip_jdot_qd(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """J̇(q, qd)·qd of the bucket tip (its classical acceleration at qdd = 0) [m/s^2] (a new array)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float), np.asarray(qd, dtype=float),
                              self._zero)
        pin.updateFramePlacements(self.model, self.data)
        return pin.getFrameClassicalAcceleration(self.model, self.data, self.tip_frame,
                                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear.copy()

    # ------------------------------------------------------------------ actuators
    def actuator_gains(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """g(q) = diag of J_p(q): dl_i/dq_i [m/rad] per cylinder, displacement [m^3/rad] for the swing motor.

        Beyond the bucket four-bar's closing range the last gain computed is kept (as the plant does).
        """
        g = self._gains if out is None else out
        for i, act in enumerate(self.actuators):
            if act.cylinder is None:
                g[i] = act.displacement
                continue
            try:
                g[i] = moment_arm(act.cylinder, act.origin, act.pitch, float(q[i]))
            except ValueError:
                if g[i] == 0.0:
                    raise
        return g.copy() if out is None else g

    def actuator_map(self, q: np.ndarray) -> np.ndarray:
        """J_p(q) = diag(g(q)) (4 x 4, a new array)."""
        return np.diag(self.actuator_gains(q))

    def torque_limits(self, gains: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tau_min, tau_max) [N m] the reliefs allow at the actuator gains ``gains`` (HEAP eq. 21)."""
        t1, t2 = gains * self._fmax, gains * self._fmin
        return np.minimum(t1, t2), np.maximum(t1, t2)

