"""Settings of one ``com3_bridge`` converter: its ``config/can/<kind>.yaml`` ``bridge:`` section, its machine
description and the site, in one frozen :class:`BridgeConfig`.

Everything type-specific is read from what the description has (a vessel, a swing, a blade), never from its
type or kind, so a new machine of a known type needs no code here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from com3_can.bus import load_bus_config
from com3_can.codec import dbc_file
from tms_common.errors import ConfigError
from tms_model.fleet import load_named
from tms_model.machines import LIFT_JOINT, Machine
from tms_model.site import load_site

__all__ = ["BridgeConfig"]

#: keys of the ``bridge:`` section of config/can/<kind>.yaml
BRIDGE_KEYS = frozenset({"watchdog_s", "diagnostic_period_s", "default_setting", "effort_dead_zone"})


@dataclass(frozen=True)
class BridgeConfig:
    """Settings of one converter (config/can/<kind>.yaml ``bridge`` + config/machines/<kind>.yaml + the site).

    ``machine`` is the machine's name on the site; ``machine_type`` (its profile's registry name) and ``dbc`` are
    read from its description when not given.
    """

    machine: str
    watchdog_s: float = 0.5
    diagnostic_period_s: float = 0.5
    default_setting: Mapping[str, float] = field(default_factory=dict)
    effort_dead_zone: Mapping[str, float] = field(default_factory=dict)
    track_gauge: float = 2.0
    vessel_max_angle: float = 1.134464
    #: a carrier's swing (rotate_joint) command range [rad]; None = no rotating upper body
    swing_range: tuple[float, float] | None = None
    #: a dozer's blade lift (lift_joint) command range [rad] and rate limit [rad/s]
    blade_range: tuple[float, float] = (0.0, 0.0)
    blade_velocity: float = 0.0
    #: DBC file of the machine's bus (com3_can/dbc), as its description names it
    dbc: str = ""
    #: site map origin in the plane-rectangular CRS (excavator swing-centre -> map) and the CRS itself
    map_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    crs: str = "EPSG:6677"
    machine_type: str = ""
    #: no site heartbeat for this long (after a first one) -> emg_stop latched; 0 = no site watchdog
    site_timeout_s: float = 0.0

    def __post_init__(self) -> None:
        if not self.machine_type or not self.dbc:
            description = load_named(self.machine)  # unknown machine -> ConfigError naming the site's
            object.__setattr__(self, "machine_type", self.machine_type or description.type)
            object.__setattr__(self, "dbc", self.dbc or dbc_file(description.kind))
        if not (math.isfinite(self.watchdog_s) and self.watchdog_s > 0):
            raise ConfigError(f"com3_bridge: watchdog_s must be > 0 s, got {self.watchdog_s}")
        if not (math.isfinite(self.site_timeout_s) and self.site_timeout_s >= 0):
            raise ConfigError(f"com3_bridge: site_timeout_s must be >= 0 s (0 = off), got {self.site_timeout_s}")
        if not self.track_gauge > 0:
            raise ConfigError(f"com3_bridge: track gauge must be > 0 m, got {self.track_gauge}")

    @classmethod
    def load(cls, machine: str, can_config: Mapping[str, Any] | None = None, **overrides: Any) -> BridgeConfig:
        """Build for the machine called ``machine`` from its kind's ``config/can/<kind>.yaml`` (as the site
        changes it for this machine), the machine description and the site; ``overrides`` win."""
        description = load_named(machine)
        if can_config is None:
            can_config = load_bus_config(machine)
        bridge = dict((can_config or {}).get("bridge") or {})
        unknown = sorted(set(bridge) - BRIDGE_KEYS)
        if unknown:
            raise ConfigError(f"config/can/{description.kind}.yaml: bridge: unknown key(s) {unknown}; "
                              f"known: {sorted(BRIDGE_KEYS)}")
        site = load_site()
        kwargs: dict[str, Any] = {"machine": machine, "machine_type": description.type,
                                  "dbc": dbc_file(description.kind), **bridge, **from_description(description),
                                  "map_origin": site.origin_plane, "crs": site.crs}
        kwargs.update(overrides)
        return cls(**kwargs)


def from_description(description: Machine) -> dict[str, Any]:
    """The :class:`BridgeConfig` fields a machine description gives: track gauge, and the command ranges of
    whatever it carries (vessel, swinging upper body, blade)."""
    out: dict[str, Any] = {"track_gauge": description.tracks.gauge}
    if description.vessel is not None:
        out["vessel_max_angle"] = description.vessel.max_angle
    if description.swing is not None:
        s = description.swing
        out["swing_range"] = (-math.pi, math.pi) if s.lower is None or s.upper is None else (s.lower, s.upper)
    if description.blade is not None:
        lift = description.joint(LIFT_JOINT)
        assert lift.lower is not None and lift.upper is not None  # tms_model: the lift joint has limits
        out["blade_range"] = (lift.lower, lift.upper)
        out["blade_velocity"] = lift.velocity
    return out
