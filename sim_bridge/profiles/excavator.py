"""Excavator plant profile (ZX200, ZX120, ...): the published COM3 excavator frames on an :class:`Excavator`.

Commands: ``Machine_Setting_Cmd`` selects the front source (1 pilot pressure, 2 velocity) and the travel
source (1 pilot, 2 per-track velocity, 3 centre velocity + yaw rate). Until a setting frame has arrived,
velocity frames are honoured (centre+yaw when non-zero, else per-track). Pilot pressure maps linearly
to velocity: ``v = v_max * (p_a - p_b) / 5 MPa``. States: joint angles/velocities, azimuths, the swing
centre in the site CRS (RTK noise), pin positions in ``base_link``, flows, pressures, pilot echoes.
"""

from __future__ import annotations

import math
from typing import Any

from com3_can.profiles.excavator import ExcavatorProfile
from com3_can.signal_map import EXCAVATOR_FRAMES as F
from com3_can.signal_map import EXCAVATOR_FRONT, PILOT_MAX_MPA
from com3_can.signal_map import TRACK_SIGNALS as T
from sim_bridge.machines import Excavator
from sim_bridge.profiles.base import PlantBus, PlantProfile, Side
from sim_bridge.profiles.common import vec
from sim_bridge.spec import PlantMachine
from tms_model.geometry import wrap_angle

__all__ = ["ExcavatorPlantProfile"]

_LINK_BOX = {  # visual boxes per link: (half sizes, offset in link frame), ZX200-sized
    "body_link": ((1.4, 1.3, 0.5), (-0.9, 0.0, 0.2)),
    "boom_link": ((2.8, 0.3, 0.3), (2.75, 0.0, 1.0)),
    "arm_link": ((1.4, 0.2, 0.2), (0.95, 0.0, 1.05)),
    "bucket_link": ((0.6, 0.5, 0.3), (0.6, 0.0, 0.5)),
}


