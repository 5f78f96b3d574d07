"""Typed access to a YAML mapping that reports ``file:line: key.path: problem`` on bad input."""

from __future__ import annotations

import math
from typing import Any

from tms_common.config import Where
from tms_common.errors import ConfigError

__all__ = ["Reader"]


class Reader:
    """One mapping of a YAML document plus where it came from.

    Every accessor raises :class:`ConfigError` naming the file, the line and the key path, so a typo in a
    machine or site YAML points at itself instead of surfacing later as a KeyError.
    """

    def __init__(self, data: Any, where: Where, path: tuple[Any, ...] = ()) -> None:
        self.where = where
        self.path = path
        if not isinstance(data, dict):
            raise self.error(path, f"expected a mapping, got {type(data).__name__} {data!r}")
        self.data = data

    @staticmethod
    def _name(path: tuple[Any, ...]) -> str:
        return ".".join(str(p) for p in path) or "<document>"

    def error(self, path: tuple[Any, ...], problem: str) -> ConfigError:
        return ConfigError(f"{self.where.file}:{self.where.line_of(path)}: {self._name(path)}: {problem}")

    def key_error(self, key: str, problem: str) -> ConfigError:
        return self.error(self.path + (key,), problem)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str) -> Any:
        if key not in self.data:
            raise self.key_error(key, "missing required key")
        return self.data[key]

    def sub(self, key: str) -> Reader:
        return Reader(self.raw(key), self.where, self.path + (key,))

    def keys(self) -> list[str]:
        return list(self.data)

    def only(self, allowed: set[str]) -> None:
        """Reject keys not in ``allowed`` (typos in sections whose every key we know)."""
        for key in self.data:
            if key not in allowed:
                raise self.key_error(key, f"unknown key; expected one of {sorted(allowed)}")

    def number(self, key: str, *, lo: float | None = None, hi: float | None = None, default: float | None = None) -> float:
        if default is not None and key not in self.data:
            return float(default)
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.key_error(key, f"expected a number, got {value!r}")
        if lo is not None and value < lo:
            raise self.key_error(key, f"must be >= {lo}, got {value!r}")
        if hi is not None and value > hi:
            raise self.key_error(key, f"must be <= {hi}, got {value!r}")
        return float(value)

    def vector(self, key: str, n: int) -> tuple[float, ...]:
        value = self.raw(key)
        ok = isinstance(value, list) and len(value) == n
        ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        if not ok:
            raise self.key_error(key, f"expected a list of {n} numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def string(self, key: str, default: str | None = None) -> str:
        if default is not None and key not in self.data:
            return default
        value = self.raw(key)
        if not isinstance(value, str) or not value:
            raise self.key_error(key, f"expected a non-empty string, got {value!r}")
        return value

    def names(self, key: str) -> tuple[str, ...]:
        value = self.raw(key)
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            raise self.key_error(key, f"expected a non-empty list of names, got {value!r}")
        return tuple(value)

    def per_name(self, key: str, names: tuple[str, ...] | list[str], *, lo: float | None = None) -> dict[str, float]:
        """A mapping ``{name: number}`` that must list exactly ``names``."""
        sub = self.sub(key)
        sub.only(set(names))
        return {name: sub.number(name, lo=lo) for name in names}
