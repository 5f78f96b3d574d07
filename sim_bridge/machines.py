"""The machines of the plant, one class per type: state, actuator commands, stepping.

Pure (no ROS, no CAN, no MuJoCo): the plant profiles (:mod:`sim_bridge.profiles`) build them from a machine of
the plant (:class:`~sim_bridge.spec.PlantMachine`: its tms_model description, start pose and joints) and map COM3
frames onto their commands. Each keeps its description as ``description``.
"""

from __future__ import annotations

import math

from sim_bridge.hydraulics import JointBank, ValveFront
from sim_bridge.spec import PlantMachine
from sim_bridge.tracks import SkidSteer, centre_to_tracks
from tms_model.cylinders import moment_arm
from tms_model.geometry import wrap_angle
from tms_model.machines import LIFT_JOINT, ROTATE_JOINT, VESSEL_JOINT, Machine

__all__ = ["Excavator", "CrawlerCarrier", "Dozer"]


class _Tracked:
    """What every machine on tracks shares: its skid-steer base (``self.base``) driven by track commands."""

    name: str
    description: Machine
    base: SkidSteer

    def _place(self, machine: PlantMachine, dt: float) -> None:
        self.name = machine.name
        self.description = machine.description
        self.base = SkidSteer(machine.description.tracks, machine.description.track_drive, dt, machine.pose)
        self.z = 0.0

    def set_centre_velocity(self, v: float, yaw_rate: float) -> None:
        t = self.description.tracks
        self.base.command[0], self.base.command[1] = centre_to_tracks(v, yaw_rate, t.gauge, t.max_yaw_rate)

    def set_track_speeds(self, left: float, right: float) -> None:
        self.base.command[0], self.base.command[1] = left, right


class Excavator(_Tracked):
    """Backhoe state: tracked base + hydraulic front joints (swing, boom, arm, bucket)."""

    def __init__(self, machine: PlantMachine, dt: float) -> None:
        self._place(machine, dt)
        d = machine.description
        assert d.bucket is not None and d.pump_flow is not None and d.cylinders is not None  # tms_model: every
        self.bucket = d.bucket  # excavator has them
        self.front = ValveFront(d.joints, d.drives, d.cylinders, machine.physics, d.pump_flow, dt)
        self.front.set_positions(dict(machine.start_joints))
        self._cyl_planes = [
            (c, (j.origin_xyz[0], j.origin_xyz[2]), j.origin_rpy[1], i + 1)
            for i, (c, j) in enumerate(zip(d.cylinders.all, d.joints[1:], strict=True))
        ]

    @property
    def bank(self) -> ValveFront:
        """The joints the machine reports and the MuJoCo model shows (the front)."""
        return self.front

    def set_front_velocity(self, velocities: dict[str, float]) -> None:
        """Velocity mode: joint speeds [rad/s] for the machine's own controller to meter."""
        self.front.pilot = None
        for name, v in velocities.items():
            self.front.command[self.front.names.index(name)] = v

    def set_front_pilot(self, pilot: dict[str, float]) -> None:
        """Pilot-pressure mode: p_plus - p_minus [MPa] per front joint, straight to the main spools."""
        self.front.pilot = [pilot[name] for name in self.front.names]

    def rest(self) -> None:
        self.front.rest()
        self.base.rest()

    def set_pilot_cutoff(self, engaged: bool) -> None:
        """Pilot cut-off (hydraulic lock) on/off; no-op when the machine YAML has no ``pilot_cutoff``."""
        c = self.description.pilot_cutoff
        if c is None:
            return
        self.front.set_cutoff(c.front_time_constant if engaged else None)
        self.base.set_cutoff(c.tracks_time_constant if engaged else None)

    def at_rest(self) -> bool:
        return self.front.at_rest() and self.base.at_rest()

    def step(self) -> None:
        """Valves for one step at the present pose (the dynamics move the joints: :mod:`sim_bridge.physics`)."""
        q = self.front.q
        for cyl, origin, pitch, i in self._cyl_planes:
            try:
                self.front.moment[i] = moment_arm(cyl, origin, pitch, q[i])
            except ValueError:
                pass  # beyond the linkage's closing range for an instant: keep the last ratio
        self.front.step()
        self.base.step()

    def tip_angle(self) -> float:
        """Angle of the bucket pin->tip line below horizontal [rad] (0 = pointing out, pi/2 = down).

        With all front axes parallel and the URDF's fixed pitches cancelling the link offsets, this is
        exactly boom + arm + bucket.
        """
        q = self.front.q
        return q[1] + q[2] + q[3]


