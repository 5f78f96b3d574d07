"""Plant profiles: what the plant does for one machine type, found by name as the converter's profiles are.

A profile builds the type's machine (:mod:`sim_bridge.machines`) from its description placed on the site
(:class:`~sim_bridge.spec.PlantMachine`), writes its MuJoCo bodies, applies its COM3 command frames and builds its
state frames, all through the signal map of :mod:`com3_can.signal_map`. :class:`~sim_bridge.can_io.PlantCanIO`,
:class:`~sim_bridge.plant.Plant` and :func:`~sim_bridge.model.build_mjcf` are neutral and ask the profile of each
machine's ``type``.

``PLANT_PROFILES`` is the registry, the one place that maps machine types to plant code: ``excavator``,
``crawler_dump`` and ``dozer`` are registered here; another type registers with ``PLANT_PROFILES.register("name",
Class)`` (a duplicate name is refused, an unknown one named with the known ones). The profiles import nothing of
this module, :mod:`sim_bridge.config` or :mod:`sim_bridge.can_io`: the dependency runs from the registry (and the
modules that ask it) to them, and they see the bus I/O through :class:`~sim_bridge.profiles.base.PlantBus`.
"""

from __future__ import annotations

from com3_can.registry import Registry
from sim_bridge.profiles.base import PlantProfile
from sim_bridge.profiles.crawler_carrier import CrawlerCarrierPlantProfile
from sim_bridge.profiles.dozer import DozerPlantProfile
from sim_bridge.profiles.excavator import ExcavatorPlantProfile

__all__ = ["PLANT_PROFILES", "PlantProfile"]

#: machine type -> plant profile class
PLANT_PROFILES: Registry[type[PlantProfile]] = Registry("plant profile")

for _profile in (ExcavatorPlantProfile, CrawlerCarrierPlantProfile, DozerPlantProfile):
    PLANT_PROFILES.register(_profile.machine_type, _profile)
