"""Hydraulic valve models: the excavator front in cylinder space (:class:`ValveFront`) and, for the other machines'
joints, dead time, first-order lag, velocity limits, shared pump flow, end stops (:class:`JointBank`).

Pilot cut-off (:meth:`JointBank.set_cutoff`): the command path is bypassed, the queued pilot signal is
vented and every output decays to zero with the spool-centring time constant (no dead time).

Per joint and per step ``dt``::

    command --clamp(+-v_max)--> dead time (FIFO of round(T_d/dt) steps) --> first-order lag
    (v += (u - v)(1 - exp(-dt/tau))) --> pump-flow share --> q += v dt, held at the end stops

The shared pumps: a joint with ``flow_at_limit > 0`` draws ``flow_at_limit * |v| / v_max`` L/min;
when the sum exceeds ``pump_flow`` every shared joint is slowed by the same factor (a load-sensing
system dividing flow in proportion). Pure Python floats: this runs every 10 ms step for every joint
and must stay in the microseconds.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence

from sim_bridge.physics import PhysicsSpec
from tms_model.cylinders import Cylinders
from tms_model.machines import Joint, JointDrive

__all__ = ["DeadTimeLag", "JointBank", "ValveFront"]


class DeadTimeLag:
    """A pure delay of ``dead_time`` followed by a first-order lag of ``time_constant``, clamped to ``limit``."""

    def __init__(self, dead_time: float, time_constant: float, limit: float, dt: float) -> None:
        self.limit = limit
        steps = max(0, round(dead_time / dt))
        self._fifo: deque[float] = deque([0.0] * steps, maxlen=steps) if steps else deque()
        self._alpha = 1.0 if time_constant <= 0 else 1.0 - math.exp(-dt / time_constant)
        self.value = 0.0

    def step(self, command: float) -> float:
        """Advance one step with ``command`` and return the lagged output."""
        u = max(-self.limit, min(self.limit, command))
        if self._fifo.maxlen:
            delayed = self._fifo[0]
            self._fifo.append(u)
        else:
            delayed = u
        self.value += (delayed - self.value) * self._alpha
        return self.value

    def vent(self) -> None:
        """Pilot cut-off engaged: the pilot pressure queued in the dead time is gone (FIFO zeroed)."""
        for i in range(len(self._fifo)):
            self._fifo[i] = 0.0

    def step_vented(self, alpha: float) -> float:
        """One step with the pilot cut off: the output decays to zero with ``alpha`` (spools centring)."""
        self.value -= self.value * alpha
        return self.value

    def reset(self, value: float = 0.0) -> None:
        """Forget the pipeline (replay, teleport)."""
        for i in range(len(self._fifo)):
            self._fifo[i] = value
        self.value = value


class JointBank:
    """The hydraulic joints of one machine with their positions, velocities and the shared pumps."""

    def __init__(
        self, joints: Sequence[Joint], drives: Mapping[str, JointDrive], dt: float, *, pump_flow: float = math.inf
    ) -> None:
        """``joints`` (geometry, limits) and ``drives`` (actuator per joint name) as the machine description has
        them."""
        self.joints = tuple(joints)
        self.drives = tuple(drives[j.name] for j in joints)
        self.names = tuple(j.name for j in joints)
        self.dt = dt
        self.pump_flow = pump_flow
        self.actuators = [
            DeadTimeLag(d.dead_time, d.time_constant, j.velocity, dt)
            for j, d in zip(self.joints, self.drives, strict=True)
        ]
        self.q = [0.0] * len(joints)
        self.v = [0.0] * len(joints)
        self.command = [0.0] * len(joints)
        self.flow_scale = 1.0  # last pump-flow scaling (1 = pumps not saturated)
        self.cut_alpha: float | None = None  # pilot cut off: per-step decay factor of every output
        self.v_ref = [0.0] * len(joints)  # the speed the valves meter (the dynamics' reference; ``v`` is measured)

    def set_cutoff(self, time_constant: float | None) -> None:
        """Engage (a spool-centring time constant [s]) or release (None) the pilot cut-off.

        Engaging vents the dead-time pipelines and zeroes the commands: after a release nothing moves
        until a new command arrives (and then through the normal dead time).
        """
        if time_constant is None:
            self.cut_alpha = None
            return
        for act in self.actuators:
            act.vent()
        self.rest()
        self.cut_alpha = 1.0 if time_constant <= 0 else 1.0 - math.exp(-self.dt / time_constant)

    def set_positions(self, q: dict[str, float]) -> None:
        for name, value in q.items():
            i = self.names.index(name)
            j = self.joints[i]
            if j.lower is not None and j.upper is not None:
                value = max(j.lower, min(j.upper, value))
            self.q[i] = value

    def step(self) -> None:
        """Advance all joints by one ``dt`` with the current ``command`` velocities."""
        if self.cut_alpha is not None:
            lagged = [act.step_vented(self.cut_alpha) for act in self.actuators]
        else:
            lagged = [act.step(cmd) for act, cmd in zip(self.actuators, self.command, strict=True)]
        demand = 0.0
        for j, d, v in zip(self.joints, self.drives, lagged, strict=True):
            if d.flow_at_limit > 0.0 and j.velocity > 0.0:
                demand += d.flow_at_limit * abs(v) / j.velocity
        scale = self.pump_flow / demand if demand > self.pump_flow else 1.0
        self.flow_scale = scale
        dt = self.dt
        for i, (j, d) in enumerate(zip(self.joints, self.drives, strict=True)):
            v = lagged[i] * scale if d.flow_at_limit > 0.0 else lagged[i]
            if scale < 1.0 and d.flow_at_limit > 0.0:
                self.actuators[i].value = v  # the flow shortfall is what the joint actually did
            q = self.q[i] + v * dt
            if j.upper is not None and q >= j.upper and v > 0.0:
                q, v = j.upper, 0.0
                self.actuators[i].value = 0.0
            elif j.lower is not None and q <= j.lower and v < 0.0:
                q, v = j.lower, 0.0
                self.actuators[i].value = 0.0
            self.q[i] = q
            self.v[i] = v
            self.v_ref[i] = v

    def set_forces(self, forces: Sequence[float], speeds: Sequence[float]) -> None:
        """The dynamics' drive torques: nothing to report on these joints (no pressure model, no pressure frames)."""

    def reset(self) -> None:
        """Forget the pipelines (replay, teleport)."""
        for act in self.actuators:
            act.reset()

    def flows(self) -> list[float]:
        """Flow [L/min] each joint draws now (0 for joints off the shared pumps)."""
        return [
            d.flow_at_limit * abs(v) / j.velocity if d.flow_at_limit > 0 and j.velocity > 0 else 0.0
            for j, d, v in zip(self.joints, self.drives, self.v, strict=True)
        ]

    def rest(self) -> None:
        """Command zero on every joint (the pipeline still drains through dead time and lag)."""
        for i in range(len(self.command)):
            self.command[i] = 0.0

    def at_rest(self, tol: float = 1e-3) -> bool:
        return all(abs(v) < tol for v in self.v)


