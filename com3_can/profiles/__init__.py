"""Converter profiles: what the COM3 converter does for one machine type, found by name.

A profile says which command channels the type has (frames guarded by one watchdog), how each ROS command
becomes frames and how each state frame becomes outputs. :class:`~com3_can.bridge_core.BridgeCore` is neutral:
it validates, latches, schedules and counts, and hands every type-specific step to the profile it is given.

``PROFILES`` is the registry (``can.interfaces.BACKENDS`` style) and the one place here that lists the types: the
built-in ones (the type constants of :mod:`tms_model.machines`) register on import; another type registers its
class with ``PROFILES.register(name, Class)``. A machine kind names its type (key ``type``) in
``config/machines/<kind>.yaml``; :func:`profile_for` resolves a machine name to its profile class,
:func:`converter_profile` to the profile a converter of that machine runs.
"""

from __future__ import annotations

from com3_can.profiles.base import ConverterProfile
from com3_can.profiles.crawler_carrier import CrawlerCarrierProfile
from com3_can.profiles.dozer import DozerProfile
from com3_can.profiles.excavator import ExcavatorProfile
from com3_can.registry import Registry, machine_type
from tms_model.machines import CRAWLER_DUMP, DOZER, EXCAVATOR

__all__ = ["PROFILES", "ConverterProfile", "converter_profile", "profile_for"]

#: machine type -> converter profile class
PROFILES: Registry[type[ConverterProfile]] = Registry("converter profile")
PROFILES.register(EXCAVATOR, ExcavatorProfile)
PROFILES.register(CRAWLER_DUMP, CrawlerCarrierProfile)
PROFILES.register(DOZER, DozerProfile)


def profile_for(machine: str) -> type[ConverterProfile]:
    """The profile class of the machine called ``machine`` (via the type of its kind's description)."""
    return PROFILES.get(machine_type(machine))


def converter_profile(machine: str) -> ConverterProfile:
    """A new profile instance for a converter of the machine called ``machine`` (what
    :class:`~com3_can.bridge_core.BridgeCore` is given)."""
    return profile_for(machine)(machine)
