"""The COM3 signal <-> joint map: which DBC signal carries which joint, in one place.

Data only, read by both ends of the bus: the converter (:mod:`com3_can.profiles`) writes commands and
reads states through it, the plant (:mod:`sim_bridge.profiles`) reads commands and writes states through
it. Names are those of the DBC files in ``com3_can/dbc`` (including the published spelling
``anguler``). Sign convention of every joint signal (COM3, URDF): swing + = left (CCW from above),
boom + = down, arm + = crowd, bucket + = crowd.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from tms_model.com3 import CARRIER_DUMP_JOINT, CARRIER_ROTATE_JOINT
from tms_model.machines import LIFT_JOINT

__all__ = [
    "JointSignals",
    "TrackSignals",
    "EXCAVATOR_FRONT",
    "EXCAVATOR_FRAMES",
    "TRACK_SIGNALS",
    "CARRIER_FRAMES",
    "CARRIER_VESSEL",
    "CARRIER_SWING",
    "DOZER_FRAMES",
    "DOZER_BLADE",
    "TRACKS",
    "PILOT_MAX_MPA",
]

#: Pilot pressure of a full lever [MPa] (COM3 pilot frames).
PILOT_MAX_MPA = 5.0


@dataclass(frozen=True)
class JointSignals:
    """The signals of one excavator front joint.

    ``pilot_plus``/``pilot_minus`` are the ``Pilot_Pressure_Cmd_1`` signals of a + / - lever, and
    ``pilot_measured_plus``/``_minus`` their echoes in ``Pilot_Pressure_1``.
    """

    joint: str
    short: str  # prefix shared by the cylinder/motor signals (boom, arm, bucket, swing)
    velocity_cmd: str
    angle: str
    angular_velocity: str
    pilot_plus: str
    pilot_minus: str
    pilot_measured_plus: str
    pilot_measured_minus: str


def _joint(joint: str, short: str, plus: str, minus: str) -> JointSignals:
    return JointSignals(
        joint=joint,
        short=short,
        velocity_cmd=f"{short}_target_anguler_velocity",
        angle=f"{short}_relative_angle",
        angular_velocity=f"{short}_relative_angular_velocity",
        pilot_plus=f"{short}_{plus}",
        pilot_minus=f"{short}_{minus}",
        pilot_measured_plus=f"{short}_{plus}_pilot_pressure",
        pilot_measured_minus=f"{short}_{minus}_pilot_pressure",
    )


#: Excavator front joints in bus order (the order of ``joint_states``).
EXCAVATOR_FRONT: tuple[JointSignals, ...] = (
    _joint("swing_joint", "swing", "left", "right"),
    _joint("boom_joint", "boom", "down", "up"),
    _joint("arm_joint", "arm", "crowd", "dump"),
    _joint("bucket_joint", "bucket", "crowd", "dump"),
)

#: Track joint names of every tracked machine (``tracks_cmd`` / ``track_cmd``, ``joint_states``).
TRACKS: tuple[str, str] = ("left_track", "right_track")


@dataclass(frozen=True)
class TrackSignals:
    """Travel signals of every tracked machine (all DBCs name them alike): per-track and centre velocity commands
    and the per-track pilot pair (the excavator's ``Pilot_Pressure_Cmd_2``)."""

    left_velocity_cmd: str = "target_travel_left_velocity"
    right_velocity_cmd: str = "target_travel_right_velocity"
    centre_velocity_cmd: str = "target_travel_center_velocity"
    yaw_rate_cmd: str = "target_travel_yaw_rate"
    left_forward: str = "left_track_forward"
    left_backward: str = "left_track_backward"
    right_forward: str = "right_track_forward"
    right_backward: str = "right_track_backward"


#: the travel signals of every machine on tracks (excavator, crawler carrier, dozer)
TRACK_SIGNALS = TrackSignals()

#: Frame roles of the excavator DBC (``dbc/excavator_com3.dbc``).
EXCAVATOR_FRAMES: Mapping[str, str] = MappingProxyType({
    "front_velocity": "Velocity_Cmd_1",
    "front_pilot": "Pilot_Pressure_Cmd_1",
    "travel_velocity": "Velocity_Cmd_2",
    "travel_pilot": "Pilot_Pressure_Cmd_2",
    "setting": "Machine_Setting_Cmd",
    "front_angle": "Front_Angle",
    "front_angular_velocity": "Front_Angular_Velocity",
    "front_pilot_measured": "Pilot_Pressure_1",
})

#: Frame roles of the crawler-carrier DBC (``dbc/crawler_carrier_com3.dbc``).
CARRIER_FRAMES: Mapping[str, str] = MappingProxyType({
    "travel_velocity": "Velocity_Cmd",
    "vessel": "Vessel_Cmd",
    "setting": "Machine_Setting_Cmd",
    "track_velocity": "Track_Velocity",
    "vessel_angle": "Vessel_Angle",
    "swing": "Swing_Cmd",
    "swing_angle": "Swing_Angle",
})

#: Frame roles of the dozer DBC (``dbc/dozer_com3.dbc``).
DOZER_FRAMES: Mapping[str, str] = MappingProxyType({
    "travel_velocity": "Velocity_Cmd",
    "blade": "Blade_Cmd",
    "setting": "Machine_Setting_Cmd",
    "track_velocity": "Track_Velocity",
    "blade_angle": "Blade_Angle",
})


@dataclass(frozen=True)
class VesselSignals:
    joint: str = "vessel_joint"
    # the joint names of rot_dump_cmd (tms_model.com3): the vessel, and the rotating body the IC120 lacks
    command_joint: str = CARRIER_DUMP_JOINT
    rotate_joint: str = CARRIER_ROTATE_JOINT
    target_angle_cmd: str = "target_vessel_angle"
    enable_cmd: str = "vessel_control_enable"
    angle: str = "vessel_angle"
    angular_velocity: str = "vessel_angular_velocity"
    left_track_velocity: str = "left_track_velocity"
    right_track_velocity: str = "right_track_velocity"


CARRIER_VESSEL = VesselSignals()


@dataclass(frozen=True)
class SwingSignals:
    """A carrier's rotating upper body (MSTs): ``rotate_joint`` of ``rot_dump_cmd`` and ``joint_states``."""

    joint: str = CARRIER_ROTATE_JOINT
    target_angle_cmd: str = "target_swing_angle"
    enable_cmd: str = "swing_control_enable"
    angle: str = "swing_angle"
    angular_velocity: str = "swing_angular_velocity"
    mode_setting: str = "swing_mode"  # Machine_Setting_Cmd: 0 angle control, 1 lever input


CARRIER_SWING = SwingSignals()


@dataclass(frozen=True)
class BladeSignals:
    """A dozer's blade lift (``lift_joint``, URDF sign: + = down) on ``blade_cmd`` and ``joint_states``."""

    joint: str = LIFT_JOINT
    target_angle_cmd: str = "target_blade_lift_angle"
    target_velocity_cmd: str = "target_blade_lift_velocity"
    mode_cmd: str = "blade_control_mode"  # 0 hold, 1 angle, 2 velocity
    angle: str = "blade_lift_angle"
    angular_velocity: str = "blade_lift_angular_velocity"


DOZER_BLADE = BladeSignals()
BLADE_HOLD, BLADE_ANGLE, BLADE_VELOCITY = 0, 1, 2
