"""Name -> implementation registries, as python-can finds its interfaces (``can.interfaces.BACKENDS``).

A machine type (a type constant of :mod:`tms_model.machines`) is a name; the converter and the plant each keep a
:class:`Registry` of what serves that type on their side. Registering a name twice is an error (two
modules claiming one type is a packaging mistake, not something to resolve silently), and looking up an
unknown name names the known ones. :func:`machine_type` says which type a machine is, from its kind's
machine description ``config/machines/<kind>.yaml`` (key ``type``).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Generic, TypeVar

from tms_common.errors import ConfigError
from tms_model.fleet import load_named

__all__ = ["Registry", "machine_type"]

T = TypeVar("T")


class Registry(Generic[T]):
    """Items found by name; ``what`` names the registry in error messages (e.g. "converter profile")."""

    def __init__(self, what: str) -> None:
        self.what = what
        self._items: dict[str, T] = {}

    def register(self, name: str, item: T) -> T:
        """Add ``item`` under ``name``; a name already taken raises ``ValueError``."""
        if not name or not isinstance(name, str):
            raise ValueError(f"{self.what}: name must be a non-empty string, got {name!r}")
        if name in self._items:
            raise ValueError(f"{self.what} {name!r} is already registered ({self._items[name]!r})")
        self._items[name] = item
        return item

    def get(self, name: str) -> T:
        """The item registered as ``name``; an unknown name raises ``ConfigError`` listing the known ones."""
        try:
            return self._items[name]
        except KeyError:
            raise ConfigError(f"unknown {self.what} {name!r}; known: {', '.join(sorted(self._items))}") from None

    def names(self) -> tuple[str, ...]:
        return tuple(sorted(self._items))

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())


def machine_type(name: str) -> str:
    """The type (profile name) of the machine called ``name``: ``type`` of its kind's description
    (:func:`tms_model.fleet.load_named`)."""
    return load_named(name).type
