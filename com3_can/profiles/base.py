"""Base class of converter profiles (see :mod:`com3_can.profiles`) and :class:`Core`, what a profile may use of the
converter core that runs it (:class:`com3_can.bridge_core.BridgeCore` is one)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Protocol

from com3_can.bridge_config import BridgeConfig
from com3_can.codec import Com3Codec
from com3_can.errors import Com3CommandError
from com3_can.outputs import ImuOut, Tx

__all__ = ["ConverterProfile", "Core"]


class Core(Protocol):
    """The converter core as its profile sees it: settings, codec, latest state frames, and the steps every type
    shares (validate a JointCmd, accept a command, set a switch of ``Machine_Setting_Cmd``)."""

    config: BridgeConfig
    codec: Com3Codec
    #: latest decoded values of every state frame (profiles combine frames through it)
    state: dict[str, dict[str, float]]

    def accept(self, topic: str, channel: str, updates: Mapping[str, Mapping[str, float]], now: float) -> list[Tx]: ...

    def set_switch(self, signal: str, value: float) -> None: ...

    def check_joint_cmd(self, topic: str, allowed: Sequence[str], names: Sequence[str], control_type: int,
                        velocity: Sequence[float], effort: Sequence[float]) -> dict[str, float]: ...

    def pilot(self, effort: float, dead_zone: float) -> float: ...

    def plane_to_geodetic(self, easting: float, northing: float) -> tuple[float, float]: ...

    def check_machine_alive(self, alive: int) -> None: ...


class ConverterProfile:
    """What the converter does for one machine type; one instance per converter (it may keep state).

    Class attributes a profile sets:

    * ``machine_type``: registry name (a type constant of :mod:`tms_model.machines`); the DBC is not the
      profile's: the machine description names it (``Machine.dbc``);
    * ``channels``: channel name -> command frames it feeds (one watchdog per channel);
    * ``topics``: the ROS command topics the type takes, named as OPERA's com3_ros names them for that type
      (excavator ``front_cmd``, ``tracks_cmd``; crawler carrier ``track_cmd``, ``rot_dump_cmd``; dozer ``track_cmd``,
      ``blade_cmd`` (ours: OPERA has none public); all ``cmd_vel``);
      ``tracks_topic``: which of them carries the per-track JointCmd; ``setting_topic``: the machine-setting topic;
    * ``state_handlers``: state frame name -> method name; the method gets ``(core, values, stamp)`` and
      returns outputs (:class:`~com3_can.outputs.JointStateOut`, ``OdomOut``, ...).

    A command the type does not take raises :class:`Com3CommandError`; the core counts it as rejected.
    """

    machine_type: ClassVar[str] = ""
    channels: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    topics: ClassVar[frozenset[str]] = frozenset()
    tracks_topic: ClassVar[str] = "tracks_cmd"
    setting_topic: ClassVar[str] = "machine_setting"
    state_handlers: ClassVar[Mapping[str, str]] = {}

    def __init__(self, machine: str) -> None:
        self.machine = machine

    def handler(self, frame: str) -> Callable[[Core, dict[str, float], float], list[Any]] | None:
        name = self.state_handlers.get(frame)
        return None if name is None else getattr(self, name)

    def _refuse(self, topic: str) -> Com3CommandError:
        return Com3CommandError(f"{topic}: the {self.machine} ({self.machine_type}) does not take {topic}; "
                                f"it takes {', '.join(sorted(self.topics))}")

    # ROS commands -> frames (``core.accept`` validates, commits and returns the frames to send)
    def front_cmd(self, core: Core, names: Sequence[str], control_type: int, velocity: Sequence[float],
                  effort: Sequence[float], now: float) -> list[Tx]:
        raise self._refuse("front_cmd")

    def tracks_cmd(self, core: Core, names: Sequence[str], control_type: int, velocity: Sequence[float],
                   effort: Sequence[float], now: float) -> list[Tx]:
        raise self._refuse(self.tracks_topic)

    def cmd_vel(self, core: Core, linear_x: float, angular_z: float, now: float) -> list[Tx]:
        raise self._refuse("cmd_vel")

    def rot_dump_cmd(self, core: Core, names: Sequence[str], control_type: int, position: Sequence[float],
                     now: float) -> list[Tx]:
        raise self._refuse("rot_dump_cmd")

    def blade_cmd(self, core: Core, names: Sequence[str], control_type: int, position: Sequence[float],
                  velocity: Sequence[float], now: float) -> list[Tx]:
        raise self._refuse("blade_cmd")

    # state handlers shared by the types (both DBCs carry these frames)
    def roll_pitch(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        az = core.state.get("Vehicle_Azimuth")
        if az is None:  # no azimuth yet: an IMU with a made-up yaw of 0 would be taken as the machine's heading
            return []
        yaw = -az["track_body_azimuth"]
        rate = az.get("yaw_rate")  # clockwise-positive like the azimuth -> ROS angular z = -yaw_rate
        return [ImuOut(values["roll_angle"], values["pitch_angle"], yaw, None if rate is None else -rate)]

    def machine_state(self, core: Core, values: dict[str, float], stamp: float) -> list[Any]:
        core.check_machine_alive(int(values["alive_counter"]))
        return []
