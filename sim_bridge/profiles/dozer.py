"""Dozer plant profile (D37PXi): our COM3 dozer extension frames (``dbc/dozer_com3.dbc``) on a :class:`Dozer`.

Commands: ``Velocity_Cmd`` by ``velocity_mode`` (0 centre + yaw rate, 1 per track; pilot input is not modelled and
stops the tracks); ``Blade_Cmd`` by ``blade_control_mode`` (0 hold, 1 target lift angle, 2 lift velocity);
``track_lock`` / ``blade_lock`` of ``Machine_Setting_Cmd`` hold the tracks / the blade. States: track velocities,
blade lift angle, azimuth and yaw rate, roll/pitch, GNSS fix of the base (RTK noise), as the carrier's.

The blade's soil resistance slows the dozer through its tracks' slip (``Plant._doze``, :mod:`sim_bridge.tracks`):
the ``physics:`` section must give the traction coefficient, the soil's shear deformation modulus, the tracks'
contact length and the blade's rake; the weight is the description's ``masses``.
"""

from __future__ import annotations

from com3_can.profiles.dozer import DozerProfile
from com3_can.signal_map import BLADE_ANGLE, BLADE_VELOCITY
from com3_can.signal_map import DOZER_BLADE as B
from com3_can.signal_map import DOZER_FRAMES as F
from com3_can.signal_map import TRACK_SIGNALS as T
from sim_bridge.errors import SimConfigError
from sim_bridge.machines import Dozer
from sim_bridge.physics import G
from sim_bridge.profiles.base import PlantBus, PlantProfile, Side
from sim_bridge.profiles.common import tracked_state, vec
from sim_bridge.spec import PlantMachine
from tms_model.machines import LIFT_JOINT

__all__ = ["DozerPlantProfile"]

#: ``physics:`` keys a dozer needs besides its blade drive's (the blade's resistance and the tracks' slip under it)
TRACTION_NEEDS = ("traction_coefficient", "shear_modulus_m", "track_contact_length_m", "blade_rake_deg")


class DozerPlantProfile(PlantProfile):
    machine_type = DozerProfile.machine_type
    motion_frames = frozenset(f for frames in DozerProfile.channels.values() for f in frames)

    @staticmethod
    def make_machine(machine: PlantMachine, dt: float) -> Dozer:
        ph = machine.physics
        try:
            ph.need(machine.description.source, *TRACTION_NEEDS)
        except ValueError as exc:
            raise SimConfigError(str(exc)) from None
        assert ph.traction_coefficient is not None and ph.shear_modulus_m is not None  # needed above
        assert ph.track_contact_length_m is not None
        dz = Dozer(machine, dt)
        weight = sum(machine.description.masses.values()) * G  # [N] the whole machine rests on its tracks
        dz.base.set_traction(ph.traction_coefficient * weight, ph.shear_modulus_m, ph.track_contact_length_m)
        return dz

    @staticmethod
    def mjcf(machine: PlantMachine) -> list[str]:
        name, d = machine.name, machine.description
        assert d.blade is not None  # tms_model: every dozer has one
        j, b = d.joint(LIFT_JOINT), d.blade
        t = d.footprint
        rng = f' range="{j.lower} {j.upper}" limited="true"'
        return [
            f'    <body name="{name}_base" mocap="true">',
            f'      <geom type="box" size="{t.length * 0.35} {t.width * 0.4} 0.6" pos="0 0 0.6" material="dz" '
            'contype="0" conaffinity="0"/>',
            f'      <body name="{name}_{j.child}" pos="{vec(j.origin_xyz)}" euler="{vec(j.origin_rpy)}">',
            f'        <joint name="{name}_{j.name}" type="hinge" axis="{vec(j.axis)}"{rng}/>',
            f'        <geom type="box" size="{b.edge_xyz[0] / 2} 0.1 0.1" pos="{b.edge_xyz[0] / 2} 0 0" material="dz" '
            f'contype="0" conaffinity="0" mass="{d.masses["blade"] * 0.3}"/>',
            f'        <geom type="box" size="0.1 {b.width / 2} 0.45" '
            f'pos="{vec((b.edge_xyz[0], b.edge_xyz[1], b.edge_xyz[2] + 0.45))}" '
            f'material="dz" contype="0" conaffinity="0" mass="{d.masses["blade"] * 0.7}"/>',
            f'        <site name="{name}_blade_edge" pos="{vec(b.edge_xyz)}" size="0.08"/>',
            "      </body>",
            "    </body>",
        ]

    @staticmethod
    def command(io: PlantBus, side: Side, frame: str, v: dict[str, float]) -> None:
        dz: Dozer = side.machine
        s = side.settings
        if frame == F["setting"]:
            side.settings = v
            if v["track_lock"] >= 0.5:
                dz.set_track_speeds(0.0, 0.0)
            if v["blade_lock"] >= 0.5:
                dz.set_lift_velocity(0.0)
        elif frame == F["travel_velocity"]:
            if s is not None and s["track_lock"] >= 0.5:
                side.counters["ignored_track_lock"] += 1
                dz.set_track_speeds(0.0, 0.0)
                return
            mode = 0 if s is None else int(s["velocity_mode"])
            if mode == 0:
                dz.set_centre_velocity(v[T.centre_velocity_cmd], v[T.yaw_rate_cmd])
            elif mode == 1:
                dz.set_track_speeds(v[T.left_velocity_cmd], v[T.right_velocity_cmd])
            else:  # pilot input: not modelled
                side.counters["ignored_unsupported_mode"] += 1
                dz.set_track_speeds(0.0, 0.0)
        elif frame == F["blade"]:
            mode = int(v[B.mode_cmd])
            if s is not None and s["blade_lock"] >= 0.5:
                mode = 0
            if mode == BLADE_ANGLE:
                dz.set_lift_target(v[B.target_angle_cmd])
            elif mode == BLADE_VELOCITY:
                dz.set_lift_velocity(v[B.target_velocity_cmd])
            else:
                dz.set_lift_velocity(0.0)

    @staticmethod
    def state(io: PlantBus, side: Side, frame: str) -> dict[str, float]:
        dz: Dozer = side.machine
        if frame == F["blade_angle"]:
            return {B.angle: dz.lift_angle, B.angular_velocity: dz.lift_rate}
        # travel, azimuth, attitude, GNSS and Machine_State frames are every tracked machine's
        return tracked_state(io, side, frame)
