"""The ROS-free core of the ``com3_bridge`` converter: commands -> COM3 frames, state frames -> outputs.

:class:`BridgeCore` holds everything the node does except ROS I/O, so unit tests and benchmarks drive
it with plain numbers and an injected clock. It is the same for every machine type: what a type does
(its channels, how a command becomes frames, how a state frame becomes outputs) is its profile
(:mod:`com3_can.profiles`), which the caller picks from the registry by the ``type`` of the machine description
and hands to the core; the core never looks a profile up itself.

* Commands (``front_cmd``, ``tracks_cmd`` / ``track_cmd``, ``cmd_vel``, ``rot_dump_cmd``, ``blade_cmd``,
  ``machine_setting``) are
  validated as a whole (unknown joint, NaN, array length, value outside the COM3 range ...). A bad
  command raises :class:`Com3CommandError` naming topic, joint/field and value, and changes nothing:
  values are never clipped or wrapped. A good one updates the frame and returns it for an immediate
  send (event-triggered, then cyclic at the DBC period).
* ``emg_stop`` is a latch: while set, every motion frame is neutral and motion commands are refused;
  only an explicit ``False`` clears it (and the cleared channels stay neutral until new commands).
* Watchdog per channel (front, travel, vessel, swing, blade): no accepted command for ``watchdog_s`` -> the channel
  goes neutral at once and the diagnostic says which topic went silent and for how long.
* Site watchdog (``site_timeout_s`` > 0, off by default): on a machine PC cut off from the site the
  controller may keep commanding, so command freshness says nothing; the node feeds the site's heartbeat to
  :meth:`BridgeCore.site_heartbeat` and calls :meth:`BridgeCore.site_check` periodically; once a heartbeat
  was seen, ``site_timeout_s`` without one while the machine is driven latches emg_stop (same latch, same clearing:
  an explicit ``False``).
* :meth:`BridgeCore.tick` returns the frames due now (scheduler), with the alive counter in
  ``Machine_Setting_Cmd`` advanced on every send.
* :meth:`BridgeCore.on_frame` decodes a received frame into outputs (:mod:`com3_can.outputs`: ``JointStateOut``,
  ``OdomOut``, ``ImuOut``, ``FixOut``); unknown ids, wrong DLC, out-of-range values,
  error/remote/standard frames are counted per reason and dropped, never raised.

Thread safety: every public method takes the core's lock; the node calls them from the executor thread
(commands), a sender thread (tick) and a receiver thread (on_frame).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from com3_can.bridge_config import BridgeConfig
from com3_can.codec import AliveCounter, Com3Codec, codec_for
from com3_can.errors import Com3CommandError, Com3DecodeError, Com3EncodeError
from com3_can.outputs import DiagSnapshot, FixOut, ImuOut, JointStateOut, OdomOut, Tx, finite
from com3_can.profiles.base import ConverterProfile
from com3_can.scheduler import FrameScheduler
from com3_can.signal_map import PILOT_MAX_MPA
from tms_common.errors import ConfigError
from tms_model.com3 import CONTROL_NAMES, EFFORT, POSITION, VELOCITY
from tms_model.site import Projector

# the output types, BridgeConfig and the control types are re-exported: users of the core import them from here
__all__ = [
    "BridgeConfig",
    "BridgeCore",
    "Tx",
    "JointStateOut",
    "OdomOut",
    "ImuOut",
    "FixOut",
    "DiagSnapshot",
    "POSITION",
    "VELOCITY",
    "EFFORT",
]

_log = logging.getLogger(__name__)

DIAG_OK, DIAG_WARN, DIAG_ERROR = 0, 1, 2


@dataclass
class _Channel:
    """A group of motion frames fed by some topics and guarded by one watchdog."""

    name: str
    frames: tuple[str, ...]
    last_cmd: float | None = None  # time of the last accepted command
    last_topic: str = ""
    timed_out: bool = False


class BridgeCore:
    """Converter state of one machine; see the module docstring.

    Args:
        config: :class:`BridgeConfig`.
        now: time [s] of construction on the same monotonic clock later passed to the methods.
        profile: what this machine's type does (channels, command and state handlers): the caller picks it from
            the registry, :func:`com3_can.profiles.converter_profile`.
        codec: the machine's codec (default: that of ``config.dbc``).
    """

    def __init__(self, config: BridgeConfig, now: float, profile: ConverterProfile,
                 codec: Com3Codec | None = None) -> None:
        if profile.machine_type != config.machine_type:
            raise ConfigError(f"com3_bridge: {config.machine} is a {config.machine_type}, but the profile given "
                              f"serves {profile.machine_type!r}")
        self.config = config
        self.machine = config.machine
        self.profile = profile
        self.codec = codec or codec_for(config.dbc, config.machine)
        self._lock = threading.RLock()
        self._alive = AliveCounter()
        self._values: dict[str, dict[str, float]] = {f: self.codec.neutral(f) for f in self.codec.command_frames}
        setting = self._values["Machine_Setting_Cmd"]
        for key, value in config.default_setting.items():
            if key not in setting or key == "alive_counter":
                raise ConfigError(
                    f"config/can/{self.machine}.yaml: bridge.default_setting.{key}: not a settable "
                    f"Machine_Setting_Cmd signal ({sorted(k for k in setting if k != 'alive_counter')})"
                )
            setting[key] = float(value)
        try:
            self.codec.encode("Machine_Setting_Cmd", setting)
        except Com3EncodeError as exc:
            raise ConfigError(f"config/can/{self.machine}.yaml: bridge.default_setting: {exc}") from None
        self._channels = {name: _Channel(name, frames) for name, frames in self.profile.channels.items()}
        self._motion_frames = tuple(f for ch in self._channels.values() for f in ch.frames)
        self._command_ids = frozenset(self.codec.frame_id(f) for f in self.codec.command_frames)
        self._scheduler = FrameScheduler({f: self.codec.cycle_ms(f) / 1000.0 for f in self.codec.command_frames}, now)
        self._emg = False
        self._emg_reason = ""
        self._site_seen: float | None = None  # last site heartbeat; None = not (re-)armed
        self._site_suspect = False  # site_check saw the heartbeat expired once
        self.counters: Counter[str] = Counter()
        self._last_reject = ""
        self._last_rx_error = ""
        #: latest decoded values of every state frame (profiles combine frames through it)
        self.state: dict[str, dict[str, float]] = {}
        self._machine_alive: int | None = None
        self._projector: Projector | None = None

    @property
    def topics(self) -> frozenset[str]:
        """The ROS commands this machine takes (its profile's)."""
        return self.profile.topics

    # ------------------------------------------------------------------ helpers
    def _encode(self, name: str) -> Tx:
        values = self._values[name]
        if name == "Machine_Setting_Cmd":
            values["alive_counter"] = float(self._alive.next())
        return Tx(name, self.codec.frame_id(name), self.codec.encode(name, values))

    def accept(self, topic: str, channel: str, updates: Mapping[str, Mapping[str, float]], now: float) -> list[Tx]:
        """Validate ``updates`` (frame -> full signal dict) by encoding, then commit and return the frames."""
        if self._emg:
            self.counters["cmd_ignored_emg_stop"] += 1
            raise Com3CommandError(f"{topic}: refused, emg_stop is latched (publish false on emg_stop to clear)")
        for frame, values in updates.items():
            try:
                self.codec.encode(frame, values)
            except Com3EncodeError as exc:
                raise Com3CommandError(f"{topic}: {exc}") from None
        ch = self._channels[channel]
        for frame, values in updates.items():
            self._values[frame] = dict(values)
        for other in ch.frames:  # a command kind replaces the other kind of the same channel
            if other not in updates:
                self._values[other] = self.codec.neutral(other)
        ch.last_cmd, ch.last_topic, ch.timed_out = now, topic, False
        self.counters["cmd_accepted"] += 1
        out = []
        for frame in ch.frames:
            out.append(self._encode(frame))
            self._scheduler.sent(frame, now)
        return out

    def _reject(self, exc: Com3CommandError) -> None:
        self.counters["cmd_rejected"] += 1
        self._last_reject = str(exc)

    def set_switch(self, signal: str, value: float) -> None:
        """Set a ``Machine_Setting_Cmd`` signal (the switch matching the last command's kind)."""
        self._values["Machine_Setting_Cmd"][signal] = value

    @staticmethod
    def check_joint_cmd(
        topic: str, allowed: Sequence[str], names: Sequence[str], control_type: int,
        velocity: Sequence[float], effort: Sequence[float],
    ) -> dict[str, float]:
        """Validate a JointCmd (control type, names, lengths, finite, effort in [-1, 1]): joint -> value."""
        arrays = {VELOCITY: velocity, EFFORT: effort}
        if control_type not in (VELOCITY, EFFORT):
            ctl_name = CONTROL_NAMES.get(control_type, str(control_type))
            raise Com3CommandError(
                f"{topic}: control_type {ctl_name} is not carried by COM3; use VELOCITY (1) or EFFORT (2)"
            )
        if not names:
            raise Com3CommandError(f"{topic}: joint_name is empty")
        unknown = [n for n in names if n not in allowed]
        if unknown:
            raise Com3CommandError(f"{topic}: unknown joint(s) {unknown}; expected some of {list(allowed)}")
        if len(set(names)) != len(names):
            raise Com3CommandError(f"{topic}: duplicate joint names {list(names)}")
        values = arrays[control_type]
        label = "velocity" if control_type == VELOCITY else "effort"
        if len(values) != len(names):
            raise Com3CommandError(f"{topic}: {len(names)} joint names but {len(values)} {label} values")
        out = {n: finite(topic, f"{n} {label}", v) for n, v in zip(names, values, strict=True)}
        if control_type == EFFORT:
            for n, v in out.items():
                if not -1.0 <= v <= 1.0:
                    raise Com3CommandError(f"{topic}: {n} effort {v:g} outside [-1, 1] (normalised lever)")
        return out

    @staticmethod
    def pilot(effort: float, dead_zone: float) -> float:
        """Pilot pressure [MPa] of a lever ``effort`` in [-1, 1] past its ``dead_zone`` (fraction of full lever)."""
        if abs(effort) < 0.001:
            return 0.0
        return min(abs(effort) + dead_zone, 1.0) * PILOT_MAX_MPA

    # ------------------------------------------------------------------ commands
    def _command(self, topic: str, fn: Any, *args: Any) -> list[Tx]:
        with self._lock:
            try:
                return fn(self, *args)
            except Com3CommandError as exc:
                self._reject(exc)
                raise

    def front_cmd(
        self, names: Sequence[str], control_type: int, velocity: Sequence[float], effort: Sequence[float], now: float
    ) -> list[Tx]:
        """``front_cmd`` (JointCmd): front joints, VELOCITY or EFFORT (the excavator profile)."""
        return self._command("front_cmd", self.profile.front_cmd, names, control_type, velocity, effort, now)

    def tracks_cmd(
        self, names: Sequence[str], control_type: int, velocity: Sequence[float], effort: Sequence[float], now: float
    ) -> list[Tx]:
        """Per-track JointCmd (left_track/right_track) on the type's ``tracks_topic``: velocity [m/s] (or effort, if the
        type takes it)."""
        return self._command(self.profile.tracks_topic, self.profile.tracks_cmd, names, control_type, velocity, effort,
                             now)

    def cmd_vel(self, linear_x: float, angular_z: float, now: float) -> list[Tx]:
        """``cmd_vel`` (Twist): body-centre velocity [m/s] and yaw rate [rad/s]."""
        with self._lock:
            try:
                v = finite("cmd_vel", "linear.x", linear_x)
                w = finite("cmd_vel", "angular.z", angular_z)
            except Com3CommandError as exc:
                self._reject(exc)
                raise
            return self._command("cmd_vel", self.profile.cmd_vel, v, w, now)

    def rot_dump_cmd(self, names: Sequence[str], control_type: int, position: Sequence[float], now: float) -> list[Tx]:
        """``rot_dump_cmd`` (JointCmd, com3_ros crawler carrier): POSITION of ``dump_joint`` = target vessel angle
        [rad], 0 = lowered, + = raised, and of ``rotate_joint`` = target swing angle where the carrier has a swing
        (the crawler-carrier profile)."""
        return self._command("rot_dump_cmd", self.profile.rot_dump_cmd, names, control_type, position, now)

    def blade_cmd(self, names: Sequence[str], control_type: int, position: Sequence[float], velocity: Sequence[float],
                  now: float) -> list[Tx]:
        """``blade_cmd`` (JointCmd, ours): POSITION or VELOCITY of a dozer's ``lift_joint`` (+ = down)."""
        return self._command("blade_cmd", self.profile.blade_cmd, names, control_type, position, velocity, now)

    def machine_setting(self, fields: Mapping[str, float], now: float) -> list[Tx]:
        """``machine_setting``: signal name -> value of Machine_Setting_Cmd (the node maps the ROS message).

        Accepted even while emg_stop is latched (it carries no motion).
        """
        with self._lock:
            try:
                setting = dict(self._values["Machine_Setting_Cmd"])
                for key, value in fields.items():
                    if key not in setting or key == "alive_counter":
                        raise Com3CommandError(f"machine_setting: unknown field {key!r}")
                    setting[key] = finite("machine_setting", key, value)
                try:
                    self.codec.encode("Machine_Setting_Cmd", setting)
                except Com3EncodeError as exc:
                    raise Com3CommandError(f"machine_setting: {exc}") from None
                self._values["Machine_Setting_Cmd"] = setting
                self.counters["cmd_accepted"] += 1
                tx = self._encode("Machine_Setting_Cmd")
                self._scheduler.sent("Machine_Setting_Cmd", now)
                return [tx]
            except Com3CommandError as exc:
                self._reject(exc)
                raise

    def emg_stop(self, stop: bool, now: float) -> list[Tx]:
        """Set (True) or clear (False) the emergency-stop latch; setting it sends neutral motion frames at once."""
        with self._lock:
            if stop:
                if not self._emg:
                    _log.warning("%s: emg_stop latched: all motion frames neutral", self.machine)
                self._emg = True
                self.counters["emg_stop_set"] += 1
                return self._neutralise(self._channels.values(), now)
            if self._emg:
                _log.warning("%s: emg_stop cleared: motion frames stay neutral until new commands", self.machine)
                self._emg = False
                self._emg_reason = ""
                for ch in self._channels.values():
                    ch.last_cmd, ch.timed_out = None, False
            return []

    @property
    def emg_latched(self) -> bool:
        """True while the emergency-stop latch is set."""
        return self._emg

    def _neutralise(self, channels: Any, now: float) -> list[Tx]:
        out = []
        for ch in channels:
            for frame in ch.frames:
                self._values[frame] = self.codec.neutral(frame)
                out.append(self._encode(frame))
                self._scheduler.sent(frame, now)
        return out

    def site_heartbeat(self, now: float) -> None:
        """A heartbeat of the site arrived (arms the site watchdog)."""
        with self._lock:
            self._site_seen = now

    @property
    def emg_reason(self) -> str:
        """Why emg_stop latched when the converter latched it itself (site watchdog); else empty."""
        return self._emg_reason

    def site_check(self, now: float) -> list[Tx]:
        """Site watchdog: emg_stop latched (neutral frames returned) once the site heartbeat is ``site_timeout_s`` old
        while the machine is being driven (a channel not timed out whose command is not neutral).

        Call it from the thread that delivers the heartbeats (the node's executor): an expiry seen at one call
        latches only if it still holds at the next, so heartbeats that arrived while that thread was starved
        are handled first and a busy CPU is not taken for a cut link.
        """
        with self._lock:
            timeout = self.config.site_timeout_s
            if timeout <= 0 or self._site_seen is None or now - self._site_seen <= timeout:
                self._site_suspect = False
                return []
            if not self._site_suspect:
                self._site_suspect = True
                return []
            if not any(ch.last_cmd is not None and not ch.timed_out
                       and any(self._values[f] != self.codec.neutral(f) for f in ch.frames)
                       for ch in self._channels.values()):
                # not driven (no command, or a neutral one): nothing to stop; a motion command latches next check
                return []
            silent, self._site_seen, self._site_suspect = now - self._site_seen, None, False  # re-armed by a heartbeat
            self.counters["site_lost"] += 1
            if self._emg:
                return []
            self._emg_reason = f"site link lost: no site heartbeat for {silent:.2f} s (> {timeout:g} s)"
            _log.warning("%s: %s -> emg_stop latched", self.machine, self._emg_reason)
            self._emg = True
            return self._neutralise(self._channels.values(), now)

    # ------------------------------------------------------------------ cyclic
    def tick(self, now: float) -> list[Tx]:
        """Watchdog check, then every frame due at ``now`` (cyclic emission at DBC cycle times)."""
        with self._lock:
            out = []
            for ch in self._channels.values():
                if ch.last_cmd is not None and not ch.timed_out and now - ch.last_cmd > self.config.watchdog_s:
                    ch.timed_out = True
                    self.counters[f"watchdog_{ch.name}"] += 1
                    # a sender that stopped after a neutral command (a navigator at its goal) left nothing moving
                    moving = any(self._values[f] != self.codec.neutral(f) for f in ch.frames)
                    _log.log(
                        logging.WARNING if moving else logging.DEBUG,
                        "%s: watchdog: no %s for %.2f s -> neutral %s", self.machine, ch.last_topic,
                        now - ch.last_cmd, "/".join(ch.frames),
                    )
                    out.extend(self._neutralise([ch], now))
            for name in self._scheduler.due(now):
                out.append(self._encode(name))
            self.counters["frames_tx"] += len(out)
            return out

    def next_wake(self) -> float:
        """Earliest time :meth:`tick` has something to do (next frame due or watchdog expiry)."""
        with self._lock:
            t = self._scheduler.next_due()
            for ch in self._channels.values():
                if ch.last_cmd is not None and not ch.timed_out:
                    t = min(t, ch.last_cmd + self.config.watchdog_s + 1e-4)
            return t

    def current_values(self, frame_name: str) -> dict[str, float]:
        """Physical values the next emission of ``frame_name`` will carry (a copy)."""
        with self._lock:
            return dict(self._values[frame_name])

    # ------------------------------------------------------------------ receive
    def on_frame(
        self,
        arbitration_id: int,
        data: bytes,
        *,
        is_extended_id: bool = True,
        is_error_frame: bool = False,
        is_remote_frame: bool = False,
        stamp: float = 0.0,
    ) -> list[JointStateOut | OdomOut | ImuOut | FixOut]:
        """Decode one received frame; bad frames are counted (``rx_<reason>``) and dropped, never raised.

        ``stamp`` [s] is the ROS time of reception (sim time under ``/clock``), used to integrate odometry.
        """
        with self._lock:
            self.counters["frames_rx"] += 1
            if is_error_frame or is_remote_frame or not is_extended_id:
                reason = "error_frame" if is_error_frame else "remote_frame" if is_remote_frame else "standard_id"
                self.counters[f"rx_{reason}"] += 1
                return []
            if arbitration_id in self._command_ids:  # our own (or another controller's) command frames
                self.counters["rx_command_echo"] += 1
                return []
            try:
                name, values = self.codec.decode(arbitration_id, data)
            except Com3DecodeError as exc:
                self.counters[f"rx_{exc.reason}"] += 1
                self._last_rx_error = str(exc)
                return []
            if self.codec.is_command(name):
                self.counters["rx_command_echo"] += 1  # our own (or another controller's) command frames
                return []
            self.counters["rx_ok"] += 1
            self.state[name] = values
            handler = self.profile.handler(name)
            return handler(self, values, stamp) if handler else []

    # ------------------------------------------------------------------ for the profiles' state handlers
    def plane_to_geodetic(self, easting: float, northing: float) -> tuple[float, float]:
        """(lat, lon) [deg] of a point in the site CRS."""
        if self._projector is None:
            self._projector = Projector(self.config.crs, self.config.map_origin)
        return self._projector.plane_to_geodetic(easting, northing)

    def check_machine_alive(self, alive: int) -> None:
        """Count a ``Machine_State`` alive counter that is not the successor of the previous one."""
        if self._machine_alive is not None and not AliveCounter.is_successor(self._machine_alive, alive):
            self.counters["machine_alive_skips"] += 1
        self._machine_alive = alive

    # ------------------------------------------------------------------ diagnostics
    def diagnostics(self, now: float) -> DiagSnapshot:
        """Level, a message saying why (emg_stop, watchdog, rejects, bad frames) and all counters."""
        with self._lock:
            level, message = DIAG_OK, "ok: commands flowing"
            timed = [ch for ch in self._channels.values() if ch.timed_out]
            waiting = all(ch.last_cmd is None for ch in self._channels.values())
            if self._emg:
                level, message = (
                    DIAG_ERROR,
                    "emg_stop latched: neutral motion frames (publish false on emg_stop to clear)",
                )
                if self._emg_reason:
                    message = f"{self._emg_reason}: {message}"
            elif timed:
                level = DIAG_WARN
                message = "; ".join(
                    f"watchdog: no {ch.last_topic} for {now - (now if ch.last_cmd is None else ch.last_cmd):.2f} s "
                    f"(> {self.config.watchdog_s:g} s) -> neutral {'/'.join(ch.frames)}"
                    for ch in timed
                )
            elif waiting:
                message = "ok: no command yet, neutral frames"
            errors = sum(
                v for k, v in self.counters.items() if k.startswith("rx_") and k not in ("rx_ok", "rx_command_echo")
            )
            if level == DIAG_OK and (self.counters["cmd_rejected"] or errors):
                level = DIAG_WARN
                message += f"; {self.counters['cmd_rejected']} command(s) rejected, {errors} bad frame(s) dropped"
            values: list[tuple[str, str]] = [("machine", self.machine), ("emg_stop", str(self._emg))]
            values += [(k, str(v)) for k, v in sorted(self.counters.items())]
            values.append(("rx_dropped_total", str(errors)))
            values.append(("last_reject", self._last_reject))
            values.append(("last_rx_error", self._last_rx_error))
            values.append(("alive_counter_next", str(self._alive.value)))
            state = self.state.get("Machine_State")
            if state:
                values += [(f"machine_state.{k}", f"{v:g}") for k, v in state.items()]
            return DiagSnapshot(level, message, tuple(values))