class CrawlerCarrier(_Tracked):
    """Crawler dump state: tracked base + vessel (target-angle or velocity control) and, on a carrier with a rotating
    upper body (the MSTs), the swing (target-angle control; ``rotate_joint`` endless unless the description limits it).

    ``bank`` holds the joints in bus order (``rotate_joint`` first when there is one).
    """

    def __init__(self, machine: PlantMachine, dt: float) -> None:
        self._place(machine, dt)
        d = machine.description
        assert d.vessel is not None  # tms_model: every crawler dump has one
        self.vessel = d.vessel  # hinge, inner size, capacity, loading and dumping
        self.vessel_joint = d.joint(VESSEL_JOINT)  # angle 0 = lowered, + = raised
        #: the upper body's rotate_joint (None: the vessel does not swing); with it the vessel turns about the
        #: vertical axis through its origin
        self.swing_joint = d.joint(ROTATE_JOINT) if d.swing is not None else None
        self._swing_gain = d.swing.angle_gain if d.swing is not None else 0.0
        self.joints = JointBank(d.joints, d.drives, dt)
        self.joints.set_positions(dict(machine.start_joints))
        self._iv = self.joints.names.index(self.vessel_joint.name)
        self._isw = None if self.swing_joint is None else self.joints.names.index(self.swing_joint.name)
        self.vessel_target: float | None = None  # angle mode when not None
        self.swing_target: float | None = None

    @property
    def bank(self) -> JointBank:
        """The joints the machine reports and the MuJoCo model shows (swing if any, vessel)."""
        return self.joints

    @property
    def vessel_angle(self) -> float:
        return self.joints.q[self._iv]

    @property
    def vessel_rate(self) -> float:
        return self.joints.v[self._iv]

    @property
    def has_swing(self) -> bool:
        return self._isw is not None

    @property
    def swing_angle(self) -> float:
        """Angle of the upper body [rad], wrapped to [-pi, pi) (0 without a swing)."""
        return 0.0 if self._isw is None else wrap_angle(self.joints.q[self._isw])

    @property
    def swing_rate(self) -> float:
        return 0.0 if self._isw is None else self.joints.v[self._isw]

    def set_vessel_target(self, angle: float) -> None:
        lo, hi = self.vessel_joint.lower or 0.0, self.vessel_joint.upper or 0.0
        self.vessel_target = max(lo, min(hi, angle))

    def set_vessel_velocity(self, v: float) -> None:
        self.vessel_target = None
        self.joints.command[self._iv] = v

    def set_swing_target(self, angle: float) -> None:
        """Hold the upper body at ``angle`` (clamped to its limits, if any); ignored without a swing."""
        j = self.swing_joint
        if j is None or self._isw is None:
            return
        if j.lower is not None and j.upper is not None:
            angle = max(j.lower, min(j.upper, angle))
        self.swing_target = angle

    def hold_swing(self) -> None:
        self.swing_target = None
        if self._isw is not None:
            self.joints.command[self._isw] = 0.0

    def rest(self) -> None:
        """Hold the vessel and the swing where they are and stop the tracks."""
        self.vessel_target = None
        self.swing_target = None
        self.joints.rest()
        self.base.rest()

    def set_pilot_cutoff(self, engaged: bool) -> None:
        """Pilot cut-off (hydraulic lock) on/off; no-op when the machine YAML has no ``pilot_cutoff``."""
        c = self.description.pilot_cutoff
        if c is None:
            return
        if engaged:
            self.vessel_target = None
            self.swing_target = None
        self.joints.set_cutoff(c.front_time_constant if engaged else None)
        self.base.set_cutoff(c.tracks_time_constant if engaged else None)

    def at_rest(self) -> bool:
        return self.joints.at_rest() and self.base.at_rest()

    def step(self) -> None:
        if self.vessel_target is not None:
            err = self.vessel_target - self.joints.q[self._iv]
            self.joints.command[self._iv] = err * self.vessel.angle_gain
        if self.swing_target is not None and self._isw is not None:
            q = self.joints.q[self._isw]
            j = self.swing_joint
            # endless slew: the short way round; limited: straight to the target
            err = wrap_angle(self.swing_target - q) if j is not None and j.lower is None else self.swing_target - q
            self.joints.command[self._isw] = err * self._swing_gain
        self.joints.step()
        self.base.step()


class Dozer(_Tracked):
    """Dozer state: tracked base + blade lift (hold, target angle or velocity; ``lift_joint`` + = down)."""

    def __init__(self, machine: PlantMachine, dt: float) -> None:
        self._place(machine, dt)
        d = machine.description
        assert d.blade is not None  # tms_model: every dozer has one
        self.blade = d.blade  # edge, width, capacity, angle gain, cutting
        self.lift = d.joint(LIFT_JOINT)
        self.joints = JointBank([self.lift], d.drives, dt)
        self.joints.set_positions({self.lift.name: machine.start_joints[self.lift.name]})
        self.lift_target: float | None = None

    @property
    def bank(self) -> JointBank:
        return self.joints

    @property
    def lift_angle(self) -> float:
        return self.joints.q[0]

    @property
    def lift_rate(self) -> float:
        return self.joints.v[0]

    def set_lift_target(self, angle: float) -> None:
        j = self.lift
        self.lift_target = max(j.lower if j.lower is not None else angle, min(j.upper if j.upper is not None else angle,
                                                                              angle))

    def set_lift_velocity(self, v: float) -> None:
        self.lift_target = None
        self.joints.command[0] = v

    def rest(self) -> None:
        self.lift_target = None
        self.joints.rest()
        self.base.rest()

    def set_pilot_cutoff(self, engaged: bool) -> None:
        c = self.description.pilot_cutoff
        if c is None:
            return
        if engaged:
            self.lift_target = None
        self.joints.set_cutoff(c.front_time_constant if engaged else None)
        self.base.set_cutoff(c.tracks_time_constant if engaged else None)

    def at_rest(self) -> bool:
        return self.joints.at_rest() and self.base.at_rest()

    def edge_in_base(self) -> tuple[float, float, float]:
        """The blade's cutting edge in base_link [m] (lift_joint about y: + turns the arm's x axis down)."""
        j, e = self.lift, self.blade.edge_xyz
        q = self.joints.q[0]
        c, s = math.cos(q), math.sin(q)
        # rotation about +y by q: x' = c x + s z, z' = -s x + c z
        return (j.origin_xyz[0] + c * e[0] + s * e[2], j.origin_xyz[1] + e[1], j.origin_xyz[2] - s * e[0] + c * e[2])

    def step(self) -> None:
        if self.lift_target is not None:
            self.joints.command[0] = (self.lift_target - self.joints.q[0]) * self.blade.angle_gain
        self.joints.step()
        self.base.step()
