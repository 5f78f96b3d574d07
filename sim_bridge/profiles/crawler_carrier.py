"""Crawler-carrier plant profile (IC120, MST-110CR, MST-2200VD): our COM3 extension frames on a :class:`CrawlerCarrier`.

Commands: ``Velocity_Cmd`` by ``velocity_mode`` (0 centre + yaw rate, 1 per track; pilot input is not
modelled and stops the tracks), ``Vessel_Cmd`` (enable 1: target angle; 0 or lever dump mode: hold),
``Swing_Cmd`` (enable 1: target swing angle; 0 or lever swing mode: hold; counted and ignored by a carrier
without a swing). States: track velocities, vessel angle, swing angle (0 without a swing), azimuth and yaw
rate, roll/pitch, GNSS fix of the base (RTK noise).
"""

from __future__ import annotations

from com3_can.profiles.crawler_carrier import CrawlerCarrierProfile
from com3_can.signal_map import CARRIER_FRAMES as F
from com3_can.signal_map import CARRIER_SWING as S
from com3_can.signal_map import CARRIER_VESSEL as V
from com3_can.signal_map import TRACK_SIGNALS as T
from sim_bridge.machines import CrawlerCarrier
from sim_bridge.profiles.base import PlantBus, PlantProfile, Side
from sim_bridge.profiles.common import tracked_state, vec
from sim_bridge.spec import PlantMachine
from tms_model.machines import ROTATE_JOINT, VESSEL_JOINT

__all__ = ["CrawlerCarrierPlantProfile"]


class CrawlerCarrierPlantProfile(PlantProfile):
    machine_type = CrawlerCarrierProfile.machine_type
    motion_frames = frozenset(f for frames in CrawlerCarrierProfile.channels.values() for f in frames)

    @staticmethod
    def make_machine(machine: PlantMachine, dt: float) -> CrawlerCarrier:
        return CrawlerCarrier(machine, dt)

    @staticmethod
    def mjcf(machine: PlantMachine) -> list[str]:
        name, d = machine.name, machine.description
        assert d.vessel is not None  # tms_model: every crawler dump has one
        length, width = d.vessel.inner_length, d.vessel.inner_width
        vessel = d.joint(VESSEL_JOINT)
        lines = [
            f'    <body name="{name}_base" mocap="true">',
            f'      <geom type="box" size="{d.footprint.length / 2} {d.footprint.width / 2} 0.45" pos="0 0 0.45" '
            'material="ic" contype="0" conaffinity="0"/>',
        ]
        indent = "      "
        if d.swing is not None:  # the rotating upper body carries the vessel
            sw = d.joint(ROTATE_JOINT)
            rng = "" if sw.lower is None else f' range="{sw.lower} {sw.upper}" limited="true"'
            lines += [
                f'{indent}<body name="{name}_{sw.child}" pos="{vec(sw.origin_xyz)}">',
                f'{indent}  <joint name="{name}_{sw.name}" type="hinge" axis="0 0 1"{rng}/>',
                f'{indent}  <geom type="cylinder" size="1.0 0.1" material="ic" contype="0" conaffinity="0" '
            f'mass="{d.masses["body"]}"/>',
            ]
            indent += "  "
        lines += [
            f'{indent}<body name="{name}_vessel_link" pos="{vec(vessel.origin_xyz)}">',
            f'{indent}  <joint name="{name}_{vessel.name}" type="hinge" axis="0 -1 0"'
            f' range="{vessel.lower} {vessel.upper}" limited="true"/>',
            f'{indent}  <geom type="box" size="{length / 2} {width / 2} 0.05" pos="{length / 2} 0 0.53" material="ic" '
            f'contype="0" conaffinity="0" mass="{d.masses["vessel"]}"/>',
            f'{indent}  <site name="{name}_vessel_centre" pos="{length / 2} 0 0.53" size="0.1"/>',
            f"{indent}</body>",
        ]
        if d.swing is not None:
            lines.append("      </body>")
        lines.append("    </body>")
        return lines

    @staticmethod
    def command(io: PlantBus, side: Side, frame: str, v: dict[str, float]) -> None:
        ic: CrawlerCarrier = side.machine
        s = side.settings
        if frame == F["setting"]:
            side.settings = v
        elif frame == F["travel_velocity"]:
            mode = 0 if s is None else int(s["velocity_mode"])
            if mode == 0:
                ic.set_centre_velocity(v[T.centre_velocity_cmd], v[T.yaw_rate_cmd])
            elif mode == 1:
                ic.set_track_speeds(v[T.left_velocity_cmd], v[T.right_velocity_cmd])
            else:  # pilot input: not modelled on the carrier
                side.counters["ignored_unsupported_mode"] += 1
                ic.set_track_speeds(0.0, 0.0)
        elif frame == F["vessel"]:
            lever = s is not None and int(s["dump_mode"]) == 1
            if v[V.enable_cmd] >= 0.5 and not lever:
                ic.set_vessel_target(v[V.target_angle_cmd])
            else:
                ic.set_vessel_velocity(0.0)
        elif frame == F["swing"]:
            if not ic.has_swing:
                if v[S.enable_cmd] >= 0.5:
                    side.counters["ignored_no_swing"] += 1
                return
            lever = s is not None and int(s.get(S.mode_setting, 0)) == 1  # lever input: not modelled, hold
            if v[S.enable_cmd] >= 0.5 and not lever:
                ic.set_swing_target(v[S.target_angle_cmd])
            else:
                ic.hold_swing()

    @staticmethod
    def state(io: PlantBus, side: Side, frame: str) -> dict[str, float]:
        ic: CrawlerCarrier = side.machine
        if frame == F["vessel_angle"]:
            return {V.angle: ic.vessel_angle, V.angular_velocity: ic.vessel_rate}
        if frame == F["swing_angle"]:
            return {S.angle: ic.swing_angle, S.angular_velocity: ic.swing_rate}
        # travel, azimuth, attitude, GNSS and Machine_State frames are every tracked machine's
        return tracked_state(io, side, frame)
