"""A machine kind's navigation file: ``config/nav/<kind>_nav.yaml`` over the default ``config/nav/tracked_nav.yaml``.

Every tracked machine's localisation and navigator (tms_rp.tracked.config) and a carrier's vessel controller
(tms_rc, its ``vessel`` section) read the same files, merged once, here. The default file holds every section
complete; a kind's file may hold only what differs: each of its sections is merged key by key over the
default's. A kind without its own file uses the default. Each consumer reads the sections it owns with its own
schema dataclass (:meth:`NavFiles.section`): the default's section is read alone first, then the merged one
against the kind's file, so an error names the file and line its value came from.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from tms_common.config import Where, config_path, load_yaml
from tms_common.schema import read_schema

__all__ = ["DEFAULT_NAV", "NAV_SECTIONS", "NavFiles", "load_nav_files", "nav_path_for"]

T = TypeVar("T")

#: the default nav file, of a kind without ``config/nav/<kind>_nav.yaml``
DEFAULT_NAV = "tracked_nav.yaml"
#: every section a nav file may hold (its consumers: the localisation, costmap, planner, controller, goal and
#: progress checkers, and legs of tms_rp.tracked; vessel of tms_rc.carrier; tracks and footprint: what the
#: machine's description does not give)
NAV_SECTIONS = ("localization", "costmap", "planner", "controller", "goal_checker", "progress_checker", "vessel",
                "tracks", "footprint", "legs")


def nav_path_for(kind: str) -> Path:
    """``config/nav/<kind>_nav.yaml`` when it exists, else the default ``config/nav/tracked_nav.yaml``."""
    own = Path(config_path("nav", f"{kind}_nav.yaml"))
    return own if own.is_file() else Path(config_path("nav", DEFAULT_NAV))


def _read(path: Path) -> tuple[dict, Where]:
    data, where = load_yaml(path)
    if not isinstance(data, dict):
        raise where.error((), "a nav file must be a mapping of sections")
    for key, value in data.items():
        if key not in NAV_SECTIONS:
            raise where.error((key,), f"unknown section {key!r}; known: {sorted(NAV_SECTIONS)}")
        if not isinstance(value, dict):
            raise where.error((key,), f"section {key!r} must be a mapping")
    return data, where


@dataclass(frozen=True)
class NavFiles:
    """One kind's nav file (``path``) and the default under it (the same file for a kind without its own)."""

    path: Path
    own: Mapping[str, Any]
    own_where: Where
    default: Mapping[str, Any]
    default_where: Where

    def has(self, section: str) -> bool:
        return section in self.own or section in self.default

    def merged(self, section: str) -> dict:
        """The section's keys: the default's, overridden by the kind's file's."""
        return {**self.default.get(section, {}), **self.own.get(section, {})}

    def where(self, section: str) -> Where:
        """The file a message about the section names: the kind's file when it holds the section."""
        return self.own_where if section in self.own else self.default_where

    def section(self, cls: type[T], section: str) -> T:
        """The merged ``section`` read as the schema dataclass ``cls`` (:func:`tms_common.schema.read_schema`);
        a section neither file holds is read as empty (the dataclass's defaults, or an error naming a missing key)."""
        if section in self.default and self.own is not self.default:
            read_schema(cls, dict(self.default[section]), self.default_where, (section,))
        return read_schema(cls, self.merged(section), self.where(section), (section,))


def load_nav_files(kind: str, nav_yaml: str | Path | None = None) -> NavFiles:
    """The nav files of ``kind``: ``nav_yaml`` (default :func:`nav_path_for` the kind) over the default file.
    A file given by path is read even when missing (the error names it)."""
    path = Path(nav_yaml) if nav_yaml else nav_path_for(kind)
    default_path = Path(config_path("nav", DEFAULT_NAV))
    own, own_where = _read(path)
    if path.resolve() == default_path.resolve():
        return NavFiles(path, own, own_where, own, own_where)
    default, default_where = _read(default_path)
    return NavFiles(path, own, own_where, default, default_where)
