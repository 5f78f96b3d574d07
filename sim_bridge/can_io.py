"""COM3 CAN I/O of the plant: command frames in, state frames out, command-loss watchdog.

The plant is driven *only* through these frames, as the real machines are. Per machine:

* Command frames are decoded with :mod:`com3_can.codec`. A frame that fails to decode (value outside
  its DBC range, wrong DLC, unknown id) is ignored and counted by reason; frames of the machine's
  own state direction (echoes) are ignored silently.
* What a command frame does and what a state frame carries is the machine type's plant profile
  (:mod:`sim_bridge.profiles`: excavator, crawler_dump, dozer); this module is the same for every type.
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
altitude), RTK noise; ``Front_Pin_Position_*`` = pin positions in the excavator's ``base_link`` frame.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping

import can
import numpy as np

from com3_can.codec import Com3Codec, codec_for
from com3_can.errors import Com3DecodeError
from com3_can.pilot_cutoff import FRAME as CUTOFF_FRAME
from com3_can.pilot_cutoff import cutoff_codec
from sim_bridge.plant import Plant
from sim_bridge.profiles import PLANT_PROFILES
from sim_bridge.profiles.base import Side
from sim_bridge.sensors import Gnss, Noise
from sim_bridge.spec import SensorSpec

__all__ = ["PlantCanIO", "Side"]

log = logging.getLogger(__name__)


class PlantCanIO:
    """Connects a :class:`Plant` to one COM3 bus per machine.

    Args:
        plant: the plant to drive.
        buses: machine name -> bus (any python-can bus; a machine of the plant may be omitted).
        watchdog_s: command-loss timeout in simulated seconds.
        codecs: override the codecs (default: the DBC each machine's description names, ``Machine.dbc``).
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
        self.sides: dict[str, Side] = {}
        for m, bus in buses.items():
            machine = plant.spec.machines[m]
            codec = (codecs or {}).get(m) or codec_for(machine.description.dbc, m)
            self.sides[m] = Side(m, plant.machines[m], PLANT_PROFILES.get(machine.type), bus, codec, plant.time)
        self.gnss = Gnss(plant.spec.site)
        self.noise = Noise(plant.spec.sensors)
        self.replay = False  # True: commands are counted but not applied (the plant follows a log)
        self._cutoff = cutoff_codec()

    def _on_cutoff(self, side: Side, msg: can.Message, now: float) -> None:
        try:
            _, values = self._cutoff.decode(msg.arbitration_id, bytes(msg.data))
        except Com3DecodeError as exc:
            side.counters[f"ignored_{exc.reason}"] += 1
            return
        side.counters["received"] += 1
        if self.replay:
            return
        want = values["pilot_cutoff_cmd"] >= 0.5
        spec = side.machine.description.pilot_cutoff
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
                side.machine.set_pilot_cutoff(False)
                log.warning("%s: pilot cut-off released", side.name)
        side.cutoff_requested = want

    def apply_cutoffs(self) -> None:
        """Engage every requested pilot cut-off whose solenoid delay has passed (call every step)."""
        now = self.plant.time
        for side in self.sides.values():
            if side.cutoff_at is not None and now + 1e-9 >= side.cutoff_at:
                side.cutoff_at = None
                side.cutoff_engaged = True
                side.machine.set_pilot_cutoff(True)
                log.warning("%s: pilot cut-off engaged (hydraulic lock)", side.name)

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
                        log.warning("%s: undecodable bus message ignored (%d so far): %s", side.name,
                                    side.counters["ignored_undecodable"], exc)
                    continue
                if msg is None:
                    break
                n += 1
                self.handle(side.name, msg, now)
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
        if name in side.profile.motion_frames:
            side.last_motion = now
            side.resting = False
        side.profile.command(self, side, name, values)

    # -- watchdog --------------------------------------------------------------------------------
    def watchdog(self) -> None:
        """Bring to rest every machine whose motion commands stopped ``watchdog_s`` ago."""
        self.apply_cutoffs()
        now = self.plant.time
        for side in self.sides.values():
            if not side.resting and now - side.last_motion > self.watchdog_s:
                side.resting = True
                side.counters["watchdog_trips"] += 1
                side.machine.rest()
                log.warning("%s: no command for %.2f s: bringing the machine to rest", side.name, self.watchdog_s)

    # -- transmit --------------------------------------------------------------------------------
    def emit(self) -> int:
        """Send the state frames due at the plant's current time; returns how many were sent."""
        now = self.plant.time + 1e-9
        sent = 0
        for side in self.sides.values():
            due = side.schedule.due(now)
            if not due:
                continue
            for frame in due:
                msg = side.encode(frame, side.profile.state(self, side, frame))
                try:
                    side.bus.send(msg)
                except can.CanError as exc:
                    side.counters["send_errors"] += 1
                    log.debug("%s: send %s failed: %s", side.name, frame, exc)
                    continue
                sent += 1
                side.counters["sent"] += 1
        return sent

    @property
    def sensors(self) -> SensorSpec:
        """The plant's sensor noise figures."""
        return self.plant.spec.sensors

    def body_pos(self, body: str) -> np.ndarray:
        """Map position of MuJoCo body ``body`` (``<machine>_<link>``) now."""
        return self.plant.model.body_pos(body)

    def _alive(self, side: Side) -> int:
        value = side.alive
        side.alive = (value + 1) % 256
        return value

    def machine_state(self, side: Side) -> dict[str, float]:
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

    def roll_pitch(self, machine: str) -> dict[str, float]:
        roll, pitch = self.plant.roll_pitch(machine)
        sigma = self.plant.spec.sensors.imu_sigma
        return {"roll_angle": roll + self.noise.gauss(sigma), "pitch_angle": pitch + self.noise.gauss(sigma)}

    def counters(self) -> dict[str, dict[str, int]]:
        """Frame counters per machine (received, sent, ignored_<reason>, watchdog_trips, echo)."""
        return {m: dict(side.counters) for m, side in self.sides.items()}
