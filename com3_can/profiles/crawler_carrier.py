"""Crawler-carrier profile (IC120, MST-110CR, MST-2200VD): travel, vessel and, where the machine has one, the swing
of its upper body on our COM3 extension (``dbc/crawler_carrier_com3.dbc``).

Commands, on com3_ros's crawler-carrier topics: ``cmd_vel`` -> ``Velocity_Cmd`` centre + yaw rate
(``velocity_mode`` 0), ``track_cmd`` VELOCITY -> ``Velocity_Cmd`` per track (``velocity_mode`` 1),
``rot_dump_cmd`` POSITION of ``dump_joint`` -> ``Vessel_Cmd`` target angle in [0, ``vessel.max_angle``] and of
``rotate_joint`` -> ``Swing_Cmd`` target swing angle (within ``swing.position`` of the machine description, or
[-pi, pi] for an endless slew). A machine without a swing (the IC120) refuses a command naming ``rotate_joint``.
The vessel and the swing are two channels (two watchdogs): a ``rot_dump_cmd`` naming one joint leaves the other's
command as it was. States: ``Track_Velocity`` -> odometry integrated from the track speeds (heading from
``Vehicle_Azimuth`` when present; dead-reckoned from 0 before the first azimuth, then turning with the azimuth
from where it was, since odom must not jump, REP 105) and joint states (``rotate_joint`` if any,
``vessel_joint``, track positions), ``GNSS_Altitude_Status`` (with the latest latitude/longitude) -> fix,
``Roll_Pitch_Angle`` -> IMU (once an azimuth is known).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from com3_can.errors import Com3CommandError
from com3_can.outputs import FixOut, JointStateOut, OdomOut, Tx, finite
from com3_can.profiles.base import ConverterProfile, Core
from com3_can.signal_map import CARRIER_FRAMES as F
from com3_can.signal_map import CARRIER_SWING as S
from com3_can.signal_map import CARRIER_VESSEL as V
from com3_can.signal_map import TRACK_SIGNALS as T
from com3_can.signal_map import TRACKS
from tms_model.com3 import POSITION, VELOCITY
from tms_model.machines import CRAWLER_DUMP

__all__ = ["CrawlerCarrierProfile", "TrackedProfile"]


class TrackedProfile(ConverterProfile):
    """What every COM3 extension machine on tracks shares: ``cmd_vel`` and ``track_cmd`` on ``Velocity_Cmd``
    (``velocity_mode`` 0 / 1), odometry and joint states from ``Track_Velocity``, and the GNSS fix."""

    tracks_topic = "track_cmd"
    travel_frame = "Velocity_Cmd"
    track_velocity_frame = "Track_Velocity"

    def __init__(self, machine: str) -> None:
        super().__init__(machine)
        # odometry integrated from the track velocities
        self._x = self._y = self._yaw = 0.0
        self._stamp: float | None = None
        self._azimuth_offset: float | None = None  # odom yaw - azimuth, fixed at the first azimuth
        self._track_pos = [0.0, 0.0]

    def tracks_cmd(self, core: Core, names: Sequence[str], control_type: int, velocity: Sequence[float],
                   effort: Sequence[float], now: float) -> list[Tx]:
        vals = core.check_joint_cmd(self.tracks_topic, TRACKS, names, control_type, velocity, effort)
        if control_type != VELOCITY:
            raise Com3CommandError(f"{self.tracks_topic}: the {self.machine} takes VELOCITY track commands only")
        frame = core.codec.neutral(self.travel_frame)
        frame.update(
            {T.left_velocity_cmd: vals.get("left_track", 0.0), T.right_velocity_cmd: vals.get("right_track", 0.0)}
        )
        txs = core.accept(self.tracks_topic, "travel", {self.travel_frame: frame}, now)
        core.set_switch("velocity_mode", 1.0)
        return txs

    def cmd_vel(self, core: Core, linear_x: float, angular_z: float, now: float) -> list[Tx]:
        frame = core.codec.neutral(self.travel_frame)
        frame.update({T.centre_velocity_cmd: linear_x, T.yaw_rate_cmd: angular_z})
        txs = core.accept("cmd_vel", "travel", {self.travel_frame: frame}, now)
        core.set_switch("velocity_mode", 0.0)
        return txs

    def joints(self, core: Core) -> tuple[tuple[str, ...], tuple[float, ...], tuple[float, ...]]:
        """Names, positions and velocities of the machine's own joints (bus order) for ``joint_states``."""
        return (), (), ()

    # state frames
    def tracks(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        vl, vr = values[V.left_track_velocity], values[V.right_track_velocity]
        first = self._stamp is None  # every Track_Velocity gives an odometry pose: none went out before this one
        dt = 0.0 if first else min(max(stamp - self._stamp, 0.0), 0.1)
        self._stamp = stamp
        v = 0.5 * (vl + vr)
        w = (vr - vl) / core.config.track_gauge
        az = core.state.get("Vehicle_Azimuth")
        if az is not None:
            azimuth = -az["track_body_azimuth"]
            if self._azimuth_offset is None:
                # The first azimuth. Odometry already out (the state frames' order on the bus at start-up) was
                # dead-reckoned from 0: jumping to the azimuth would be a turn in place that never happened (a
                # localisation took it as one, its heading left its azimuth gate for good). Odom stays continuous.
                self._azimuth_offset = 0.0 if first else self._yaw + w * dt - azimuth
            self._yaw = math.remainder(azimuth + self._azimuth_offset, math.tau)
        else:
            self._yaw += w * dt
        self._x += v * math.cos(self._yaw) * dt
        self._y += v * math.sin(self._yaw) * dt
        self._track_pos[0] += vl * dt
        self._track_pos[1] += vr * dt
        names, pos, vel = self.joints(core)
        joints = JointStateOut(
            (*names, *TRACKS),
            (*pos, self._track_pos[0], self._track_pos[1]),
            (*vel, vl, vr),
        )
        return [OdomOut(self._x, self._y, 0.0, self._yaw, v, w), joints]

    def gnss(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        try:
            lat = core.state["GNSS_Latitude"]["latitude"]
            lon = core.state["GNSS_Longitude"]["longitude"]
        except KeyError:
            return []
        status = int(values["fix_status"]) - 1  # DBC 0 no fix .. 3 GBAS -> NavSatStatus -1 .. 2
        return [FixOut(lat, lon, values["altitude"], status, values["horizontal_accuracy"])]


class CrawlerCarrierProfile(TrackedProfile):
    machine_type = CRAWLER_DUMP
    channels = {"travel": (F["travel_velocity"],), "vessel": (F["vessel"],), "swing": (F["swing"],)}
    topics = frozenset({"track_cmd", "cmd_vel", "rot_dump_cmd"})
    setting_topic = "crawler_carrier_machine_setting"
    state_handlers = {
        F["track_velocity"]: "tracks",
        "Roll_Pitch_Angle": "roll_pitch",
        "GNSS_Altitude_Status": "gnss",
        "Machine_State": "machine_state",
    }

    def rot_dump_cmd(self, core: Core, names: Sequence[str], control_type: int, position: Sequence[float],
                     now: float) -> list[Tx]:
        topic = "rot_dump_cmd"
        swing = core.config.swing_range
        allowed = [V.command_joint] if swing is None else [V.rotate_joint, V.command_joint]
        if control_type != POSITION:
            raise Com3CommandError(f"{topic}: the {self.machine} takes POSITION (0) dump commands only, "
                                   f"got control_type {control_type}")
        if not names or len(set(names)) != len(names) or any(n not in allowed for n in names):
            if swing is None and V.rotate_joint in names:
                raise Com3CommandError(
                    f"{topic}: the {self.machine} has no {V.rotate_joint} (its body does not rotate); "
                    f"send joint_name [{V.command_joint!r}] only"
                )
            want = f"{allowed}" if swing is None else f"some of {allowed}, each at most once"
            raise Com3CommandError(f"{topic}: joint_name {list(names)}; expected {want}")
        if len(position) != len(names):
            raise Com3CommandError(f"{topic}: {len(names)} joint name{'s' if len(names) > 1 else ''} but "
                                   f"{len(position)} position values")
        targets = {n: finite(topic, f"{n} position", p) for n, p in zip(names, position, strict=True)}
        updates: list[tuple[str, str, dict[str, float]]] = []
        if V.command_joint in targets:
            angle, top = targets[V.command_joint], core.config.vessel_max_angle
            if not 0.0 <= angle <= top:
                raise Com3CommandError(
                    f"{topic}: {V.command_joint} angle {angle:g} rad outside [0, {top:g}] rad "
                    f"(0 = lowered, + = raised; config/machines/{self.machine}.yaml vessel.max_angle)"
                )
            updates.append(("vessel", F["vessel"], {V.target_angle_cmd: angle, V.enable_cmd: 1.0}))
        if V.rotate_joint in targets:
            assert swing is not None
            angle = targets[V.rotate_joint]
            if not swing[0] <= angle <= swing[1]:
                raise Com3CommandError(
                    f"{topic}: {V.rotate_joint} angle {angle:g} rad outside [{swing[0]:g}, {swing[1]:g}] rad "
                    f"(config/machines/{self.machine}.yaml swing.position; null = endless, [-pi, pi])"
                )
            updates.append(("swing", F["swing"], {S.target_angle_cmd: angle, S.enable_cmd: 1.0}))
        txs: list[Tx] = []
        for channel, frame, values in updates:
            txs += core.accept(topic, channel, {frame: values}, now)
        return txs

    def joints(self, core: Core) -> tuple[tuple[str, ...], tuple[float, ...], tuple[float, ...]]:
        vessel = core.state.get(F["vessel_angle"], {})
        names: tuple[str, ...] = (V.joint,)
        pos: tuple[float, ...] = (vessel.get(V.angle, 0.0),)
        vel: tuple[float, ...] = (vessel.get(V.angular_velocity, 0.0),)
        if core.config.swing_range is not None:  # bus order: rotate_joint first
            sw = core.state.get(F["swing_angle"], {})
            names, pos, vel = (S.joint, *names), (sw.get(S.angle, 0.0), *pos), (sw.get(S.angular_velocity, 0.0), *vel)
        return names, pos, vel
