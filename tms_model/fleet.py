"""Machine names -> machines: the site's list of machines (``machines:`` of ``config/site.yaml``).

A machine's name is the original's ``model_name``: the namespace of its nodes and the first segment of its
actions (``/ic120_1/st_ic120_follow_waypoints``). Its kind is the description it shares with every machine
of that kind (``config/machines/<kind>.yaml``). Several machines of one kind are several names; code that
needs per-kind knowledge asks :func:`machine_kind` or :func:`load_named` instead of reading the name as a kind.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader
from tms_model.machines import Joint, Machine, load_machine
from tms_model.site import Site, SiteMachine, load_site

__all__ = ["BusConfig", "CAN_KEYS", "load_bus_config", "load_named", "machine_kind", "machine_name", "site_machine",
           "vessel_swing_joint"]

#: keys of config/can/<kind>.yaml: the link (python-can's interface, channel and its backends' options), the
#: link used when the plant and the converter share a process, and the converter's settings (com3_can's)
CAN_KEYS = frozenset({"interface", "channel", "port", "hop_limit", "fd", "receive_own_messages", "in_process",
                      "bridge"})


def site_machine(name: str, site: Site | None = None) -> SiteMachine:
    """The site's entry of machine ``name``; ConfigError listing the site's machines when it has none."""
    site = site or load_site()
    try:
        return site.machine(name)
    except KeyError as exc:
        raise ConfigError(str(exc.args[0])) from None


def machine_kind(name: str, site: Site | None = None) -> str:
    """The kind of the machine called ``name`` (``ic120_1`` -> ``ic120``)."""
    return site_machine(name, site).kind


def load_named(name: str, path: str | Path | None = None, site: Site | None = None) -> Machine:
    """The description of the machine called ``name``: its kind's (or the file ``path``'s), named ``name``."""
    kind = machine_kind(name, site)
    return load_machine(kind, path).named(name)


def machine_name(parameter: str, namespace: str, default: str = "") -> str:
    """The machine a machine-side node serves: its ``machine`` parameter, else the last segment of its namespace
    (``/ic120_1`` -> ``ic120_1``), else ``default``; ConfigError when none gives one."""
    name = parameter.strip() or namespace.rstrip("/").rpartition("/")[2] or default
    if not name:
        raise ConfigError("no machine: give the parameter machine:=<name> or run the node in the machine's "
                          "namespace (-r __ns:=/<name>)")
    return name


def vessel_swing_joint(machine: Machine) -> Joint | None:
    """The joint that swings a crawler carrier's vessel (MST-type carriers: a vertical axis), None for a carrier
    whose vessel only tips (the IC120). Read from the description: a vessel and a joint about the z axis."""
    if machine.vessel is None:
        return None
    return next((j for j in machine.joints if tuple(j.axis) == (0.0, 0.0, 1.0)), None)


class BusConfig(dict[str, Any]):
    """A machine's CAN bus options (a plain mapping, as python-can takes them) with where each was given:
    ``origin[key]`` is ``file:line`` of the key in its config/can file, or the site entry or node parameter that
    changed it (``origin[""]``: the file itself), so an error about an option names where to fix it."""

    def __init__(self, data: Mapping[str, Any] = MappingProxyType({}), origin: Mapping[str, str] | None = None) -> None:
        super().__init__(data)
        self.origin = dict(origin or {})

    def at(self, key: str = "") -> str:
        """Where ``key`` was given, else where the options came from ("" when not known)."""
        return self.origin.get(key) or self.origin.get("", "")


def load_bus_config(name: str, path: str | Path | None = None, site: Site | None = None) -> BusConfig:
    """The CAN bus configuration of the machine called ``name``, for every reader of a bus (the converter, the
    plant, ``tms_rc_identify``): its kind's ``config/can/<kind>.yaml`` (or ``path``) read through
    :mod:`tms_common.schema` (unknown keys refused, types checked, ``file:line`` errors), with the site's ``can``
    changes for this machine over the top level (``machines:`` of config/site.yaml: two machines of one kind need
    udp_multicast ports of their own) and ``{name}`` in the ``in_process`` channel replaced by the machine's name.

    Raises:
        ConfigError: the machine is not on the site, the file is missing or bad, or another machine of the site
            would share its link.
    """
    site = site or load_site()
    entry = site_machine(name, site)
    default = config_path("can", f"{entry.kind}.yaml")
    path = Path(path) if path else default
    data, where = load_yaml(path)
    reader = Reader(data, where)
    reader.only(set(CAN_KEYS))
    reader.string("interface")
    reader.string("channel")
    if reader.has("port"):
        port = reader.raw("port")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
            raise reader.key_error("port", f"expected a port number 1..65535, got {port!r}")
    if reader.has("in_process"):
        local = reader.sub("in_process")
        local.only({"interface", "channel", "receive_own_messages"})
        local.string("interface")
        local.string("channel")
    if reader.has("bridge"):
        reader.sub("bridge")  # a mapping; its keys are the converter's (com3_can.bridge_config)
    origin = {"": f"{where.file}:1"}
    for key in data:
        origin[key] = f"{where.file}:{where.line_of((key,))}"
    for key in data.get("in_process") or {}:
        origin[f"in_process.{key}"] = f"{where.file}:{where.line_of(('in_process', key))}"
    for key in entry.can:
        origin[key] = f"{site.source}: machines.{name}.can.{key}"
    out = BusConfig(_named(data, entry), origin)
    link = _udp_link(out)
    if link and path == default:
        for other in site.machines.values():
            if other.name != name and other.kind == entry.kind and _udp_link(_named(data, other)) == link:
                raise ConfigError(f"{path}: machines {name!r} and {other.name!r} of the site would share the "
                                  f"udp_multicast link {link}: give one its own port (machines.<name>.can.port in "
                                  f"{site.source})")
    return out


def _named(data: Mapping[str, Any], entry: SiteMachine) -> dict[str, Any]:
    """The kind's bus config as machine ``entry`` uses it."""
    out = {**data, **entry.can}
    local = data.get("in_process")
    if isinstance(local, Mapping) and isinstance(local.get("channel"), str):
        out["in_process"] = {**local, "channel": local["channel"].replace("{name}", entry.name)}
    return out


def _udp_link(cfg: Mapping[str, Any]) -> tuple[str, int] | None:
    if cfg.get("interface") != "udp_multicast":
        return None
    return str(cfg.get("channel")), int(cfg.get("port", 0))
