"""Machine names -> machines: the site's list of machines (``machines:`` of ``config/site.yaml``).

A machine's name is the original's ``model_name``: the namespace of its nodes and the first segment of its
actions (``/ic120_1/st_ic120_follow_waypoints``). Its kind is the description it shares with every machine
of that kind (``config/machines/<kind>.yaml``). Several machines of one kind are several names; code that
needs per-kind knowledge asks :func:`machine_kind` or :func:`load_named` instead of reading the name as a kind.
"""

from __future__ import annotations

from pathlib import Path

from tms_common.errors import ConfigError
from tms_model.machines import Joint, Machine, load_machine
from tms_model.site import Site, SiteMachine, load_site

__all__ = ["load_named", "machine_kind", "machine_name", "site_machine", "vessel_swing_joint"]


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
