"""Base class of plant profiles (see :mod:`sim_bridge.profiles`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from com3_can.codec import Com3Codec
from com3_can.profiles.base import codec_for

if TYPE_CHECKING:
    from sim_bridge.can_io import PlantCanIO, Side

__all__ = ["PlantProfile"]


class PlantProfile:
    """The plant side of one machine type; class-level (no per-machine state: that lives in the :class:`Side`).

    * ``type``: registry name; ``dbc``: DBC file in ``com3_can/dbc`` (the converter profile's);
    * ``motion_frames``: command frames that feed the command-loss watchdog.
    """

    machine_type: ClassVar[str] = ""
    dbc: ClassVar[str] = ""
    motion_frames: ClassVar[frozenset[str]] = frozenset()

    @classmethod
    def codec(cls, machine: str) -> Com3Codec:
        return codec_for(cls.dbc, machine)

    @staticmethod
    def load_spec(path: Path) -> Any:
        """The machine spec of a machine YAML of this type."""
        raise NotImplementedError

    @staticmethod
    def make_machine(spec: Any, dt: float, pose: tuple[float, float, float]) -> Any:
        """The machine state object (an :mod:`sim_bridge.machines` class)."""
        raise NotImplementedError

    @staticmethod
    def mjcf(name: str, spec: Any) -> list[str]:
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