class ValveFront:
    """An excavator's front hydraulics in cylinder space: command -> pilot pressure -> main spool -> flow -> the
    reference speed of each drive (swing motor, boom, arm and bucket cylinders).

    Per function ``i`` and step ``dt``::

        command (a joint speed, or a pilot pressure difference) -> dead time (``hydraulics.dead_time_s``: controller,
        pilot line and valve)
        -> velocity mode (the machine's own controller): u = dq_cmd * dl/dq * A_side / Q_fn at the present pose (the
            spool fraction that passes the flow for the commanded speed; the controller knows the spool's overlap and
            skips it); pilot mode: spool target = clip((|p_a - p_b| - p_crack) / (p_full - p_crack), 0, 1)
        -> spool lag (``hydraulics.time_constant_s``)
        -> opening max(0, |x| - overlap) / (1 - overlap) -> flow demand opening * Q_fn (pressure-compensated:
        load-independent while the pump keeps its margin)
        -> pumps: p_pump = max(load pressure) + LS margin; supply = min(pump flow, power / p_pump); every function
        slowed by the same factor when the demands exceed it
        -> v_ref = Q / A_side (cap area extending, annulus retracting; the swing: Q / displacement per rad)

    The chamber pressures come back from the dynamics (``set_forces``): the load pressure of the side being fed.
    """

    def __init__(self, joints: Sequence[Joint], drives: Mapping[str, JointDrive], cylinders: Cylinders,
                 physics: PhysicsSpec, pump_flow: float, dt: float) -> None:
        self.joints = tuple(joints)
        self.names = tuple(j.name for j in joints)
        self.dt = dt
        n = len(joints)
        swing = cylinders.swing
        #: per function: area extending, area retracting [m^2] (the swing: displacement per rad both ways)
        self.a_ext = [swing.displacement_per_rad] + [c.cap_area for c in cylinders.all]
        self.a_ret = [swing.displacement_per_rad] + [c.rod_area for c in cylinders.all]
        self.relief = [swing.relief_mpa * 1e6] + [cylinders.relief_pa] * 3
        self.q_fn = [physics.function_flow_lpm[name] / 60000.0 for name in self.names]
        self.pump_flow = pump_flow / 60000.0
        self.pump_power = physics.pump_power_kw * 1e3
        self.margin = physics.ls_margin_mpa * 1e6
        self.tank = physics.tank_pressure_mpa * 1e6
        self.crack, self.full = physics.pilot_crack_mpa, physics.pilot_full_mpa
        self.overlap = physics.spool_overlap
        self.delays = [DeadTimeLag(drives[name].dead_time, 0.0, math.inf, dt) for name in self.names]
        self.spool_alpha = [1.0 if drives[name].time_constant <= 0 else 1.0 - math.exp(-dt / drives[name].time_constant)
                            for name in self.names]
        self.spool = [0.0] * n
        self.q = [0.0] * n
        self.v = [0.0] * n
        self.command = [0.0] * n  # velocity mode: joint speeds [rad/s]
        self.pilot: list[float] | None = None  # pilot mode: p_plus - p_minus per function [MPa]
        self.moment = [1.0] * n  # dl/dq of each function at the current pose (1 for the swing)
        self.v_ref = [0.0] * n  # drive speed the valves meter [m/s, rad/s]
        self.flow = [0.0] * n  # flow into the drive [m^3/s], + extending
        self.p_ext = [self.tank] * n  # pressure of the extending side (cap; swing port A) [Pa]
        self.p_ret = [self.tank] * n  # pressure of the retracting side (rod; swing port B) [Pa]
        self.drive_speed = [0.0] * n
        self.flow_scale = 1.0
        self.pump_pressure = self.tank
        self.cut_alpha: float | None = None
        self.brake_delay = physics.swing_brake_delay_s
        self.brake_torque = swing.brake_torque
        self._swing_idle = 0.0  # [s] the swing's spool has been closed
        self.swing_brake = False  # the swing parking brake holds (spring-applied, released by pilot pressure)

    # -- commands ------------------------------------------------------------------------------------
    def set_cutoff(self, time_constant: float | None) -> None:
        """Pilot cut-off: pilot lines vented (the dead-time pipelines emptied), spools centre with ``time_constant``."""
        if time_constant is None:
            self.cut_alpha = None
            return
        for d in self.delays:
            d.vent()
        self.rest()
        self.cut_alpha = 1.0 if time_constant <= 0 else 1.0 - math.exp(-self.dt / time_constant)

    def rest(self) -> None:
        for i in range(len(self.command)):
            self.command[i] = 0.0
        self.pilot = None

    def set_positions(self, q: dict[str, float]) -> None:
        for name, value in q.items():
            self.q[self.names.index(name)] = value

    def reset(self) -> None:
        for d in self.delays:
            d.reset()
        self.spool = [0.0] * len(self.spool)

    def at_rest(self, tol: float = 1e-3) -> bool:
        return all(abs(v) < tol for v in self.v)

    # -- stepping ------------------------------------------------------------------------------------
    def _target(self, i: int, value: float) -> float:
        """Spool target in [-1, 1] of function ``i`` for a delayed command ``value`` (pilot [MPa] or speed)."""
        if self.pilot is not None:
            # the pilot pair is named by joint direction (COM3): the spool moves the cylinder the way that turns so
            x = min(1.0, max(0.0, (abs(value) - self.crack) / (self.full - self.crack)))
            return math.copysign(x, value * self.moment[i]) if x > 0 else 0.0
        vmax = self.joints[i].velocity  # the machine's controller holds each joint to its rated speed
        s = max(-vmax, min(vmax, value)) * self.moment[i]
        if s == 0.0:
            return 0.0
        area = self.a_ext[i] if s > 0 else self.a_ret[i]
        u = min(1.0, abs(s) * area / self.q_fn[i]) if self.q_fn[i] > 0 else 0.0
        return math.copysign(self.overlap + u * (1.0 - self.overlap), s) if u > 1e-4 else 0.0

    def step(self) -> None:
        """One ``dt``: spools, flows, pump sharing -> ``v_ref`` of every drive."""
        n = len(self.names)
        ol = self.overlap
        demand = [0.0] * n
        for i in range(n):
            if self.cut_alpha is not None:
                self.spool[i] -= self.spool[i] * self.cut_alpha
            else:
                x_d = self._target(i, self.delays[i].step(self.command[i] if self.pilot is None else self.pilot[i]))
                self.spool[i] += (x_d - self.spool[i]) * self.spool_alpha[i]
            x = self.spool[i]
            opening = max(0.0, abs(x) - ol) / (1.0 - ol)
            demand[i] = math.copysign(opening * self.q_fn[i], x) if opening > 0 else 0.0
        # the parking brake is spring-applied and released by pilot pressure: it applies at once when the pilot line
        # is cut off (hydraulic lock), else once the swing spool has been closed for its delay and the swing is still
        self._swing_idle = self._swing_idle + self.dt if demand[0] == 0.0 else 0.0
        self.swing_brake = self.cut_alpha is not None or (
            self._swing_idle >= self.brake_delay and abs(self.v[0]) < 0.05)
        loads = [self.p_ext[i] if demand[i] > 0 else self.p_ret[i] for i in range(n) if demand[i] != 0.0]
        p_pump = min(max(loads) + self.margin, max(self.relief)) if loads else self.tank + self.margin
        supply = min(self.pump_flow, self.pump_power / p_pump)
        total = sum(abs(q) for q in demand)
        scale = supply / total if total > supply else 1.0
        self.flow_scale, self.pump_pressure = scale, p_pump
        for i in range(n):
            q = demand[i] * scale
            self.flow[i] = q
            self.v_ref[i] = q / (self.a_ext[i] if q > 0 else self.a_ret[i]) if q != 0.0 else 0.0

    def set_forces(self, forces: Sequence[float], speeds: Sequence[float]) -> None:
        """Chamber pressures from the drive forces [N, N m] the dynamics produced (the low side at tank)."""
        for i, f in enumerate(forces):
            ae, ar, pt = self.a_ext[i], self.a_ret[i], self.tank
            if f >= 0.0:
                self.p_ext[i], self.p_ret[i] = (f + pt * ar) / ae, pt
            else:
                self.p_ext[i], self.p_ret[i] = pt, (-f + pt * ae) / ar
            self.drive_speed[i] = speeds[i]

    def flows(self) -> list[float]:
        """Flow [L/min] into each drive's extending side now (the piston's speed times its area)."""
        return [s * self.a_ext[i] * 60000.0 for i, s in enumerate(self.drive_speed)]