class ExcavatorPlantProfile(PlantProfile):
    machine_type = ExcavatorProfile.machine_type
    motion_frames = frozenset(f for frames in ExcavatorProfile.channels.values() for f in frames)

    @staticmethod
    def make_machine(machine: PlantMachine, dt: float) -> Excavator:
        return Excavator(machine, dt)

    @staticmethod
    def mjcf(machine: PlantMachine) -> list[str]:
        name, d = machine.name, machine.description
        assert d.bucket is not None  # tms_model: every excavator has one
        lines = [
            f'    <body name="{name}_base" mocap="true">',
            f'      <geom type="box" size="{d.footprint.length / 2} {d.footprint.width / 2} 0.45" pos="0 0 0.45" '
            'material="zx" contype="0" conaffinity="0"/>',
        ]
        indent = "      "
        closes = []
        for j in d.joints:
            half, off = _LINK_BOX.get(j.child, ((0.2, 0.2, 0.2), (0, 0, 0)))
            lines.append(
                f'{indent}<body name="{name}_{j.child}" pos="{vec(j.origin_xyz)}" euler="{vec(j.origin_rpy)}">'
            )
            rng = "" if j.lower is None else f' range="{j.lower} {j.upper}" limited="true"'
            lines.append(f'{indent}  <joint name="{name}_{j.name}" type="hinge" axis="{vec(j.axis)}"{rng}/>')
            lines.append(f'{indent}  <geom type="box" size="{vec(half)}" pos="{vec(off)}" material="zx" contype="0" '
                         'conaffinity="0" mass="1"/>')
            closes.append(f"{indent}</body>")
            indent += "  "
        lines.append(f'{indent}<site name="{name}_bucket_tip" pos="{vec(d.bucket.tip_xyz)}" size="0.08"/>')
        lines.extend(reversed(closes))
        lines.append("    </body>")
        return lines

    @staticmethod
    def command(io: PlantBus, side: Side, frame: str, v: dict[str, float]) -> None:
        zx: Excavator = side.machine
        s = side.settings
        front_mode = None if s is None else int(s["front_signal_switch_command"])
        travel_mode = None if s is None else int(s["travel_signal_switch_command"])
        if frame == F["setting"]:
            side.settings = v
        elif frame == F["front_velocity"]:
            if front_mode in (None, 2):
                zx.set_front_velocity({j.joint: v[j.velocity_cmd] for j in EXCAVATOR_FRONT})
        elif frame == F["front_pilot"]:
            side.pilot.update(v)
            if front_mode == 1:
                vmax = {j.name: j.velocity for j in zx.description.joints}
                zx.set_front_velocity(
                    {
                        j.joint: vmax[j.joint] * (v[j.pilot_plus] - v[j.pilot_minus]) / PILOT_MAX_MPA
                        for j in EXCAVATOR_FRONT
                    }
                )
        elif frame == F["travel_velocity"]:
            centre, yaw = v[T.centre_velocity_cmd], v[T.yaw_rate_cmd]
            left, right = v[T.left_velocity_cmd], v[T.right_velocity_cmd]
            if travel_mode == 3 or (travel_mode is None and (centre != 0.0 or yaw != 0.0)):
                zx.set_centre_velocity(centre, yaw)
            elif travel_mode in (2, None):
                zx.set_track_speeds(left, right)
        elif frame == F["travel_pilot"]:
            side.pilot.update(v)
            if travel_mode == 1:
                vmax = zx.description.tracks.max_speed
                zx.set_track_speeds(
                    vmax * (v[T.left_forward] - v[T.left_backward]) / PILOT_MAX_MPA,
                    vmax * (v[T.right_forward] - v[T.right_backward]) / PILOT_MAX_MPA,
                )

    @staticmethod
    def state(io: PlantBus, side: Side, frame: str) -> dict[str, float]:
        zx: Excavator = side.machine
        name = side.name
        q = dict(zip(zx.front.names, zx.front.q, strict=True))
        dq = dict(zip(zx.front.names, zx.front.v, strict=True))
        if frame == F["front_angle"]:
            out = {j.angle: q[j.joint] for j in EXCAVATOR_FRONT}
            out["swing_relative_angle"] = wrap_angle(q["swing_joint"])
            return out
        if frame == F["front_angular_velocity"]:
            return {j.angular_velocity: dq[j.joint] for j in EXCAVATOR_FRONT}
        if frame == "Machine_State":
            return io.machine_state(side)
        if frame == "Roll_Pitch_Angle":
            return io.roll_pitch(name)
        if frame == "Vehicle_Azimuth":
            yaw = zx.base.yaw
            return {"upper_body_azimuth": -wrap_angle(yaw + q["swing_joint"]), "track_body_azimuth": -wrap_angle(yaw)}
        if frame.startswith("Swing_Center_Position"):
            c = io.body_pos(f"{name}_body_link")
            s = io.sensors
            e, n, alt = io.gnss.map_to_plane(float(c[0]), float(c[1]), float(c[2]))
            axis = frame[-1]
            value = {"1": e + io.noise.gauss(s.gnss_sigma_h), "2": n + io.noise.gauss(s.gnss_sigma_h),
                     "3": alt + io.noise.gauss(s.gnss_sigma_v)}[axis]
            return {f"swing_center_position_{'xyz'[int(axis) - 1]}": value}
        if frame.startswith("Front_Pin_Position"):
            joint = {"1": "boom", "2": "arm", "3": "bucket"}[frame[-1]]
            p = _in_base(zx, io.body_pos(f"{name}_{joint}_link"))
            return {f"{joint}_pin_position_{a}": p[i] for i, a in enumerate("xyz")}
        if frame == "Hydraulic_Flow_Rate_1":
            flows = dict(zip(zx.front.names, zx.front.flows(), strict=True))
            out = {}
            for j in EXCAVATOR_FRONT:
                if j.joint == "swing_joint":
                    continue
                f = math.copysign(flows[j.joint], dq[j.joint])
                out[f"{j.short}_cylinder_bottom_flow_rate"] = f
                out[f"{j.short}_cylinder_rod_flow_rate"] = -f
            sw = 200.0 * dq["swing_joint"] / zx.description.joint("swing_joint").velocity
            out.update(swing_motor_a_flow_rate=sw, swing_motor_b_flow_rate=-sw)
            return out
        if frame == "Hydraulic_Flow_Rate_2":
            t = zx.description.tracks
            fl, fr = 200.0 * zx.base.vl / t.max_speed, 200.0 * zx.base.vr / t.max_speed
            return {"right_track_motor_a_flow_rate": fr, "right_track_motor_b_flow_rate": -fr,
                    "left_track_motor_a_flow_rate": fl, "left_track_motor_b_flow_rate": -fl}
        if frame in ("Pressure_1", "Pressure_2"):
            # No load model: a standby pressure plus a share proportional to the flow demand.
            base = 3.0 + 25.0 * (1.0 - zx.front.flow_scale)
            return dict.fromkeys(side.ranges[frame], base)
        if frame == F["front_pilot_measured"]:
            return _pilot_echo(zx)
        if frame == "Pilot_Pressure_2":
            return dict.fromkeys(side.ranges[frame], 0.0)
        raise KeyError(f"{name}: no builder for state frame {frame}")


def _pilot_echo(zx: Excavator) -> dict[str, float]:
    """Measured pilot pressures equivalent to the current joint commands (velocity mode)."""
    cmd = dict(zip(zx.front.names, zx.front.command, strict=True))
    vmax = {j.name: j.velocity for j in zx.description.joints}
    out: dict[str, float] = {}
    for j in EXCAVATOR_FRONT:
        p = PILOT_MAX_MPA * min(1.0, abs(cmd[j.joint]) / vmax[j.joint]) if vmax[j.joint] > 0 else 0.0
        plus, minus = (p, 0.0) if cmd[j.joint] > 0 else (0.0, p)
        out[j.pilot_measured_plus], out[j.pilot_measured_minus] = plus, minus
    return out


def _in_base(zx: Excavator, p: Any) -> tuple[float, float, float]:
    b = zx.base
    dx, dy, dz = p[0] - b.x, p[1] - b.y, p[2] - zx.z
    c, s = math.cos(b.yaw), math.sin(b.yaw)
    return c * dx + s * dy, -s * dx + c * dy, dz
