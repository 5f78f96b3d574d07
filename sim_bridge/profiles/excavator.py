"""Excavator plant profile (ZX200, ZX120, ...): the published COM3 excavator frames on an :class:`Excavator`.

Commands: ``Machine_Setting_Cmd`` selects the front source (1 pilot pressure, 2 velocity) and the travel
source (1 pilot, 2 per-track velocity, 3 centre velocity + yaw rate). Until a setting frame has arrived,
velocity frames are honoured (centre+yaw when non-zero, else per-track). Front pilot pressures go to the main
spools (:class:`sim_bridge.hydraulics.ValveFront`); travel pilot pressure maps linearly to track speed
(``v = v_max * (p_a - p_b) / 5 MPa``). States: joint angles/velocities, azimuths, the swing centre in the site CRS
(RTK noise), pin positions in ``base_link``, the pistons' flows, the chambers' pressures, the spools' pilot
pressures.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco

from com3_can.profiles.excavator import ExcavatorProfile
from com3_can.signal_map import EXCAVATOR_FRAMES as F
from com3_can.signal_map import EXCAVATOR_FRONT, PILOT_MAX_MPA, JointSignals
from com3_can.signal_map import TRACK_SIGNALS as T
from sim_bridge.machines import Excavator
from sim_bridge.physics import Drive
from sim_bridge.profiles.base import PlantBus, PlantProfile, Side, actuator_id
from sim_bridge.profiles.common import vec
from sim_bridge.spec import PlantMachine
from tms_model.cylinders import Cylinder, Linkage, cylinder_length, linkage_pin, moment_arm, ry
from tms_model.geometry import wrap_angle
from tms_model.machines import Joint

__all__ = ["ExcavatorPlantProfile"]

class ExcavatorPlantProfile(PlantProfile):
    machine_type = ExcavatorProfile.machine_type
    motion_frames = frozenset(f for frames in ExcavatorProfile.channels.values() for f in frames)

    @staticmethod
    def make_machine(machine: PlantMachine, dt: float) -> Excavator:
        return Excavator(machine, dt)

    @staticmethod
    def mjcf(machine: PlantMachine) -> list[str]:
        name, d = machine.name, machine.description
        assert d.bucket is not None and d.cylinders is not None  # tms_model: every excavator has them
        cyl = {c.joint: c for c in d.cylinders.all}
        lines = [
            f'    <body name="{name}_base" mocap="true">',
            f'      <geom type="box" size="{d.footprint.length / 2} {d.footprint.width / 2} 0.45" pos="0 0 0.45" '
            'material="zx" contype="0" conaffinity="0"/>',
        ]
        indent = "      "
        closes = []
        for j in d.joints:
            box = d.link_boxes[j.child]  # the kind's link box (config/machines/<kind>.yaml link_boxes)
            half, off = tuple(s / 2 for s in box.size), box.offset
            mass = d.masses[j.child.removesuffix("_link")]
            lines.append(
                f'{indent}<body name="{name}_{j.child}" pos="{vec(j.origin_xyz)}" euler="{vec(j.origin_rpy)}">'
            )
            rng = "" if j.lower is None else f' range="{j.lower} {j.upper}" limited="true"'
            lines.append(f'{indent}  <joint name="{name}_{j.name}" type="hinge" axis="{vec(j.axis)}"{rng}/>')
            lines.append(f'{indent}  <geom type="box" size="{vec(half)}" pos="{vec(off)}" material="zx" contype="0" '
                         f'conaffinity="0" mass="{mass}"/>')
            for c in d.cylinders.all:  # the cylinder's base pin sits on the joint's parent link
                if d.joint(c.joint).parent == j.child:
                    lines.append(f'{indent}  <site name="{name}_{_short(c.joint)}_cyl_base" '
                                 f'pos="{c.parent_pin[0]} 0 {c.parent_pin[1]}" size="0.06"/>')
            c = cyl.get(j.name)
            if c is not None and c.child_pin is not None:
                lines.append(f'{indent}  <site name="{name}_{_short(j.name)}_cyl_rod" '
                             f'pos="{c.child_pin[0]} 0 {c.child_pin[1]}" size="0.06"/>')
            if c is not None and c.linkage is not None:
                lines += _side_body(name, j, c.linkage, indent + "  ")
            bucket = d.cylinders.bucket
            if bucket.linkage is not None and d.joint(bucket.joint).parent == j.child:
                lines += _guide_body(name, d.joint(bucket.joint), bucket.linkage, indent + "  ")
            closes.append(f"{indent}</body>")
            indent += "  "
        lines.append(f'{indent}<site name="{name}_bucket_tip" pos="{vec(d.bucket.tip_xyz)}" size="0.08"/>')
        lines.extend(reversed(closes))
        lines.append("    </body>")
        return lines

    @staticmethod
    def mjcf_sections(machine: PlantMachine) -> dict[str, list[str]]:
        """The cylinders as spatial tendons between their pins with a unit-gain motor each, the swing motor, and the
        equality that closes the bucket's four-bar."""
        name, d = machine.name, machine.description
        assert d.cylinders is not None
        tendons, actuators = [], []
        for c in d.cylinders.all:
            s = f"{name}_{_short(c.joint)}_cyl"
            tendons += [f'    <spatial name="{s}" width="0.05">', f'      <site site="{s}_base"/>',
                        f'      <site site="{s}_rod"/>', "    </spatial>"]
            actuators.append(f'    <motor name="{s}" tendon="{s}" gear="1"/>')
        swing = d.joints[0]
        actuators.insert(0, f'    <motor name="{name}_swing_motor" joint="{name}_{swing.name}" gear="1"/>')
        link = d.cylinders.bucket.linkage
        equality = []
        if link is not None:
            equality.append(f'    <connect body1="{name}_guide_link" body2="{name}_side_link" '
                            f'anchor="{link.guide_length} 0 0" solref="0.004 1"/>')
        return {"tendon": tendons, "actuator": actuators, "equality": equality}

    @staticmethod
    def drives(machine: PlantMachine, model: mujoco.MjModel) -> list[Drive]:
        """Swing motor, then the boom, arm and bucket cylinders (front order): oil-column stiffness from the areas,
        the hose volume and the chambers at mid-stroke; relief forces; strokes from the joint ranges."""
        name, d, ph = machine.name, machine.description, machine.physics
        cyls = d.cylinders
        assert cyls is not None and cyls.swing is not None and ph.oil_bulk_modulus_mpa is not None
        assert ph.hose_volume_l is not None and ph.cylinder_viscous_ns_per_m is not None
        beta, hose = ph.oil_bulk_modulus_mpa * 1e6, ph.hose_volume_l / 1000.0
        sw = cyls.swing
        swing = d.joints[0]
        out = [Drive(
            actuator=actuator_id(model, f"{name}_swing_motor"), stiffness=2 * beta * sw.displacement_per_rad**2 / hose,
            viscous=0.0, f_min=-sw.relief_torque, f_max=sw.relief_torque, x_min=-math.inf, x_max=math.inf,
            damping_ratio=ph.damping_ratio, dof=_dof(model, f"{name}_{swing.name}"),
        )]
        for c in cyls.all:
            j = d.joint(c.joint)
            lo, hi = stroke(c, j)
            half = (hi - lo) / 2
            k = beta * (c.cap_area**2 / (hose + c.cap_area * half) + c.rod_area**2 / (hose + c.rod_area * half))
            q0 = machine.start_joints[j.name]
            out.append(Drive(
                actuator=actuator_id(model, f"{name}_{_short(c.joint)}_cyl"), stiffness=k,
                viscous=ph.cylinder_viscous_ns_per_m, f_min=-cyls.relief_pa * c.rod_area,
                f_max=cyls.relief_pa * c.cap_area, x_min=lo, x_max=hi, damping_ratio=ph.damping_ratio,
                dof=_dof(model, f"{name}_{j.name}"), ratio=abs(moment_arm(c, *_joint_plane(j), q0)),
            ))
        return out

    @staticmethod
    def linkage_joints(machine: PlantMachine, q: dict[str, float]) -> dict[str, float]:
        """The bucket four-bar's guide and side joints that close it at the bucket angle of ``q``."""
        d = machine.description
        assert d.cylinders is not None
        link = d.cylinders.bucket.linkage
        if link is None:
            return {}
        joint = d.joint(d.cylinders.bucket.joint)
        guide, side = linkage_angles(joint, link, q[joint.name])
        return {f"{machine.name}_guide_joint": guide, f"{machine.name}_side_joint": side}

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
                zx.set_front_pilot({j.joint: v[j.pilot_plus] - v[j.pilot_minus] for j in EXCAVATOR_FRONT})
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
            # what the pistons displace: bottom = cap area x piston speed (+ into the cap side), rod = -annulus x speed
            front = zx.front
            out = {}
            for i, j in enumerate(_bus_order(zx)):
                lpm = front.drive_speed[i] * 60000.0
                if j.joint == "swing_joint":
                    out["swing_motor_a_flow_rate"] = lpm * front.a_ext[i]
                    out["swing_motor_b_flow_rate"] = -lpm * front.a_ret[i]
                else:
                    out[f"{j.short}_cylinder_bottom_flow_rate"] = lpm * front.a_ext[i]
                    out[f"{j.short}_cylinder_rod_flow_rate"] = -lpm * front.a_ret[i]
            return out
        if frame == "Hydraulic_Flow_Rate_2":
            t = zx.description.tracks
            fl, fr = 200.0 * zx.base.vl / t.max_speed, 200.0 * zx.base.vr / t.max_speed
            return {"right_track_motor_a_flow_rate": fr, "right_track_motor_b_flow_rate": -fr,
                    "left_track_motor_a_flow_rate": fl, "left_track_motor_b_flow_rate": -fl}
        if frame == "Pressure_1":
            front = zx.front
            out = {}
            for i, j in enumerate(_bus_order(zx)):
                a, b = front.p_ext[i] / 1e6, front.p_ret[i] / 1e6
                if j.joint == "swing_joint":
                    out.update(swing_motor_a_pressure=a, swing_motor_b_pressure=b)
                else:
                    out[f"{j.short}_cylinder_bottom_pressure"] = a
                    out[f"{j.short}_cylinder_rod_pressure"] = b
            return out
        if frame == "Pressure_2":
            # travel and attachment circuits are not modelled: the pump's standby pressure (tank + LS margin)
            return dict.fromkeys(side.ranges[frame], zx.front.tank / 1e6 + zx.front.margin / 1e6)
        if frame == F["front_pilot_measured"]:
            return _pilot_echo(zx)
        if frame == "Pilot_Pressure_2":
            return dict.fromkeys(side.ranges[frame], 0.0)
        raise KeyError(f"{name}: no builder for state frame {frame}")


