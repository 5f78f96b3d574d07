"""CAN bus construction from configuration: ``socketcan``, ``udp_multicast`` or ``virtual``.

``open_bus({"interface": ..., "channel": ..., **extras})`` returns a ``can.BusABC`` built with
``ignore_config=True`` so the YAML is the whole truth (no ``~/can.conf`` or environment leaking in).
A backend that cannot be opened raises :class:`Com3BusError` saying why, e.g. "SocketCAN is not
available in this kernel" or that ``vcan0`` does not exist.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import can

from com3_can.errors import Com3BusError
from tms_common.errors import ConfigError
from tms_model.fleet import BusConfig, load_bus_config  # the one reader of config/can/<kind>.yaml

__all__ = ["BusConfig", "BACKENDS", "IN_PROCESS_ENV", "open_bus", "socketcan_available", "load_bus_config",
           "link_config", "in_process_machines"]

_log = logging.getLogger(__name__)

#: interface -> extra keys it accepts besides ``interface`` and ``channel``
BACKENDS: Mapping[str, frozenset[str]] = {
    "socketcan": frozenset({"receive_own_messages", "fd"}),
    "udp_multicast": frozenset({"port", "hop_limit", "fd"}),
    "virtual": frozenset({"receive_own_messages"}),
}
#: keys of a config/can/<machine>.yaml that are not bus options
_IGNORED_KEYS = frozenset({"bridge", "in_process"})
#: machines (comma-separated) whose plant and COM3 converter run in this process: their link is in-process.
#: tms-launch sets it for a container that holds the plant and those converters (tms_launch.launch_file).
IN_PROCESS_ENV = "TMS_CAN_IN_PROCESS"


def socketcan_available() -> bool:
    """True when the kernel offers AF_CAN raw sockets (SocketCAN)."""
    if not hasattr(socket, "AF_CAN"):
        return False
    try:
        sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError:
        return False
    sock.close()
    return True


def open_bus(cfg: Mapping[str, Any]) -> can.BusABC:
    """Open the CAN bus described by ``cfg`` (``interface``, ``channel``, backend extras).

    A :class:`BusConfig` (what :func:`load_bus_config` and :func:`link_config` return) knows where each option
    was given: every error then starts with that ``file:line`` (or the site entry or node parameter).

    Raises:
        ConfigError: unknown interface, missing channel or an extra key the backend does not take.
        Com3BusError: the backend exists but cannot be opened here (message says why).
    """

    def at(key: str = "") -> str:
        where = cfg.at(key) if isinstance(cfg, BusConfig) else ""
        return f"{where}: {key + ': ' if key else ''}" if where else ""

    interface = cfg.get("interface")
    if interface not in BACKENDS:
        raise ConfigError(f"{at('interface')}CAN interface {interface!r} unknown; expected one of "
                          f"{', '.join(BACKENDS)}")
    channel = cfg.get("channel")
    if not channel:
        raise ConfigError(f"{at('channel')}CAN {interface}: 'channel' is required")
    extras = {k: v for k, v in cfg.items() if k not in {"interface", "channel"} | _IGNORED_KEYS}
    unknown = sorted(set(extras) - BACKENDS[interface])
    if unknown:
        raise ConfigError(
            f"{at(unknown[0])}CAN {interface}: unknown option(s) {unknown}; accepted: {sorted(BACKENDS[interface])}"
        )
    if interface == "socketcan":
        if not socketcan_available():
            raise Com3BusError(f"{at('interface')}SocketCAN is not available in this kernel (no AF_CAN sockets); "
                               "use interface udp_multicast or virtual, or run in a VM with vcan")
        if not Path("/sys/class/net", str(channel)).exists():
            raise Com3BusError(
                f"{at('channel')}SocketCAN interface {channel!r} does not exist (create it: ip link add dev "
                f"{channel} type vcan; ip link set up {channel})"
            )
    if interface == "udp_multicast":
        extras.setdefault("fd", False)
    try:
        bus = can.Bus(interface=interface, channel=channel, ignore_config=True, **extras)
    except (can.CanError, OSError, NotImplementedError, ImportError) as exc:
        raise Com3BusError(f"{at('channel')}cannot open CAN {interface} channel {channel!r}: {exc}") from exc
    _log.info("opened CAN bus interface=%s channel=%s options=%s", interface, channel, extras)
    return bus


def in_process_machines() -> frozenset[str]:
    """The machines :data:`IN_PROCESS_ENV` names (empty when unset)."""
    return frozenset(m.strip() for m in os.environ.get(IN_PROCESS_ENV, "").split(",") if m.strip())


def link_config(machine: str, cfg: Mapping[str, Any], *, interface: str = "", channel: str = "",
                port: int = 0) -> BusConfig:
    """The bus options of ``machine``'s COM3 link, for either end (plant or converter): the one place that
    chooses the interface.

    1. Any override given (a node's ``can_interface`` / ``can_channel`` / ``can_port`` parameters) applies
       over the file's top level: explicit wins.
    2. Else, when the plant and this machine's converter run in one process (:data:`IN_PROCESS_ENV` names
       the machine), the file's ``in_process`` section: python-can's ``virtual`` interface, which hands a
       frame to the other buses of its channel in this process and not back to its sender.
    3. Else the file's top level: ``udp_multicast`` between processes of one host, ``socketcan`` on a
       machine's own CAN bus.

    Raises:
        ConfigError: the machine is named in-process but its file has no ``in_process`` mapping.
    """
    if not (interface or channel or port) and machine in in_process_machines():
        local = cfg.get("in_process")
        if not isinstance(local, Mapping):
            raise ConfigError(f"CAN link of {machine!r}: {IN_PROCESS_ENV} names it but its bus config has no "
                              "'in_process' mapping (e.g. in_process: {interface: virtual, channel: com3_<machine>})")
        origin = cfg.origin if isinstance(cfg, BusConfig) else {}
        return BusConfig(local, {"": origin.get("in_process", origin.get("", "")),
                                 **{k: origin[f"in_process.{k}"] for k in local if f"in_process.{k}" in origin}})
    out = BusConfig({k: v for k, v in cfg.items() if k not in _IGNORED_KEYS},
                    cfg.origin if isinstance(cfg, BusConfig) else None)
    for key, value in (("interface", interface), ("channel", channel), ("port", port)):
        if value:
            out[key] = value
            out.origin[key] = f"the {key} given by a node parameter"
    if out.get("interface") != "udp_multicast":
        out.pop("port", None)
    return out
