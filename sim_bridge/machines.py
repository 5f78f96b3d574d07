"""The machines of the plant, one class per type: state, actuator commands, stepping.

Pure (no ROS, no CAN, no MuJoCo): the plant profiles (:mod:`sim_bridge.profiles`) build them from a
machine spec and map COM3 frames onto their commands.
"""

from __future__ import annotations

import math

from sim_bridge.config import CarrierSpec, DozerSpec, ExcavatorSpec
from sim_bridge.hydraulics import JointBank
from sim_bridge.tracks import SkidSteer, centre_to_tracks
from tms_model.geometry import wrap_angle

__all__ = ["Excavator", "CrawlerCarrier", "Dozer"]


class _Tracked:
    """What every machine on tracks shares: its skid-steer base (``self.base``) driven by track commands."""

    spec: ExcavatorSpec | CarrierSpec | DozerSpec
    base: SkidSteer

    def set_centre_velocity(self, v: float, yaw_rate: float) -> None:
        t = self.spec.tracks
        self.base.command[0], self.base.command[1] = centre_to_tracks(v, yaw_rate, t.gauge, t.max_yaw_rate)

    def set_track_speeds(self, left: float, right: float) -> None:
        self.base.command[0], self.base.command[1] = left, right


class Excavator(_Tracked):
    """Backhoe state: tracked base + hydraulic front joints (swing, boom, arm, bucket)."""

    def __init__(self, spec: ExcavatorSpec, dt: float, pose: tuple[float, float, float]) -> None:
        s = spec
        self.spec = s
        self.front = JointBank(s.joints, s.drives, dt, pump_flow=s.pump_flow)
        self.front.set_positions(s.home_pose)
        self.base = SkidSteer(s.tracks, dt, pose)
        self.z = 0.0

    @property
    def bank(self) -> JointBank:
        """The joints the machine reports and the MuJoCo model shows (the front)."""
        return self.front

    def set_front_velocity(self, velocities: dict[str, float]) -> None:
        for name, v in velocities.items():
            self.front.command[self.front.names.index(name)] = v

    def rest(self) -> None:
        self.front.rest()
        self.base.rest()

    def set_pilot_cutoff(self, engaged: bool) -> None:
        """Pilot cut-off (hydraulic lock) on/off; no-op when the machine YAML has no ``pilot_cutoff``."""
        c = self.spec.pilot_cutoff
        if c is None:
            return
        self.front.set_cutoff(c.front_time_constant if engaged else None)
        self.base.set_cutoff(c.tracks_time_constant if engaged else None)

    def at_rest(self) -> bool:
        return self.front.at_rest() and self.base.at_rest()

    def step(self) -> None:
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

    def __init__(self, spec: CarrierSpec, dt: float, pose: tuple[float, float, float]) -> None:
        s = spec
        self.spec = s
        self.joints = JointBank(s.joints, s.drives, dt)
        self._iv = self.joints.names.index(s.vessel.name)
        self._isw = None if s.swing is None else self.joints.names.index(s.swing.name)
        self.base = SkidSteer(s.tracks, dt, pose)
        self.vessel_target: float | None = None  # angle mode when not None
        self.swing_target: float | None = None
        self.z = 0.0

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
        lo, hi = self.spec.vessel.lower or 0.0, self.spec.vessel.upper or 0.0
        self.vessel_target = max(lo, min(hi, angle))

    def set_vessel_velocity(self, v: float) -> None:
        self.vessel_target = None
        self.joints.command[self._iv] = v

    def set_swing_target(self, angle: float) -> None:
        """Hold the upper body at ``angle`` (clamped to its limits, if any); ignored without a swing."""
        j = self.spec.swing
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
        c = self.spec.pilot_cutoff
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
            self.joints.command[self._iv] = err * self.spec.vessel_angle_gain
        if self.swing_target is not None and self._isw is not None:
            q = self.joints.q[self._isw]
            j = self.spec.swing
            # endless slew: the short way round; limited: straight to the target
            err = wrap_angle(self.swing_target - q) if j is not None and j.lower is None else self.swing_target - q
            self.joints.command[self._isw] = err * self.spec.swing_angle_gain
        self.joints.step()
        self.base.step()


class Dozer(_Tracked):
    """Dozer state: tracked base + blade lift (hold, target angle or velocity; ``lift_joint`` + = down)."""

    def __init__(self, spec: DozerSpec, dt: float, pose: tuple[float, float, float]) -> None:
        self.spec = spec
        self.joints = JointBank([spec.lift], spec.drives, dt)
        self.joints.set_positions({spec.lift.name: spec.home_lift})
        self.base = SkidSteer(spec.tracks, dt, pose)
        self.lift_target: float | None = None
        self.z = 0.0

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
        j = self.spec.lift
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
        c = self.spec.pilot_cutoff
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
        j, e = self.spec.lift, self.spec.blade.edge_xyz
        q = self.joints.q[0]
        c, s = math.cos(q), math.sin(q)
        # rotation about +y by q: x' = c x + s z, z' = -s x + c z
        return (j.origin_xyz[0] + c * e[0] + s * e[2], j.origin_xyz[1] + e[1], j.origin_xyz[2] - s * e[0] + c * e[2])

    def step(self) -> None:
        if self.lift_target is not None:
            self.joints.command[0] = (self.lift_target - self.joints.q[0]) * self.spec.blade.angle_gain
        self.joints.step()
        self.base.step()
