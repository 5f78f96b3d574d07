"""Converter profiles: what the COM3 converter does for one machine kind, found by name.

A profile says which DBC the kind speaks, its command channels (frames guarded by one watchdog), how
each ROS command becomes frames and how each state frame becomes outputs. :class:`~com3_can.bridge_core.BridgeCore`
is neutral: it validates, latches, schedules and counts, and hands every kind-specific step to its profile.

``PROFILES`` is the registry (``can.interfaces.BACKENDS`` style): the built-in kinds ``excavator`` and
``crawler_carrier`` register on import; another kind registers its class with
``PROFILES.register("name", Class)``. A machine model (``zx200``, ``zx120``, ``ic120``) names its kind in
``config/machines/<model>.yaml``; :func:`profile_for` resolves a model to its profile class.
"""

from __future__ import annotations

from com3_can.profiles.base import ConverterProfile
from com3_can.registry import Registry, machine_kind

__all__ = ["PROFILES", "ConverterProfile", "profile_for"]

#: kind name -> converter profile class
PROFILES: Registry[type[ConverterProfile]] = Registry("converter profile")


def profile_for(machine: str) -> type[ConverterProfile]:
    """The profile class of machine model ``machine`` (via its kind in the machine description)."""
    return PROFILES.get(machine_kind(machine))


def _register_builtins() -> None:
    from com3_can.profiles.crawler_carrier import CrawlerCarrierProfile
    from com3_can.profiles.excavator import ExcavatorProfile

    PROFILES.register(ExcavatorProfile.kind, ExcavatorProfile)
    PROFILES.register(CrawlerCarrierProfile.kind, CrawlerCarrierProfile)


_register_builtins()