def _joint_plane(joint: Joint) -> tuple[tuple[float, float], float]:
    """The joint's origin (x, z) and pitch in its parent frame: what tms_model.cylinders takes."""
    return (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]


def stroke(c: Cylinder, joint: Joint) -> tuple[float, float]:
    """Shortest and longest pin-to-pin length of cylinder ``c`` over its joint's range [m]."""
    assert joint.lower is not None and joint.upper is not None
    a, b = (cylinder_length(c, *_joint_plane(joint), q) for q in (joint.lower, joint.upper))
    return min(a, b), max(a, b)


def _dof(model: mujoco.MjModel, joint: str) -> int:
    return int(model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)])


def _short(joint: str) -> str:
    """boom_joint -> boom (the cylinder's MJCF names)."""
    return joint.removesuffix("_joint")


#: mass of each link of the bucket's four-bar [kg] (a 20 t class guide or side link pair; assumption)
LINKAGE_MASS = 60.0
#: rotor inertia added to the four-bar's pins [kg m^2]: the light links against the bucket cylinder's oil column
#: (~8e6 N/m) would ring at ~60 Hz, too fast for the 2 ms step's explicit drive force
LINKAGE_ARMATURE = 10.0


def _linkage_frames(joint: Joint, link: Linkage) -> tuple[float, float]:
    """Angles (atan2 of z over x) of the guide link (in the arm frame, from K) and of the side link (in the bucket
    frame, from L) towards J with the bucket at 0 rad: the links' bodies are turned by these so that the loop is
    closed at qpos 0."""
    origin, pitch = (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]
    j0 = linkage_pin(link, origin, pitch, 0.0)
    if j0 is None:
        raise ValueError(f"{joint.name}: the bucket linkage cannot close at bucket angle 0")
    k, lb = link.guide_pin, link.link_pin
    jb = ry(-pitch, (j0[0] - origin[0], j0[1] - origin[1]))  # J in the bucket frame at angle 0
    return math.atan2(j0[1] - k[1], j0[0] - k[0]), math.atan2(jb[1] - lb[1], jb[0] - lb[0])


