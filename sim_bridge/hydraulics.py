"""Hydraulic actuator model: dead time, first-order lag, velocity limits, shared pump flow, end stops.

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

from tms_model.machines import Joint, JointDrive

__all__ = ["DeadTimeLag", "JointBank"]


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
