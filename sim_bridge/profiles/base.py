"""Base class of plant profiles (see :mod:`sim_bridge.profiles`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from sim_bridge.spec import PlantMachine

if TYPE_CHECKING:  # the bus I/O runs the profiles; they only see its type
    from sim_bridge.can_io import PlantCanIO, Side

__all__ = ["PlantProfile"]


class PlantProfile:
    """The plant side of one machine type; class-level (no per-machine state: that lives in the :class:`Side`).

    * ``machine_type``: registry name (a type constant of :mod:`tms_model.machines`);
    * ``motion_frames``: command frames that feed the command-loss watchdog.

    The DBC of a machine's bus is its description's (``PlantMachine.dbc``), not the type's.
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
    def command(io: PlantCanIO, side: Side, frame: str, values: dict[str, float]) -> None:
        """Apply one decoded command frame to ``side.machine``."""
        raise NotImplementedError

    @staticmethod
    def state(io: PlantCanIO, side: Side, frame: str) -> dict[str, float]:
        """Physical values of state frame ``frame`` now."""
        raise NotImplementedError
