"""Force-controlled digging around the inverse-dynamics hierarchy (HEAP, Jud et al. 2021, sec. 4.3 and 2.4).

Per control step (100 Hz) :meth:`ForceLoop.step` takes the measured joint state, the chamber pressures of the boom,
arm and bucket cylinders, a tip reference (a point on the path, its velocity and acceleration, theta_w) and the
desired force ``force_d`` the bucket is to exert on the soil at its tip (base_link axes: normal to the ground plus
along the cut), and

1. hybrid task: the tip reference's component along ``force_d`` is replaced by the measured tip's (velocity 0), so
   the hierarchy's tip PD acts along the path and damps the motion along the force, but never fights the force;
2. calls :class:`~tms_rc.excavator.id_hqp.InverseDynamicsHQP` with ``F_ext = -(force_d + correction)`` (the soil's
   reaction to the desired force: the cylinders' forces then hold the front against gravity *and* press);
   ``correction`` is an outer integral on the error of the pressed force along ``force_d``, estimated from the
   measured cylinder forces (statics: ``J^T F_soil = g(q) - J_p f``, least squares in the front's vertical plane),
   which takes out what the model (masses, no friction) gets wrong; only the part along the ground normal is
   controlled, the part along the cut is feed-forward;
3. hands the ID's force of each cylinder under force control (``ForceLoopSettings.functions``, default arm and
   bucket) to its :class:`~tms_rc.excavator.piston.PistonForceController` (PI on the force error + dead-zone
   compensation, ``force_contact`` gains of ``config/tms_rc/piston_control.yaml``), which returns the COM3 pilot
   pair; a cylinder under velocity control (``velocity_functions``: for a drag, :data:`DRAG_ROLES`) gets the
   resolved-rate speed along the path through its :class:`~tms_rc.excavator.piston.PistonVelocityController`; any
   other gets no pilot (held by its oil).

What of HEAP is not here (README "Not done yet"): HEAP's pressure control runs on servo valves at 100 Hz with a
fast pressure loop and puts every cylinder under it; the COM3 pilot valves have ~0.3-0.65 s of dead time, so the
tracking of the ID's cylinder forces is ~1 s slow, the ID's own tip PD must be gentle (the settings here lower its
gains), and boom, arm and bucket all under force control on one contact oscillate (measured, below): here only
some cylinders are force controlled, the others held or velocity controlled (roles, :class:`ForceLoopSettings`).
The swing motor is not force controlled (its pilot stays 0: the spool centred, the brake holds). No soil-force model
in the loop: the cutting resistance along the cut is what ``force_d``'s tangential part or the velocity-controlled
cylinders must overcome, not estimated; friction is not identified.

Pure Python (numpy, pinocchio through the ID), no ROS.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.id_hqp import IdReference, IdResult, IdSettings, InverseDynamicsHQP
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    PilotPair,
    PistonControlSettings,
    PistonForceController,
    PistonLut,
    PistonVelocityController,
    cylinder_force,
    cylinder_of,
    extend_sign,
)

__all__ = ["DRAG_ROLES", "ForceLoopSettings", "ForceLoopStep", "ForceLoop", "contact_force_estimate",
           "default_id_settings"]


@dataclass(frozen=True)
class ForceLoopSettings:
    """Choices of the loop around the ID (defaults in the module; no config file yet, as the ID's)."""

    #: [1/s] outer integral on the pressed force's error along the normal (0: off, the wrench is feed-forward only);
    #: 0.5 limit-cycled with the pilot valves' dead time (force_dig bench), 0.1 does not
    force_ki: float = 0.1
    #: [N] largest correction the integral may add along force_d
    force_i_limit: float = 80e3
    #: [N] integrate only while the estimated force's error is within this (the pilot valves' dead time after a
    #: step of force_d is not wound up)
    force_i_zone: float = 60e3
    #: the cylinder functions under force control; the others get no pilot (the spool centres and the trapped oil
    #: holds the cylinder: it carries whatever the statics asks of it). Default arm and bucket, the boom held: with
    #: the boom's force loop too, three integrating loops with 0.3-0.65 s of dead time act on one contact (force_dig
    #: bench, bearing force s.d. over the last 4 s of 8 s steps of 20-60 kN: 4-10 kN at the boom's force_contact
    #: gains, 27-29 kN and the edge lifting off at the arm's, 0.3-2.5 kN with the boom held)
    functions: tuple[str, ...] = ("arm_joint", "bucket_joint")
    #: which PI set of ``piston_control.yaml`` the cylinders use: ``force_contact`` (pressed on the ground) or
    #: ``force`` (stiff stall)
    gains: str = "force_contact"

    #: the cylinder functions under piston *velocity* control (LUT + PI) instead, at the resolved-rate joint speeds
    #: of :meth:`ForceLoop.path_rates` (along the path; no speed along the normal; theta_w). Default none (pressing
    #: in place). A drag along flat ground needs the boom to move: held, the arm and bucket cannot move the edge
    #: along (in a reached-out pose their motion moves it mostly down; force_dig bench: 0.07 m of a 2 m path);
    #: ``DRAG_ROLES`` (bucket under force control, boom and arm under velocity control) drags it. Not HEAP's: all
    #: its cylinders are pressure-controlled.
    velocity_functions: tuple[str, ...] = ()
    path_gain: float = 0.5  # [1/s] tip position error along the path and theta_w error -> speed
    velocity_deadband: float = 0.002  # [m/s] a smaller piston speed command is none (spool centred, oil holds)

    def __post_init__(self) -> None:
        both = set(self.functions) & set(self.velocity_functions)
        if both:
            raise ValueError(f"ForceLoopSettings: {sorted(both)} both under force and velocity control")
        bad = [f for f in (*self.functions, *self.velocity_functions) if f not in CYLINDER_FUNCTIONS]
        if bad:
            raise ValueError(f"ForceLoopSettings.functions: {bad} are not cylinder functions {CYLINDER_FUNCTIONS}")
        if self.gains not in ("force_contact", "force"):
            raise ValueError(f"ForceLoopSettings.gains: {self.gains!r} is neither 'force_contact' nor 'force'")


#: the roles of the cylinders for a drag along the ground (:class:`ForceLoopSettings` ``functions``,
#: ``velocity_functions``): the bucket presses (the shortest dead time of the three), boom and arm move the edge
DRAG_ROLES = {"functions": ("bucket_joint",), "velocity_functions": ("boom_joint", "arm_joint")}


def default_id_settings() -> IdSettings:
    """The ID's settings for force control through the pilot valves: the tip PD ~5x gentler than the ID's defaults
    (25 / 10): the cylinder forces it asks for reach the front ~1 s late through the valves' dead time."""
    return dataclasses.replace(IdSettings(), kp_position=4.0, kd_position=4.0, kp_theta_w=4.0, kd_theta_w=4.0)


def contact_force_estimate(dyn: FrontDynamics, q: np.ndarray, cyl_force: np.ndarray) -> np.ndarray:
    """The force [N, base_link] the bucket exerts on the soil at its tip, estimated from the measured cylinder forces
    ``cyl_force`` (boom, arm, bucket, + pushing) by statics: the soil's force F_s on the tip satisfies
    ``g(q) - J_p f = J^T F_s`` on boom, arm and bucket; solved by least squares for F_s in the front's vertical plane
    (a force across it loads only the swing), returned as ``-F_s``."""
    q = np.asarray(q, dtype=float)
    grav = dyn.gravity(q)
    gains = dyn.actuator_gains(q)
    jac = dyn.tip_jacobian(q)  # 3 x 4
    heading = float(q[0])
    h = np.array([math.cos(heading), math.sin(heading), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    basis = np.column_stack([h, z])  # F_s = basis @ c
    a = (jac[:, 1:].T @ basis)  # 3 x 2: J^T over the plane
    rhs = grav[1:] - gains[1:] * np.asarray(cyl_force, dtype=float)
    c, *_ = np.linalg.lstsq(a, rhs, rcond=None)
    return -(basis @ c)


@dataclass
class ForceLoopStep:
    """One step's outcome: the pilot pairs per cylinder function, the ID's result, the measured cylinder forces [N]
    (boom, arm, bucket), the estimated pressed force [N, base_link] and the wrench handed to the ID as F_ext."""

    pairs: dict[str, PilotPair]
    id_result: IdResult
    measured: np.ndarray
    pressed: np.ndarray
    f_ext: np.ndarray


class ForceLoop:
    """The ID hierarchy + per-cylinder piston force control of one excavator front.

    Args:
        dyn, kin: the front's rigid-body model and kinematics (the machine's description).
        luts: the identified look-up table of each cylinder function (its cracks feed the dead-zone compensation).
        piston: ``config/tms_rc/piston_control.yaml``'s choices (``force_contact`` gains, rate, zero band).
        p_max: the DBC's largest pilot [MPa] (:func:`tms_rc.excavator.piston.pilot_range`).
        id_settings: the ID's settings (default :func:`default_id_settings`).
        settings: the loop's own choices.
    """

    def __init__(self, dyn: FrontDynamics, kin: ExcavatorKinematics, luts: Mapping[str, PistonLut],
                 piston: PistonControlSettings, p_max: float, id_settings: IdSettings | None = None,
                 settings: ForceLoopSettings | None = None) -> None:
        missing = [fn for fn in CYLINDER_FUNCTIONS if fn not in luts]
        if missing:
            raise ValueError(f"ForceLoop: no identified look-up table for {', '.join(missing)}")
        ids = id_settings or default_id_settings()
        if abs(ids.rate_hz - piston.rate_hz) > 1e-9:
            raise ValueError(f"ForceLoop: the ID runs at {ids.rate_hz} Hz but the piston control at "
                             f"{piston.rate_hz} Hz")
        self.dyn, self.kin = dyn, kin
        self.settings = settings or ForceLoopSettings()
        self.id = InverseDynamicsHQP(dyn, kin, ids)
        machine = dyn.machine
        self.cylinders = {fn: cylinder_of(machine, fn) for fn in CYLINDER_FUNCTIONS}
        gains = getattr(piston, self.settings.gains)
        self.pistons = {fn: PistonForceController(luts[fn], gains[fn], 1.0 / piston.rate_hz,
                                                  extend=extend_sign(machine, fn), zero_band=piston.zero_band_mpa,
                                                  p_max=p_max)
                        for fn in CYLINDER_FUNCTIONS}
        self.movers = {fn: PistonVelocityController(luts[fn], piston.velocity[fn], 1.0 / piston.rate_hz,
                                                    extend=extend_sign(machine, fn), zero_band=piston.zero_band_mpa,
                                                    p_max=p_max)
                       for fn in self.settings.velocity_functions}
        self.index = {fn: JOINTS.index(fn) for fn in CYLINDER_FUNCTIONS}
        self.dt = 1.0 / piston.rate_hz
        self.correction = 0.0  # [N] the outer integral along force_d

    def reset(self) -> None:
        self.correction = 0.0
        for ctl in (*self.pistons.values(), *self.movers.values()):
            ctl.reset()

    def path_rates(self, q: np.ndarray, ref: IdReference, n: np.ndarray) -> dict[str, float]:
        """Joint speeds [rad/s] of the velocity-controlled functions (resolved rate in the front's vertical plane, the
        force-controlled joints' speeds taken as 0): with one function the tip's speed along the path's tangent (ref's
        speed plus ``path_gain`` x its position error along it); with two also no speed along the normal ``n``; with
        three also theta_w's rate plus ``path_gain`` x its error. Least squares where the rows are singular."""
        k = self.settings.path_gain
        fns = self.settings.velocity_functions
        tip = self.dyn.tip_position(q)
        jac = self.dyn.tip_jacobian(q)[:, [self.index[fn] for fn in fns]]
        h = np.array([math.cos(float(q[0])), math.sin(float(q[0])), 0.0])
        t = h - n * float(h @ n)
        t /= max(float(np.linalg.norm(t)), 1e-9)
        theta = float(q[1] + q[2] + q[3]) + self.kin.c_bucket
        a = np.vstack([t @ jac, n @ jac, np.ones(len(fns))])[: len(fns)]
        rhs = np.array([float(t @ (ref.velocity + k * (ref.position - tip))), 0.0,
                        ref.theta_w_rate + k * (ref.theta_w - theta)])[: len(fns)]
        rates, *_ = np.linalg.lstsq(a, rhs, rcond=None)
        return dict(zip(fns, (float(r) for r in rates), strict=True))

    def measured_forces(self, pressures: Mapping[str, tuple[float, float]]) -> np.ndarray:
        """Cylinder forces [N] (boom, arm, bucket) from ``pressures[fn] = (cap, rod)`` [MPa] and the areas."""
        return np.array([cylinder_force(self.cylinders[fn], *pressures[fn]) for fn in CYLINDER_FUNCTIONS])

    def step(self, q: np.ndarray, qd: np.ndarray, pressures: Mapping[str, tuple[float, float]], ref: IdReference,
             force_d: np.ndarray, normal: np.ndarray | None = None) -> ForceLoopStep:
        """One control period: see the module docstring. ``force_d`` [N, base_link] is the force the bucket is to
        exert on the soil; ``normal`` the ground's unit normal (out of the ground, default up): along it the force is
        controlled (hybrid task, outer integral), ``force_d``'s part across it (along the cut) is feed-forward only.
        A ``force_d`` without a part into the ground is a free motion along ``ref``."""
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        force_d = np.asarray(force_d, dtype=float)
        n = np.array([0.0, 0.0, 1.0]) if normal is None else np.asarray(normal, dtype=float)
        if abs(float(np.linalg.norm(n)) - 1.0) > 1e-6:
            raise ValueError(f"ForceLoop.step: normal must be a unit vector, got {n}")
        measured = self.measured_forces(pressures)
        pressed = contact_force_estimate(self.dyn, q, measured)
        path_ref = ref
        want = -float(force_d @ n)  # [N] pressing into the ground, + = down into it
        s = self.settings
        if want > 0.0:
            err = want + float(pressed @ n)
            if s.force_ki > 0.0 and abs(err) <= s.force_i_zone:
                self.correction = min(s.force_i_limit,
                                      max(-s.force_i_limit, self.correction + s.force_ki * err * self.dt))
            # hybrid: along n the tip stays where it is (no P: the force sets the depth), its speed along n is damped
            tip = self.dyn.tip_position(q)
            ref = dataclasses.replace(
                ref,
                position=ref.position + n * float((tip - ref.position) @ n),
                velocity=ref.velocity - n * float(ref.velocity @ n),
                acceleration=ref.acceleration - n * float(ref.acceleration @ n),
            )
            f_ext = -(force_d - n * self.correction)
        else:
            self.correction = 0.0
            f_ext = -force_d
        res = self.id.solve(q, qd, ref, f_ext)
        active = self.settings.functions
        pairs = {fn: (self.pistons[fn].step(float(res.force[self.index[fn]]), float(measured[k])) if fn in active
                      else PilotPair(0.0, 0.0))
                 for k, fn in enumerate(CYLINDER_FUNCTIONS)}
        if self.movers:
            rates = self.path_rates(q, path_ref, n)
            gains = self.dyn.actuator_gains(q)
            for fn, ctl in self.movers.items():
                i = self.index[fn]
                v_ref = float(gains[i] * rates[fn])
                if abs(v_ref) < s.velocity_deadband:
                    v_ref = 0.0
                pairs[fn] = ctl.step(v_ref, float(gains[i] * qd[i]))
        return ForceLoopStep(pairs, res, measured, pressed, f_ext)
