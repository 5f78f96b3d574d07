"""Excavator profile (ZX200, ZX120, ...): front joints and travel on the published COM3 excavator frames.

Commands: ``front_cmd`` VELOCITY -> ``Velocity_Cmd_1``, EFFORT -> ``Pilot_Pressure_Cmd_1``; ``tracks_cmd``
VELOCITY -> ``Velocity_Cmd_2`` per track, EFFORT -> ``Pilot_Pressure_Cmd_2``; ``cmd_vel`` -> ``Velocity_Cmd_2``
centre + yaw rate. Each also sets the matching signal switch of ``Machine_Setting_Cmd`` (front: velocity 2,
pilot 1; travel: pilot 1, per-track 2, centre 3). States: ``Front_Angle`` (+ the latest
``Front_Angular_Velocity``) -> joint states, ``Swing_Center_Position_3`` -> map pose and fix of the swing
centre, ``Roll_Pitch_Angle`` -> IMU.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from com3_can.outputs import FixOut, JointStateOut, OdomOut, Tx
from com3_can.profiles.base import ConverterProfile, Core
from com3_can.signal_map import EXCAVATOR_FRAMES as F
from com3_can.signal_map import EXCAVATOR_FRONT, TRACK_SIGNALS, TRACKS
from tms_model.com3 import VELOCITY
from tms_model.machines import EXCAVATOR

__all__ = ["ExcavatorProfile"]

_FRONT = {j.joint: j for j in EXCAVATOR_FRONT}


class ExcavatorProfile(ConverterProfile):
    machine_type = EXCAVATOR
    channels = {
        "front": (F["front_velocity"], F["front_pilot"]),
        "travel": (F["travel_velocity"], F["travel_pilot"]),
    }
    topics = frozenset({"front_cmd", "tracks_cmd", "cmd_vel"})
    state_handlers = {
        F["front_angle"]: "front_angle",
        "Roll_Pitch_Angle": "roll_pitch",
        "Swing_Center_Position_3": "swing_centre",
        "Machine_State": "machine_state",
    }

    def front_cmd(self, core: Core, names: Sequence[str], control_type: int, velocity: Sequence[float],
                  effort: Sequence[float], now: float) -> list[Tx]:
        vals = core.check_joint_cmd("front_cmd", tuple(_FRONT), names, control_type, velocity, effort)
        if control_type == VELOCITY:
            frame = core.codec.neutral(F["front_velocity"])
            for joint, v in vals.items():
                frame[_FRONT[joint].velocity_cmd] = v
            txs = core.accept("front_cmd", "front", {F["front_velocity"]: frame}, now)
            core.set_switch("front_signal_switch_command", 2.0)
            return txs
        frame = core.codec.neutral(F["front_pilot"])
        dz = core.config.effort_dead_zone
        for joint, e in vals.items():
            sig = _FRONT[joint]
            side = sig.pilot_plus if e > 0 else sig.pilot_minus
            frame[side] = core.pilot(e, float(dz.get(side, 0.0)))
        txs = core.accept("front_cmd", "front", {F["front_pilot"]: frame}, now)
        core.set_switch("front_signal_switch_command", 1.0)
        return txs

    def tracks_cmd(self, core: Core, names: Sequence[str], control_type: int, velocity: Sequence[float],
                   effort: Sequence[float], now: float) -> list[Tx]:
        t = TRACK_SIGNALS
        vals = core.check_joint_cmd("tracks_cmd", TRACKS, names, control_type, velocity, effort)
        left, right = vals.get("left_track", 0.0), vals.get("right_track", 0.0)
        if control_type == VELOCITY:
            frame = core.codec.neutral(F["travel_velocity"])
            frame.update({t.left_velocity_cmd: left, t.right_velocity_cmd: right})
            txs = core.accept("tracks_cmd", "travel", {F["travel_velocity"]: frame}, now)
            core.set_switch("travel_signal_switch_command", 2.0)
            return txs
        frame = core.codec.neutral(F["travel_pilot"])
        dz = float(core.config.effort_dead_zone.get("tracks", 0.0))
        for e, fwd, back in ((left, t.left_forward, t.left_backward), (right, t.right_forward, t.right_backward)):
            frame[fwd if e > 0 else back] = core.pilot(e, dz)
        txs = core.accept("tracks_cmd", "travel", {F["travel_pilot"]: frame}, now)
        core.set_switch("travel_signal_switch_command", 1.0)
        return txs

    def cmd_vel(self, core: Core, linear_x: float, angular_z: float, now: float) -> list[Tx]:
        t = TRACK_SIGNALS
        frame = core.codec.neutral(F["travel_velocity"])
        frame.update({t.centre_velocity_cmd: linear_x, t.yaw_rate_cmd: angular_z})
        txs = core.accept("cmd_vel", "travel", {F["travel_velocity"]: frame}, now)
        core.set_switch("travel_signal_switch_command", 3.0)
        return txs

    # state frames
    def front_angle(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        vel = core.state.get(F["front_angular_velocity"], {})
        return [JointStateOut(
            tuple(_FRONT),
            tuple(values[s.angle] for s in EXCAVATOR_FRONT),
            tuple(vel.get(s.angular_velocity, 0.0) for s in EXCAVATOR_FRONT),
        )]

    def swing_centre(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        try:
            x = core.state["Swing_Center_Position_1"]["swing_center_position_x"]
            y = core.state["Swing_Center_Position_2"]["swing_center_position_y"]
        except KeyError:
            return []
        z = values["swing_center_position_z"]
        ox, oy, oz = core.config.map_origin
        lat, lon = core.plane_to_geodetic(x, y)
        fix = FixOut(lat, lon, z, 2, None)
        az = core.state.get("Vehicle_Azimuth")
        if az is None:  # the pose in map needs the heading: none with a made-up yaw of 0, the fix alone
            return [fix]
        return [OdomOut(x - ox, y - oy, z - oz, -az["track_body_azimuth"], 0.0, 0.0, frame_id="map"), fix]

