"""The machines of the plant, one class per type: state, actuator commands, stepping.

Pure (no ROS, no CAN, no MuJoCo): the plant profiles (:mod:`sim_bridge.profiles`) build them from a
machine spec and map COM3 frames onto their commands.
"""

from __future__ import annotations

from sim_bridge.config import CarrierSpec, ExcavatorSpec
from sim_bridge.hydraulics import JointBank
from sim_bridge.tracks import SkidSteer, centre_to_tracks

__all__ = ["Excavator", "CrawlerCarrier"]


class _Tracked:
    """What every machine on tracks shares: its skid-steer base (``self.base``) driven by track commands."""

    spec: ExcavatorSpec | CarrierSpec
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
    """Crawler dump state: tracked base + vessel (target-angle or velocity control)."""

    def __init__(self, spec: CarrierSpec, dt: float, pose: tuple[float, float, float]) -> None:
        s = spec
        self.spec = s
        self.vessel = JointBank([s.vessel], s.drives, dt)
        self.base = SkidSteer(s.tracks, dt, pose)
        self.vessel_target: float | None = None  # angle mode when not None
        self.z = 0.0

    @property
    def bank(self) -> JointBank:
        """The joints the machine reports and the MuJoCo model shows (the vessel)."""
        return self.vessel

    @property
    def vessel_angle(self) -> float:
        return self.vessel.q[0]

    def set_vessel_target(self, angle: float) -> None:
        lo, hi = self.spec.vessel.lower or 0.0, self.spec.vessel.upper or 0.0
        self.vessel_target = max(lo, min(hi, angle))

    def set_vessel_velocity(self, v: float) -> None:
        self.vessel_target = None
        self.vessel.command[0] = v

    def rest(self) -> None:
        """Hold the vessel where it is and stop the tracks."""
        self.vessel_target = None
        self.vessel.rest()
        self.base.rest()

    def set_pilot_cutoff(self, engaged: bool) -> None:
        """Pilot cut-off (hydraulic lock) on/off; no-op when the machine YAML has no ``pilot_cutoff``."""
        c = self.spec.pilot_cutoff
        if c is None:
            return
        if engaged:
            self.vessel_target = None
        self.vessel.set_cutoff(c.front_time_constant if engaged else None)
        self.base.set_cutoff(c.tracks_time_constant if engaged else None)

    def at_rest(self) -> bool:
        return self.vessel.at_rest() and self.base.at_rest()

    def step(self) -> None:
        if self.vessel_target is not None:
            err = self.vessel_target - self.vessel.q[0]
            self.vessel.command[0] = err * self.spec.vessel_angle_gain
        self.vessel.step()
        self.base.step()
