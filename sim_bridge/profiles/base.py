"""Base class of plant profiles (see :mod:`sim_bridge.profiles`), and what a profile works on: a machine's
:class:`Side` of the bus and the :class:`PlantBus` (:class:`sim_bridge.can_io.PlantCanIO` is one)."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any, ClassVar, Protocol

import can
import mujoco
import numpy as np

from com3_can.codec import Com3Codec
from com3_can.scheduler import FrameScheduler
from sim_bridge.physics import Drive
from sim_bridge.sensors import Gnss, Noise
from sim_bridge.spec import PlantMachine, SensorSpec

__all__ = ["PlantBus", "PlantProfile", "Side", "actuator_id"]


class PlantBus(Protocol):
    """The plant's CAN I/O as a profile sees it: sensors and the shared state frames."""

    gnss: Gnss
    noise: Noise

    @property
    def sensors(self) -> SensorSpec: ...

    def body_pos(self, body: str) -> np.ndarray: ...

    def machine_state(self, side: Side) -> dict[str, float]: ...

    def roll_pitch(self, machine: str) -> dict[str, float]: ...


class Side:
    """Per-machine bus state: the machine, its profile, codec, schedule, modes, watchdog and counters."""

    def __init__(self, name: str, machine: Any, profile: type[PlantProfile], bus: can.BusABC, codec: Com3Codec,
                 start: float) -> None:
        self.name = name
        self.machine = machine
        self.profile = profile
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
        self.fix: tuple[float, float, float] | None = None  # GNSS fix shared by the frames of one cycle
        self.cutoff_requested = False
        self.cutoff_at: float | None = None  # simulated time the requested cut-off takes effect
        self.cutoff_engaged = False

    def encode(self, frame: str, values: dict[str, float]) -> can.Message:
        rng = self.ranges[frame]
        clipped = {k: min(rng[k][1], max(rng[k][0], v)) for k, v in values.items()}
        data = self.codec.encode(frame, clipped)
        return can.Message(arbitration_id=self.codec.frame_id(frame), data=data, is_extended_id=True)




def actuator_id(model: mujoco.MjModel, name: str) -> int:
    """Index of actuator ``name`` of the site model (KeyError naming it when the MJCF lacks it)."""
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
    if i < 0:
        raise KeyError(f"the site model has no actuator {name!r}")
    return int(i)


class PlantProfile:
    """The plant side of one machine type; class-level (no per-machine state: that lives in the :class:`Side`).

    * ``machine_type``: registry name (a type constant of :mod:`tms_model.machines`);
    * ``motion_frames``: command frames that feed the command-loss watchdog.

    The DBC of a machine's bus is the one its description names (``Machine.dbc``), not the type's.
    """

    machine_type: ClassVar[str] = ""
    motion_frames: ClassVar[frozenset[str]] = frozenset()

    @staticmethod
    def make_machine(machine: PlantMachine, dt: float) -> Any:
        """The machine state object (an :mod:`sim_bridge.machines` class) at its start pose and joints."""
        raise NotImplementedError

    @staticmethod
    def mjcf(machine: PlantMachine) -> list[str]:
        """MJCF lines of the machine's bodies (a mocap ``<name>_base`` body and its children)."""
        raise NotImplementedError

    @staticmethod
    def mjcf_sections(machine: PlantMachine) -> dict[str, list[str]]:
        """MJCF lines outside ``worldbody`` by section (``tendon``, ``equality``, ``actuator``). Default: one motor on
        each joint, ``<name>_<joint>_drive``, written by the hydraulic drive model (:mod:`sim_bridge.physics`)."""
        name = machine.name
        return {"actuator": [f'    <motor name="{name}_{j.name}_drive" joint="{name}_{j.name}" gear="1"/>'
                             for j in machine.description.joints]}

    @staticmethod
    def drives(machine: PlantMachine, model: mujoco.MjModel) -> list[Drive]:
        """The hydraulic drives of the machine's joints in bank order (:mod:`sim_bridge.physics`). Default: a stiff
        drive on each joint at ``physics.drive_frequency_hz``, clipped at ``physics.drive_torque_limit_nm``."""
        name, ph = machine.name, machine.physics
        assert ph.drive_frequency_hz is not None and ph.drive_torque_limit_nm is not None  # config checks
        out = []
        for j in machine.description.joints:
            limit = ph.drive_torque_limit_nm[j.name]
            out.append(Drive(
                actuator=actuator_id(model, f"{name}_{j.name}_drive"), stiffness=0.0, viscous=0.0, f_min=-limit,
                f_max=limit, x_min=-math.inf if j.lower is None else j.lower,
                x_max=math.inf if j.upper is None else j.upper, damping_ratio=ph.damping_ratio,
                frequency=ph.drive_frequency_hz,
            ))
        return out

    @staticmethod
    def linkage_joints(machine: PlantMachine, q: dict[str, float]) -> dict[str, float]:
        """qpos of the MJCF joints that are not the machine's own (a closed linkage's) at joint positions ``q``,
        by MJCF joint name. Default: none."""
        return {}

    @staticmethod
    def command(io: PlantBus, side: Side, frame: str, values: dict[str, float]) -> None:
        """Apply one decoded command frame to ``side.machine``."""
        raise NotImplementedError

    @staticmethod
    def state(io: PlantBus, side: Side, frame: str) -> dict[str, float]:
        """Physical values of state frame ``frame`` now."""
        raise NotImplementedError
