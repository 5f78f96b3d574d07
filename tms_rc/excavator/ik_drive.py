"""HEAP's cylinder-space IK hierarchy driving the front through piston velocity control (HEAP 4.3.2 over 2.4).

Per control step (100 Hz) :meth:`IkDrive.step` takes the measured joint positions ``q`` and velocities ``qd`` and
the time ``t``, and

1. samples the cubic Hermite reference (:class:`~tms_rc.excavator.hermite.HermiteReference`, columns tip x, y, z
   in base_link [m] and theta_w [rad]: position and velocity);
2. solves :class:`~tms_rc.excavator.ik_cylinder.CylinderIkHQP` at ``q`` with the measured ``qd`` (its PID of HEAP
   eq. 36 on the tip and theta_w: ``v_d = v_ref + Kp e + Ki int(e) + Kd e_dot``), for the actuator velocities
   ``v`` (swing [rad/s], boom / arm / bucket piston speeds [m/s], + extending);
3. hands each cylinder's ``v_i`` to its :class:`~tms_rc.excavator.piston.PistonVelocityController` (the look-up
   table identified on the machine as feed-forward, optionally PI on the piston speed error (the measured speed
   being ``dl/dq * qd`` from the description's geometry), dead-zone compensation with the table's cracks); a command
   below ``velocity_deadband`` is none (both pilot lines 0: the spool centres and the oil holds the piston; the
   hierarchy's minimal-velocity level leaves ~1e-7 m/s of solver noise that must not open a valve at the crack);
4. returns one :class:`~tms_rc.excavator.piston.PilotPair` per front function.

The swing: driven the same way only when a table for ``swing_joint`` is given (its "piston speed" is the joint
speed [rad/s], ``extend`` +1). The identified file (``tms_rc_identify_pistons``,
``config/tms_rc/identified/<machine>_piston_lut.yaml``) holds boom, arm and bucket only, so by default the swing's
spool stays centred (pilot pair 0, 0: the swing holds where it stands) and the IK's swing speed is reported
(:attr:`IkDriveStep.swing_speed_cmd`) but not sent; references in the swing's plane need none.

The valves' dead times (0.4-0.9 s identified on the ZX200, plus a 0.15-0.23 s lag) bound what feedback alone
can do: with an integrator behind a dead time T a proportional gain above ~pi / (2 T) oscillates, and a tip that
follows a moving reference through a pure delay T lags it by ~T x its speed. So, with the identified delays given
(``delays_s``: dead time + lag per joint, :meth:`IkDrive.for_machine` reads ``config/tms_rc/identified/<machine>.yaml``
through :func:`~tms_rc.excavator.controller.load_identified`) and ``smith_predictor`` on (default), the drive is a
Smith predictor in joint space: every driven function's command is held back to the slowest one's delay T (the
boom's: equal delays, one prediction horizon), the IK solves at the predicted pose ``q + dt * sum(the joint
velocities commanded over the last T)`` (what is in flight, not yet seen) for the reference at ``t + T`` (it is
known ahead), and what reaches each valve is the command of T - T_i ago through ``dl/dq`` at the measured pose. A
model error (a piston slower than commanded) shows in the measured q one T later and the PID corrects it.
The default IK gains are the kinematic loop's (:class:`~tms_rc.excavator.ik_cylinder.IkSettings`); without the
predictor they must be lowered (``IkDriveSettings.ik``).
A motion planned ahead should be started one horizon before its reference's time 0 (``step`` from
``t = -horizon_s``): no causal loop moves the tip within the first T.

Nothing here reads the plant's configuration: the geometry comes from the machine description (tms_model), the
tables from the identification file, the piston PI gains and zero band from ``config/tms_rc/piston_control.yaml``.
Pure Python (no ROS).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from tms_common.config import config_path
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_rc.excavator.controller import load_identified
from tms_rc.excavator.hermite import HermiteReference
from tms_rc.excavator.ik_cylinder import CylinderIkHQP, IkReference, IkResult, IkSettings
from tms_rc.excavator.piston import (
    CYLINDER_FUNCTIONS,
    PilotPair,
    PistonControlSettings,
    PistonLut,
    PistonVelocityController,
    extend_sign,
    load_piston_luts,
    load_piston_settings,
    pilot_range,
)

__all__ = ["IkDriveSettings", "IkDriveStep", "IkDrive", "SWING"]

SWING = "swing_joint"


@dataclass(frozen=True)
class IkDriveSettings:
    """Choices of the drive (the machine's figures come from its description and its identification)."""

    #: the IK's own choices (HEAP eq. 36's gains: the kinematic loop's defaults, Kp 2/s; they hold with the Smith
    #: predictor; without it Kp must stay below ~pi / (2 T) of the slowest delay T, e.g. 0.8/s for the boom's 1.1 s)
    ik: IkSettings = field(default_factory=IkSettings)
    #: [m/s] a smaller piston speed command is none (spool centred); the swing's in [rad/s]
    velocity_deadband: float = 0.001
    swing_deadband: float = 0.002
    #: the piston speed PI (``piston_control.yaml``'s ``velocity`` gains) on top of the table; off by default: the
    #: table alone gives the commanded speed within a few % after the valve's dead time, while the PI, integrating
    #: the error through that dead time, overshoots it (boom ~1.4x) and breaks the predictor's model (a one-off
    #: sweep on bench ik_plant's air case with IK Kp 0.8/s: tip RMS 0.33 m with it, 0.08 m without). The position
    #: loop above removes the table's droop
    piston_feedback: bool = False
    #: with the identified delays: the joint-space Smith predictor (commands equalised to the slowest delay, the IK
    #: at the predicted pose for the reference one delay ahead); False: the IK at the measured pose, reference now
    smith_predictor: bool = True


@dataclass
class IkDriveStep:
    """One step: the pilot pair of each front function, the IK's result, the piston speeds commanded to the
    controllers (0 inside the deadband) and measured (dl/dq qd), the reference sampled (tip [m], theta_w [rad]),
    and the swing speed the IK asked for [rad/s] (sent only with a swing table)."""

    pairs: dict[str, PilotPair]
    ik: IkResult
    #: the pose the IK solved at (the measured one, or the Smith predictor's prediction) and the horizon [s]
    q_solved: np.ndarray
    horizon_s: float
    piston_cmd: dict[str, float]
    piston_measured: dict[str, float]
    ref: IkReference
    swing_speed_cmd: float


class IkDrive:
    """The IK hierarchy over piston velocity control of one excavator front.

    Args:
        kin: the front's kinematics (the machine's description).
        luts: the identified table per function (boom, arm, bucket required; ``swing_joint`` optional).
        piston: the piston-control choices (velocity PI gains per function, rate, zero band).
        p_max: the DBC's largest pilot [MPa] (:func:`~tms_rc.excavator.piston.pilot_range`).
        reference: tip (x, y, z) and theta_w against time (4 columns); may be set later (:meth:`start`).
        settings: the drive's choices.
        delays_s: per joint (swing, boom, arm, bucket) the identified dead time + lag [s] (the Smith predictor's
            model); None: no prediction.
    """

    def __init__(self, kin: ExcavatorKinematics, luts: Mapping[str, PistonLut], piston: PistonControlSettings,
                 p_max: float, reference: HermiteReference | None = None,
                 settings: IkDriveSettings | None = None, delays_s: Sequence[float] | None = None) -> None:
        s = settings or IkDriveSettings()
        missing = [fn for fn in CYLINDER_FUNCTIONS if fn not in luts]
        if missing:
            raise ValueError(f"IkDrive: no identified look-up table for {', '.join(missing)}")
        if abs(s.ik.rate_hz - piston.rate_hz) > 1e-9:
            raise ValueError(f"IkDrive: the IK's rate {s.ik.rate_hz} Hz differs from the piston control's "
                             f"{piston.rate_hz} Hz")
        self.kin, self.settings = kin, s
        self.ik = CylinderIkHQP(kin, s.ik)
        self.dt = self.ik.dt
        machine = kin.machine
        self.index = {fn: JOINTS.index(fn) for fn in (SWING, *CYLINDER_FUNCTIONS)}
        self.movers: dict[str, PistonVelocityController] = {
            fn: PistonVelocityController(luts[fn], piston.velocity[fn], self.dt, extend=extend_sign(machine, fn),
                                         zero_band=piston.zero_band_mpa, p_max=p_max, feedback=s.piston_feedback)
            for fn in CYLINDER_FUNCTIONS}
        self.swing_driven = SWING in luts
        if self.swing_driven:
            gains = piston.velocity.get(SWING, piston.velocity["boom_joint"])
            self.movers[SWING] = PistonVelocityController(luts[SWING], gains, self.dt, extend=1,
                                                          zero_band=piston.zero_band_mpa, p_max=p_max,
                                                          feedback=s.piston_feedback)
        self.p_max = p_max
        self.reference = reference
        # the Smith predictor: horizon T = the slowest driven function's delay, each held back to it
        driven = [self.index[fn] for fn in self.movers]
        self.horizon_s, self._n_horizon = 0.0, 0
        self._hold = dict.fromkeys(self.movers, 0)
        if delays_s is not None and s.smith_predictor:
            d = np.asarray(delays_s, dtype=float)
            if d.shape != (len(JOINTS),) or not np.all(np.isfinite(d)) or np.any(d < 0.0):
                raise ValueError(f"IkDrive: delays_s needs {len(JOINTS)} finite values >= 0, got {d.tolist()}")
            self._n_horizon = round(float(d[driven].max()) / self.dt)
            self.horizon_s = self._n_horizon * self.dt
            self._hold = {fn: self._n_horizon - round(float(d[self.index[fn]]) / self.dt) for fn in self.movers}
        # the joint velocities commanded (after the deadband), newest last: the prediction's and the hold's memory
        self._sent: deque[np.ndarray] = deque(maxlen=self._n_horizon + 1)
        self._in_flight = np.zeros(len(JOINTS))

    @classmethod
    def for_machine(cls, kin: ExcavatorKinematics, reference: HermiteReference | None = None,
                    settings: IkDriveSettings | None = None) -> IkDrive:
        """The drive with the machine's identified tables (``load_piston_luts(<machine name>)``), the piston
        choices of ``config/tms_rc/piston_control.yaml`` and the pilot range of its DBC."""
        machine = kin.machine
        name = machine.model_name
        ident = load_identified(config_path("tms_rc", "identified", f"{name}.yaml"), name)
        return cls(kin, load_piston_luts(name), load_piston_settings(), pilot_range(machine.dbc)[0],
                   reference, settings, delays_s=ident.dead_time_s + ident.lag_s)

    def start(self, reference: HermiteReference) -> None:
        """A new motion along ``reference``: the IK's PID integrals, the piston PIs and the commands in flight
        forgotten (start from rest)."""
        if np.shape(reference.positions)[1:] != (4,):
            raise ValueError(f"IkDrive: the reference needs 4 columns (x, y, z, theta_w), got "
                             f"{np.shape(reference.positions)}")
        self.reference = reference
        self.ik.reset()
        for m in self.movers.values():
            m.reset()
        self._sent.clear()
        self._in_flight.fill(0.0)

    def sample(self, t: float) -> IkReference:
        """The reference at time ``t`` [s] (held at its end knots outside them)."""
        if self.reference is None:
            raise RuntimeError("IkDrive: no reference (start() it first)")
        p, v = self.reference.sample(t)
        return IkReference(position=np.asarray(p[:3], dtype=float), velocity=np.asarray(v[:3], dtype=float),
                           theta_w=float(p[3]), theta_w_rate=float(v[3]))

    def step(self, t: float, q: np.ndarray, qd: np.ndarray) -> IkDriveStep:
        """One control period at time ``t`` [s] with the measured joint positions [rad] and velocities [rad/s]."""
        q = np.asarray(q, dtype=float)
        qd = np.asarray(qd, dtype=float)
        s = self.settings
        n = self._n_horizon
        if n:  # what is in flight will still move the joints: solve where they will be, for when it lands
            q_solve = q + self.dt * self._in_flight
            ref = self.sample(t + self.horizon_s)
            res = self.ik.solve(q_solve, ref, qd=self._sent[-1] if self._sent else np.zeros(len(JOINTS)))
        else:
            q_solve = q
            ref = self.sample(t)
            res = self.ik.solve(q, ref, qd=qd)
        qd_cmd = res.qd.copy()
        for fn, i in self.index.items():
            band = s.swing_deadband if fn == SWING else s.velocity_deadband
            if fn not in self.movers or abs(float(res.v[i])) < band:
                qd_cmd[i] = 0.0
        if n:  # the window of the last n commands slides on
            if len(self._sent) >= n:
                self._in_flight -= self._sent[-n]
            self._in_flight += qd_cmd
        self._sent.append(qd_cmd)
        gains, _ = self.ik.actuator_state(q)  # J_p at the measured pose
        pairs, cmd, meas = {}, {}, {}
        for fn, i in self.index.items():
            v_meas = float(gains[i] * qd[i])
            mover = self.movers.get(fn)
            if mover is None:  # the swing without a table: spool centred
                pairs[fn] = PilotPair(0.0, 0.0)
                cmd[fn] = 0.0
            else:
                k = len(self._sent) - 1 - self._hold[fn]  # the command of hold steps ago (0 before any)
                v_ref = float(gains[i] * self._sent[k][i]) if k >= 0 else 0.0
                pairs[fn] = mover.step(v_ref, v_meas)
                cmd[fn] = v_ref
            meas[fn] = v_meas
        return IkDriveStep(pairs, res, q_solve, self.horizon_s, cmd, meas, ref, float(res.v[self.index[SWING]]))
