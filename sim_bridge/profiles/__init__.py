"""Plant profiles: what the plant does for one machine type, found by name as the converter's profiles are.

A profile reads the type's machine YAML into a spec, builds the machine (:mod:`sim_bridge.machines`), writes
its MuJoCo bodies, applies its COM3 command frames and builds its state frames, all through the signal
map of :mod:`com3_can.signal_map`. :class:`~sim_bridge.can_io.PlantCanIO`, :class:`~sim_bridge.plant.Plant`
and :func:`~sim_bridge.model.build_mjcf` are neutral and ask the profile of each machine's ``type``.

``PLANT_PROFILES`` is the registry: ``excavator``, ``crawler_dump`` and ``dozer`` register on import; another type
registers with ``PLANT_PROFILES.register("name", Class)`` (a duplicate name is refused, an unknown one
named with the known ones).
"""

from __future__ import annotations

from com3_can.registry import Registry
from sim_bridge.profiles.base import PlantProfile

__all__ = ["PLANT_PROFILES", "PlantProfile"]

#: machine type -> plant profile class
PLANT_PROFILES: Registry[type[PlantProfile]] = Registry("plant profile")


def _register_builtins() -> None:
    from sim_bridge.profiles.crawler_carrier import CrawlerCarrierPlantProfile
    from sim_bridge.profiles.dozer import DozerPlantProfile
    from sim_bridge.profiles.excavator import ExcavatorPlantProfile

    PLANT_PROFILES.register(ExcavatorPlantProfile.machine_type, ExcavatorPlantProfile)
    PLANT_PROFILES.register(CrawlerCarrierPlantProfile.machine_type, CrawlerCarrierPlantProfile)
    PLANT_PROFILES.register(DozerPlantProfile.machine_type, DozerPlantProfile)


_register_builtins()