def _link_body(name: str, part: str, pin: tuple[float, float], angle: float, length: float, indent: str,
               rod_site: bool = False) -> list[str]:
    """One four-bar link: a body pinned at ``pin`` turned by ``angle`` towards J, its hinge, a capsule of ``length``
    and (the guide link) the cylinder's rod site at its end."""
    lines = [
        f'{indent}<body name="{name}_{part}_link" pos="{pin[0]} 0 {pin[1]}" euler="0 {-angle} 0">',
        f'{indent}  <joint name="{name}_{part}_joint" type="hinge" axis="0 1 0" armature="{LINKAGE_ARMATURE}"/>',
        f'{indent}  <geom type="capsule" fromto="0 0 0 {length} 0 0" size="0.06" material="zx" '
        f'contype="0" conaffinity="0" mass="{LINKAGE_MASS}"/>',
    ]
    if rod_site:
        lines.append(f'{indent}  <site name="{name}_bucket_cyl_rod" pos="{length} 0 0" size="0.06"/>')
    return [*lines, f"{indent}</body>"]


def _guide_body(name: str, joint: Joint, link: Linkage, indent: str) -> list[str]:
    """The four-bar's guide link, pinned on the arm at K, the cylinder rod at its end J."""
    angle, _ = _linkage_frames(joint, link)
    return _link_body(name, "guide", link.guide_pin, angle, link.guide_length, indent, rod_site=True)


