"""The local blackboard of one task, and the string-to-type conversions of the original nodes.

Each task run owns one :class:`Blackboard` (BT.CPP's per-tree blackboard; the original manager had
one per process). Values keep their Python type (bool, int, float, str), as BT.CPP's ``Any`` keeps
the C++ type. A non-shared SubTree gets a child blackboard whose remapped keys read and write the
parent's entries. The *global* blackboard is not here: it is documents in the DB (tms_db).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

__all__ = ["Blackboard", "MISSING", "typed_from_text", "mongo_typed_from_text", "to_text"]

MISSING: Any = object()

_INT_RE = re.compile(r"-?\d+")
_FLOAT_RE = re.compile(r"-?\d*\.\d+")


class Blackboard:
    """Key -> typed value store of one tree; ``remap`` maps local keys to keys of ``parent``."""

    __slots__ = ("_data", "_parent", "_remap")

    def __init__(self, parent: Blackboard | None = None, remap: dict[str, str] | None = None) -> None:
        self._data: dict[str, Any] = {}
        self._parent = parent
        self._remap = dict(remap or {})

    def get(self, key: str, default: Any = MISSING) -> Any:
        """The value at ``key``, or ``default`` (MISSING when not given) if absent."""
        if self._parent is not None and key in self._remap:
            return self._parent.get(self._remap[key], default)
        return self._data.get(key, default)

    def set(self, key: str, value: Any) -> None:
        """Store ``value`` at ``key`` (in the parent when ``key`` is remapped)."""
        if self._parent is not None and key in self._remap:
            self._parent.set(self._remap[key], value)
        else:
            self._data[key] = value

    def __contains__(self, key: str) -> bool:
        return self.get(key) is not MISSING

    def keys(self) -> Iterator[str]:
        yield from self._data
        yield from self._remap

    def snapshot(self) -> dict[str, Any]:
        """A plain dict copy of every entry visible from here (for status and tests)."""
        return {k: self.get(k) for k in self.keys()}


def typed_from_text(text: str) -> Any:
    """SetLocalBlackboard's rule: "true"/"false" -> bool, ``-?\\d+`` -> int, ``-?\\d*\\.\\d+`` -> float, else str."""
    if text == "true":
        return True
    if text == "false":
        return False
    if _INT_RE.fullmatch(text):
        return int(text)
    if _FLOAT_RE.fullmatch(text):
        return float(text)
    return text


def mongo_typed_from_text(text: str) -> Any:
    """MongoValueWriter's rule: "true"/"false" -> bool, contains "." -> float, integer -> int, else str."""
    if text == "true":
        return True
    if text == "false":
        return False
    if "." in text:
        try:
            return float(text)
        except ValueError:
            return text
    try:
        return int(text)
    except ValueError:
        return text


def to_text(value: Any) -> str:
    """Render a blackboard value as BT.CPP text (bools as true/false)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
