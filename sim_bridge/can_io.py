"""COM3 CAN I/O of the plant: command frames in, state frames out, command-loss watchdog.

The plant is driven *only* through these frames, as the real machines are. Per machine:

* Command frames are decoded with :mod:`com3_can.codec`. A frame that fails to decode (value outside
  its DBC range, wrong DLC, unknown id) is ignored and counted by reason; frames of the machine's
  own state direction (echoes) are ignored silently.
* ZX200 (published COM3): ``Machine_Setting_Cmd`` selects the front source (1 pilot pressure,
  2 velocity) and the travel source (1 pilot, 2 per-track velocity, 3 centre velocity + yaw rate).
  Until a setting frame has arrived, velocity frames are honoured (centre+yaw when non-zero, else
  per-track). Pilot pressure maps linearly to velocity: ``v = v_max * (p_a - p_b) / 5 MPa``.
* IC120 (our extension): ``Velocity_Cmd`` by ``velocity_mode`` (0 centre + yaw rate, 1 per track),
  ``Vessel_Cmd`` (enable 1: target angle; 0: hold).
* Watchdog: no motion command frame for ``watchdog_s`` of simulated time -> the machine is brought to
  rest (commands zeroed; the hydraulics drain through their dead time and lag) and the trip counted.
* Pilot cut-off (``Pilot_Cutoff_Cmd`` of :mod:`com3_can.pilot_cutoff`, a TMS extension beside COM3):
  1 engages the hydraulic lock after the machine's ``pilot_cutoff.solenoid_delay_s`` (simulated), 0
  releases it at once; ``Machine_State`` reports ``lock_cmd_state`` (requested) and
  ``pilot_shutoff_valve_state`` (0 locked / 1 unlocked). Ignored when the machine YAML has no
  ``pilot_cutoff`` section.
* State frames are emitted at their DBC cycle times (simulated time) with values clipped into their
  signal ranges; sensors (GNSS, IMU) carry seeded noise.

Conventions on the bus: joint angles/velocities as the URDF (swing + = CCW, boom + = down, arm + =
crowd, bucket + = curl); azimuth clockwise-positive from map +x (ROS yaw = -azimuth, as the carrier
DBC documents and the com3 relay reads it); ``Swing_Center_Position_x/y/z`` = plane rectangular
coordinates of the swing centre in the site CRS with ROS axes (x = easting, y = northing, z =
altitude), RTK noise; ``Front_Pin_Position_*`` = pin positions in the ZX200 ``base_link`` frame.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable, Mapping

import can

from com3_can.codec import Com3Codec, load_codec
from com3_can.errors import Com3DecodeError
from com3_can.pilot_cutoff import FRAME as CUTOFF_FRAME
from com3_can.pilot_cutoff import cutoff_codec
from com3_can.scheduler import FrameScheduler
from sim_bridge.plant import Plant
from sim_bridge.sensors import Gnss, Noise

__all__ = ["PlantCanIO", "MOTION_FRAMES"]

log = logging.getLogger(__name__)

#: Frames whose arrival feeds the command watchdog, per machine.
MOTION_FRAMES: Mapping[str, frozenset[str]] = {
    "zx200": frozenset({"Velocity_Cmd_1", "Velocity_Cmd_2", "Pilot_Pressure_Cmd_1", "Pilot_Pressure_Cmd_2"}),
    "ic120": frozenset({"Velocity_Cmd", "Vessel_Cmd"}),
}
PILOT_MAX = 5.0  # [MPa] full lever


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


class _Side:
    """Per-machine bus state: codec, schedule, modes, watchdog and counters."""

    def __init__(self, machine: str, bus: can.BusABC, codec: Com3Codec, start: float) -> None:
        self.machine = machine
        self.bus = bus
        self.codec = codec
        self.schedule = FrameScheduler({n: codec.cycle_ms(n) / 1000.0 for n in codec.state_frames}, start)
        self.ranges = {
            n: {s.name: (s.minimum, s.maximum) for s in codec.signals(n)} for n in codec.frame_names
        }
        self.state_ids = {codec.frame_id(n) for n in codec.state_frames}
        self.last_motion = start
        self.resting = True  # no command yet: at rest
        self.settings: dict[str, float] | None = None
        self.alive = 0
        self.counters: Counter[str] = Counter()
        self.pilot: dict[str, float] = {}
        self.cutoff_requested = False
        self.cutoff_at: float | None = None  # simulated time the requested cut-off takes effect
        self.cutoff_engaged = False

    def encode(self, frame: str, values: dict[str, float]) -> can.Message:
        rng = self.ranges[frame]
        clipped = {k: min(rng[k][1], max(rng[k][0], v)) for k, v in values.items()}
        data = self.codec.encode(frame, clipped)
        return can.Message(arbitration_id=self.codec.frame_id(frame), data=data, is_extended_id=True)


class PlantCanIO:
    """Connects a :class:`Plant` to one COM3 bus per machine.

    Args:
        plant: the plant to drive.
        buses: ``{"zx200": bus, "ic120": bus}`` (any python-can bus; one machine may be omitted).
        watchdog_s: command-loss timeout in simulated seconds.
        codecs: override the codecs (default :func:`com3_can.codec.load_codec`).
    """

    def __init__(
        self,
        plant: Plant,
        buses: Mapping[str, can.BusABC],
        *,
        watchdog_s: float = 0.5,
        codecs: Mapping[str, Com3Codec] | None = None,
    ) -> None:
        self.plant = plant
        self.watchdog_s = watchdog_s
        self.sides = {
            m: _Side(m, bus, (codecs or {}).get(m) or load_codec(m), plant.time) for m, bus in buses.items()
        }
        self.gnss = Gnss(plant.spec.site)
        self.noise = Noise(plant.spec.sensors)
        self._handlers: dict[str, Callable[[_Side, str, dict[str, float]], None]] = {
            "zx200": self._zx200_command,
            "ic120": self._ic120_command,
        }
        self._builders = {"zx200": self._zx200_state, "ic120": self._ic120_state}
        self.replay = False  # True: commands are counted but not applied (the plant follows a log)
        self._cutoff = cutoff_codec()

    def _machine(self, side: _Side):  # noqa: ANN202 - Zx200 | Ic120
        return self.plant.zx200 if side.machine == "zx200" else self.plant.ic120

    def _on_cutoff(self, side: _Side, msg: can.Message, now: float) -> None:
        try:
            _, values = self._cutoff.decode(msg.arbitration_id, bytes(msg.data))
        except Com3DecodeError as exc:
            side.counters[f"ignored_{exc.reason}"] += 1
            return
        side.counters["received"] += 1
        if self.replay:
            return
        want = values["pilot_cutoff_cmd"] >= 0.5
        spec = self._machine(side).spec.pilot_cutoff
        if spec is None:
            side.counters["ignored_no_pilot_cutoff"] += 1
            return
        if want and not side.cutoff_requested:
            side.cutoff_at = now + spec.solenoid_delay
            side.counters["pilot_cutoff_requests"] += 1
        elif not want and side.cutoff_requested:
            side.cutoff_at = None
            if side.cutoff_engaged:
                side.cutoff_engaged = False
                self._machine(side).set_pilot_cutoff(False)
                log.warning("%s: pilot cut-off released", side.machine)
        side.cutoff_requested = want

    def apply_cutoffs(self) -> None:
        """Engage every requested pilot cut-off whose solenoid delay has passed (call every step)."""
        now = self.plant.time
        for side in self.sides.values():
            if side.cutoff_at is not None and now + 1e-9 >= side.cutoff_at:
                side.cutoff_at = None
                side.cutoff_engaged = True
                self._machine(side).set_pilot_cutoff(True)
                log.warning("%s: pilot cut-off engaged (hydraulic lock)", side.machine)

    # -- receive ---------------------------------------------------------------------------------
    def poll(self) -> int:
        """Drain every bus and apply the command frames; returns the number of frames handled."""
        n = 0
        now = self.plant.time
        for side in self.sides.values():
            while True:
                try:
                    msg = side.bus.recv(timeout=0.0)
                except can.CanOperationError as exc:
                    # A datagram that is not a CAN frame (udp_multicast: anything sent to the port, e.g. a
                    # stray DDS packet) is dropped and counted; it must not stop the plant.
                    side.counters["ignored_undecodable"] += 1
                    if side.counters["ignored_undecodable"] in (1, 10, 100, 1000):
                        log.warning("%s: undecodable bus message ignored (%d so far): %s", side.machine,
                                    side.counters["ignored_undecodable"], exc)
                    continue
                if msg is None:
                    break
                n += 1
                self.handle(side.machine, msg, now)
        return n

    def handle(self, machine: str, msg: can.Message, now: float) -> None:
        """Decode and apply one received frame (ignored and counted when invalid)."""
        side = self.sides[machine]
        if msg.arbitration_id in side.state_ids:
            side.counters["echo"] += 1
            return
        if msg.arbitration_id == self._cutoff.frame_id(CUTOFF_FRAME):
            self._on_cutoff(side, msg, now)
            return
        try:
            name, values = side.codec.decode(msg.arbitration_id, bytes(msg.data))
        except Com3DecodeError as exc:
            side.counters[f"ignored_{exc.reason}"] += 1
            log.debug("%s: ignored frame: %s", machine, exc)
            return
        side.counters["received"] += 1
        if self.replay:
            return
        if name in MOTION_FRAMES[machine]:
            side.last_motion = now
            side.resting = False
        self._handlers[machine](side, name, values)

    def _zx200_command(self, side: _Side, name: str, v: dict[str, float]) -> None:
        zx = self.plant.zx200
        s = side.settings
        front_mode = None if s is None else int(s["front_signal_switch_command"])
        travel_mode = None if s is None else int(s["travel_signal_switch_command"])
        if name == "Machine_Setting_Cmd":
            side.settings = v
        elif name == "Velocity_Cmd_1":
            if front_mode in (None, 2):
                zx.set_front_velocity(
                    {
                        "swing_joint": v["swing_target_anguler_velocity"],
                        "boom_joint": v["boom_target_anguler_velocity"],
                        "arm_joint": v["arm_target_anguler_velocity"],
                        "bucket_joint": v["bucket_target_anguler_velocity"],
                    }
                )
        elif name == "Pilot_Pressure_Cmd_1":
            side.pilot.update(v)
            if front_mode == 1:
                vmax = {j.name: j.max_velocity for j in zx.spec.joints}
                zx.set_front_velocity(
                    {
                        "swing_joint": vmax["swing_joint"] * (v["swing_left"] - v["swing_right"]) / PILOT_MAX,
                        "boom_joint": vmax["boom_joint"] * (v["boom_down"] - v["boom_up"]) / PILOT_MAX,
                        "arm_joint": vmax["arm_joint"] * (v["arm_crowd"] - v["arm_dump"]) / PILOT_MAX,
                        "bucket_joint": vmax["bucket_joint"] * (v["bucket_crowd"] - v["bucket_dump"]) / PILOT_MAX,
                    }
                )
        elif name == "Velocity_Cmd_2":
            centre, yaw = v["target_travel_center_velocity"], v["target_travel_yaw_rate"]
            left, right = v["target_travel_left_velocity"], v["target_travel_right_velocity"]
            if travel_mode == 3 or (travel_mode is None and (centre != 0.0 or yaw != 0.0)):
                zx.set_centre_velocity(centre, yaw)
            elif travel_mode in (2, None):
                zx.set_track_speeds(left, right)
        elif name == "Pilot_Pressure_Cmd_2":
            side.pilot.update(v)
            if travel_mode == 1:
                vmax = zx.spec.tracks.max_speed
                zx.set_track_speeds(
                    vmax * (v["left_track_forward"] - v["left_track_backward"]) / PILOT_MAX,
                    vmax * (v["right_track_forward"] - v["right_track_backward"]) / PILOT_MAX,
                )

    def _ic120_command(self, side: _Side, name: str, v: dict[str, float]) -> None:
        ic = self.plant.ic120
        s = side.settings
        if name == "Machine_Setting_Cmd":
            side.settings = v
        elif name == "Velocity_Cmd":
            mode = 0 if s is None else int(s["velocity_mode"])
            if mode == 0:
                ic.set_centre_velocity(v["target_travel_center_velocity"], v["target_travel_yaw_rate"])
            elif mode == 1:
                ic.set_track_speeds(v["target_travel_left_velocity"], v["target_travel_right_velocity"])
            else:  # pilot input: not modelled on the carrier
                side.counters["ignored_unsupported_mode"] += 1
                ic.set_track_speeds(0.0, 0.0)
        elif name == "Vessel_Cmd":
            lever = s is not None and int(s["dump_mode"]) == 1
            if v["vessel_control_enable"] >= 0.5 and not lever:
                ic.set_vessel_target(v["target_vessel_angle"])
            else:
                ic.set_vessel_velocity(0.0)

    # -- watchdog --------------------------------------------------------------------------------
    def watchdog(self) -> None:
        """Bring to rest every machine whose motion commands stopped ``watchdog_s`` ago."""
        self.apply_cutoffs()
        now = self.plant.time
        for side in self.sides.values():
            if not side.resting and now - side.last_motion > self.watchdog_s:
                side.resting = True
                side.counters["watchdog_trips"] += 1
                (self.plant.zx200 if side.machine == "zx200" else self.plant.ic120).rest()
                log.warning("%s: no command for %.2f s: bringing the machine to rest", side.machine, self.watchdog_s)

    # -- transmit --------------------------------------------------------------------------------
    def emit(self) -> int:
        """Send the state frames due at the plant's current time; returns how many were sent."""
        now = self.plant.time + 1e-9
        sent = 0
        for side in self.sides.values():
            due = side.schedule.due(now)
            if not due:
                continue
            build = self._builders[side.machine]
            for frame in due:
                msg = side.encode(frame, build(side, frame))
                try:
                    side.bus.send(msg)
                except can.CanError as exc:
                    side.counters["send_errors"] += 1
                    log.debug("%s: send %s failed: %s", side.machine, frame, exc)
                    continue
                sent += 1
                side.counters["sent"] += 1
        return sent

    def _alive(self, side: _Side) -> int:
        value = side.alive
        side.alive = (value + 1) % 256
        return value

    def _machine_state(self, side: _Side) -> dict[str, float]:
        values = dict.fromkeys(side.ranges["Machine_State"], 0.0)
        values.update(pilot_shutoff_valve_state=0.0 if side.cutoff_engaged else 1.0, engine_state=1.0,
                      lock_cmd_state=1.0 if side.cutoff_requested else 0.0,
                      control_state=1.0 if side.resting else 0.0)
        values["alive_counter"] = float(self._alive(side))
        if "hydraulic_oil_temp" in values:
            values["hydraulic_oil_temp"] = 50.0
        if "engine_rpm" in values:
            values["engine_rpm"] = 2000.0
        return values

    def _roll_pitch(self, machine: str) -> dict[str, float]:
        roll, pitch = self.plant.roll_pitch(machine)
        sigma = self.plant.spec.sensors.imu_sigma
        return {"roll_angle": roll + self.noise.gauss(sigma), "pitch_angle": pitch + self.noise.gauss(sigma)}

    def _zx200_state(self, side: _Side, frame: str) -> dict[str, float]:
        zx = self.plant.zx200
        q = dict(zip(zx.front.names, zx.front.q, strict=True))
        dq = dict(zip(zx.front.names, zx.front.v, strict=True))
        short = {"boom": "boom_joint", "arm": "arm_joint", "bucket": "bucket_joint", "swing": "swing_joint"}
        if frame == "Front_Angle":
            out = {f"{k}_relative_angle": q[j] for k, j in short.items()}
            out["swing_relative_angle"] = _wrap(q["swing_joint"])
            return out
        if frame == "Front_Angular_Velocity":
            return {f"{k}_relative_angular_velocity": dq[j] for k, j in short.items()}
        if frame == "Machine_State":
            return self._machine_state(side)
        if frame == "Roll_Pitch_Angle":
            return self._roll_pitch("zx200")
        if frame == "Vehicle_Azimuth":
            yaw = zx.base.yaw
            return {"upper_body_azimuth": -_wrap(yaw + q["swing_joint"]), "track_body_azimuth": -_wrap(yaw)}
        if frame.startswith("Swing_Center_Position"):
            c = self.plant.model.body_pos("zx200_body_link")
            s = self.plant.spec.sensors
            e, n, alt = self.gnss.map_to_plane(float(c[0]), float(c[1]), float(c[2]))
            axis = frame[-1]
            value = {"1": e + self.noise.gauss(s.gnss_sigma_h), "2": n + self.noise.gauss(s.gnss_sigma_h),
                     "3": alt + self.noise.gauss(s.gnss_sigma_v)}[axis]
            return {f"swing_center_position_{'xyz'[int(axis) - 1]}": value}
        if frame.startswith("Front_Pin_Position"):
            joint = {"1": "boom", "2": "arm", "3": "bucket"}[frame[-1]]
            p = self._in_base(self.plant.model.body_pos(f"zx200_{joint}_link"))
            return {f"{joint}_pin_position_{a}": p[i] for i, a in enumerate("xyz")}
        if frame == "Hydraulic_Flow_Rate_1":
            flows = dict(zip(zx.front.names, zx.front.flows(), strict=True))
            out = {}
            for k, j in (("boom", "boom_joint"), ("arm", "arm_joint"), ("bucket", "bucket_joint")):
                f = math.copysign(flows[j], dq[j])
                out[f"{k}_cylinder_bottom_flow_rate"] = f
                out[f"{k}_cylinder_rod_flow_rate"] = -f
            sw = 200.0 * dq["swing_joint"] / zx.spec.joint("swing_joint").max_velocity
            out.update(swing_motor_a_flow_rate=sw, swing_motor_b_flow_rate=-sw)
            return out
        if frame == "Hydraulic_Flow_Rate_2":
            t = zx.spec.tracks
            fl, fr = 200.0 * zx.base.vl / t.max_speed, 200.0 * zx.base.vr / t.max_speed
            return {"right_track_motor_a_flow_rate": fr, "right_track_motor_b_flow_rate": -fr,
                    "left_track_motor_a_flow_rate": fl, "left_track_motor_b_flow_rate": -fl}
        if frame in ("Pressure_1", "Pressure_2"):
            # No load model: a standby pressure plus a share proportional to the flow demand.
            base = 3.0 + 25.0 * (1.0 - zx.front.flow_scale)
            return dict.fromkeys(side.ranges[frame], base)
        if frame == "Pilot_Pressure_1":
            return self._pilot_echo(side, zx)
        if frame == "Pilot_Pressure_2":
            return dict.fromkeys(side.ranges[frame], 0.0)
        raise KeyError(f"zx200: no builder for state frame {frame}")

    def _pilot_echo(self, side: _Side, zx) -> dict[str, float]:  # noqa: ANN001
        """Measured pilot pressures equivalent to the current joint commands (velocity mode)."""
        cmd = dict(zip(zx.front.names, zx.front.command, strict=True))
        vmax = {j.name: j.max_velocity for j in zx.spec.joints}

        def split(joint: str) -> tuple[float, float]:
            p = PILOT_MAX * min(1.0, abs(cmd[joint]) / vmax[joint]) if vmax[joint] > 0 else 0.0
            return (p, 0.0) if cmd[joint] > 0 else (0.0, p)

        bd, bu = split("boom_joint")
        ac, ad = split("arm_joint")
        kc, kd = split("bucket_joint")
        sl, sr = split("swing_joint")
        return {"boom_up_pilot_pressure": bu, "boom_down_pilot_pressure": bd, "arm_crowd_pilot_pressure": ac,
                "arm_dump_pilot_pressure": ad, "bucket_crowd_pilot_pressure": kc, "bucket_dump_pilot_pressure": kd,
                "swing_right_pilot_pressure": sr, "swing_left_pilot_pressure": sl}

    def _in_base(self, p) -> tuple[float, float, float]:  # noqa: ANN001
        b = self.plant.zx200.base
        dx, dy, dz = p[0] - b.x, p[1] - b.y, p[2] - self.plant.zx200.z
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        return c * dx + s * dy, -s * dx + c * dy, dz

    def _ic120_state(self, side: _Side, frame: str) -> dict[str, float]:
        ic = self.plant.ic120
        if frame == "Machine_State":
            return self._machine_state(side)
        if frame == "Track_Velocity":
            return {"left_track_velocity": ic.base.vl, "right_track_velocity": ic.base.vr}
        if frame == "Vessel_Angle":
            return {"vessel_angle": ic.vessel.q[0], "vessel_angular_velocity": ic.vessel.v[0]}
        if frame == "Vehicle_Azimuth":
            return {"track_body_azimuth": -_wrap(ic.base.yaw), "yaw_rate": -ic.base.w}
        if frame == "Roll_Pitch_Angle":
            return self._roll_pitch("ic120")
        if frame.startswith("GNSS_"):
            if frame == "GNSS_Latitude":  # one fix per 100 ms cycle, shared by the three frames
                self._fix = self.gnss.fix(ic.base.x, ic.base.y, ic.z, self.noise)
            fix = getattr(self, "_fix", None) or self.gnss.fix(ic.base.x, ic.base.y, ic.z, self.noise)
            if frame == "GNSS_Latitude":
                return {"latitude": fix[0]}
            if frame == "GNSS_Longitude":
                return {"longitude": fix[1]}
            return {"altitude": fix[2], "fix_status": 3.0, "num_satellites": 20.0,
                    "horizontal_accuracy": self.plant.spec.sensors.gnss_sigma_h}
        raise KeyError(f"ic120: no builder for state frame {frame}")

    def counters(self) -> dict[str, dict[str, int]]:
        """Frame counters per machine (received, sent, ignored_<reason>, watchdog_trips, echo)."""
        return {m: dict(side.counters) for m, side in self.sides.items()}