def _side_body(name: str, joint: Joint, link: Linkage, indent: str) -> list[str]:
    """The four-bar's side link, pinned on the bucket at L; the connect equality joins its end to J."""
    _, angle = _linkage_frames(joint, link)
    return _link_body(name, "side", link.link_pin, angle, link.link_length, indent)


def linkage_angles(joint: Joint, link: Linkage, q: float) -> tuple[float, float]:
    """qpos of the guide and side joints that close the four-bar at bucket angle ``q``."""
    origin, pitch = (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]
    g0, s0 = _linkage_frames(joint, link)
    j = linkage_pin(link, origin, pitch, q)
    if j is None:
        raise ValueError(f"{joint.name}: the bucket linkage cannot close at {q:.3f} rad")
    k, lb = link.guide_pin, link.link_pin
    jb = ry(-(pitch + q), (j[0] - origin[0], j[1] - origin[1]))
    return -(math.atan2(j[1] - k[1], j[0] - k[0]) - g0), -(math.atan2(jb[1] - lb[1], jb[0] - lb[0]) - s0)


def _pilot_echo(zx: Excavator) -> dict[str, float]:
    """Measured pilot pressures: what each main spool's position needs (the spool is pilot-operated)."""
    front = zx.front
    out: dict[str, float] = {}
    for i, j in enumerate(_bus_order(zx)):
        x = front.spool[i]
        p = front.crack + abs(x) * (front.full - front.crack) if abs(x) > 1e-6 else 0.0
        plus, minus = (p, 0.0) if x > 0 else (0.0, p)
        out[j.pilot_measured_plus], out[j.pilot_measured_minus] = plus, minus
    return out


def _bus_order(zx: Excavator) -> list[JointSignals]:
    """The bus's front signal groups in the machine's joint order."""
    by_joint = {j.joint: j for j in EXCAVATOR_FRONT}
    return [by_joint[name] for name in zx.front.names]


def _in_base(zx: Excavator, p: Any) -> tuple[float, float, float]:
    b = zx.base
    dx, dy, dz = p[0] - b.x, p[1] - b.y, p[2] - zx.z
    c, s = math.cos(b.yaw), math.sin(b.yaw)
    return c * dx + s * dy, -s * dx + c * dy, dz
