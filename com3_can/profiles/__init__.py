"""Converter profiles: what the COM3 converter does for one machine type, found by name.

A profile says which DBC the type speaks, its command channels (frames guarded by one watchdog), how
each ROS command becomes frames and how each state frame becomes outputs. :class:`~com3_can.bridge_core.BridgeCore`
is neutral: it validates, latches, schedules and counts, and hands every type-specific step to its profile.

``PROFILES`` is the registry (``can.interfaces.BACKENDS`` style): the built-in types ``excavator``,
``crawler_dump`` and ``dozer`` register on import; another type registers its class with
``PROFILES.register("name", Class)``. A machine kind (``zx200``, ``zx120``, ``ic120``, ``mst110cr``, ``d37pxi``, ...) names its type (key ``type``) in
``config/machines/<model>.yaml``; :func:`profile_for` resolves a model to its profile class.
"""

from __future__ import annotations

from com3_can.profiles.base import ConverterProfile
from com3_can.registry import Registry, machine_type

__all__ = ["PROFILES", "ConverterProfile", "profile_for"]

#: machine type -> converter profile class
PROFILES: Registry[type[ConverterProfile]] = Registry("converter profile")


def profile_for(machine: str) -> type[ConverterProfile]:
    """The profile class of machine model ``machine`` (via its type in the machine description)."""
    return PROFILES.get(machine_type(machine))


def _register_builtins() -> None:
    from com3_can.profiles.crawler_carrier import CrawlerCarrierProfile
    from com3_can.profiles.dozer import DozerProfile
    from com3_can.profiles.excavator import ExcavatorProfile

    PROFILES.register(ExcavatorProfile.machine_type, ExcavatorProfile)
    PROFILES.register(CrawlerCarrierProfile.machine_type, CrawlerCarrierProfile)
    PROFILES.register(DozerProfile.machine_type, DozerProfile)


_register_builtins()
