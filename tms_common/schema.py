"""The one way configuration is read: every error is one line ``file:line: key.path: problem``.

Two forms over the same error format:

* :func:`read_schema` / :func:`load_schema`: a frozen dataclass *is* the schema of a fixed mapping. Each field is
  a key of the same name; its annotation is the type checked; its default (visible where the dataclass is
  declared) is used when the key is absent; :func:`setting` adds bounds and a description. A key the dataclass
  does not declare is refused, so a typo never falls back to a default silently.
* :class:`Reader`: typed accessors for documents whose shape depends on their values (a machine description's
  ``type:`` chooses its sections); :meth:`Reader.only` refuses unknown keys there.

Annotations understood by :func:`read_schema`: ``float`` (an int is accepted, a bool is not, NaN/inf are refused),
``int``, ``bool``, ``str`` (non-empty), ``tuple[T, ...]`` and fixed ``tuple[T, T]``, ``dict[str, T]``, a nested
dataclass, and ``T | None`` (the key may hold null). Bounds from :func:`setting` apply to a number and to every
number of a tuple or dict.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from tms_common.config import Where, load_yaml
from tms_common.errors import ConfigError

__all__ = ["Reader", "setting", "read_schema", "load_schema", "schema_keys"]

T = TypeVar("T")
_MISSING = dataclasses.MISSING


def setting(default: Any = _MISSING, *, lo: float | None = None, hi: float | None = None, doc: str = "",
            default_factory: Any = _MISSING) -> Any:
    """A dataclass field of a schema: its default, inclusive bounds ``lo``/``hi`` for numbers, a description."""
    meta = {"lo": lo, "hi": hi, "doc": doc}
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    if isinstance(default, (list, dict, set)):
        raise TypeError("a mutable default must be given as default_factory")
    return dataclasses.field(default=default, metadata=meta)


def _name(path: tuple[Any, ...]) -> str:
    return ".".join(str(p) for p in path) or "<document>"


def _error(where: Where, path: tuple[Any, ...], problem: str) -> ConfigError:
    return ConfigError(f"{where.file}:{where.line_of(path)}: {_name(path)}: {problem}")


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def schema_keys(cls: type) -> tuple[str, ...]:
    """The keys a schema dataclass accepts (init fields), in declaration order."""
    return tuple(f.name for f in dataclasses.fields(cls) if f.init)


def _number(value: Any, where: Where, path: tuple[Any, ...], integer: bool, lo: float | None, hi: float | None) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _error(where, path, f"expected {'an integer' if integer else 'a number'}, got {value!r}")
    if integer and not isinstance(value, int):
        raise _error(where, path, f"expected an integer, got {value!r}")
    if not math.isfinite(value):
        raise _error(where, path, f"expected a finite number, got {value!r}")
    if lo is not None and value < lo:
        raise _error(where, path, f"must be >= {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise _error(where, path, f"must be <= {hi}, got {value!r}")
    return int(value) if integer else float(value)


def _convert(tp: Any, value: Any, where: Where, path: tuple[Any, ...], meta: dict[str, Any]) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    lo, hi = meta.get("lo"), meta.get("hi")
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        if value is None and len(inner) < len(args):
            return None
        if len(inner) != 1:
            raise TypeError(f"schema field {_name(path)}: only 'T | None' unions are supported, got {tp}")
        return _convert(inner[0], value, where, path, meta)
    if tp is Any:
        return value
    if tp is float or tp is int:
        return _number(value, where, path, tp is int, lo, hi)
    if tp is bool:
        if not isinstance(value, bool):
            raise _error(where, path, f"expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str) or not value:
            raise _error(where, path, f"expected a non-empty string, got {value!r}")
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise _error(where, path, f"expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            item_types = [args[0]] * len(value)
        else:
            if len(value) != len(args):
                raise _error(where, path, f"expected a list of {len(args)} values, got {len(value)}: {value!r}")
            item_types = list(args)
        return tuple(
            _convert(t, v, where, path + (i,), meta) for i, (t, v) in enumerate(zip(item_types, value, strict=True))
        )
    if origin is dict:
        if not isinstance(value, dict):
            raise _error(where, path, f"expected a mapping, got {value!r}")
        key_type, value_type = args
        out = {}
        for k, v in value.items():
            if key_type is str and not isinstance(k, str):
                raise _error(where, path + (k,), f"expected a text key, got {k!r}")
            out[k] = _convert(value_type, v, where, path + (k,), meta)
        return types.MappingProxyType(out)
    if dataclasses.is_dataclass(tp):
        return read_schema(tp, value, where, path)
    raise TypeError(f"schema field {_name(path)}: unsupported annotation {tp!r}")


def read_schema(cls: type[T], data: Any, where: Where, path: tuple[Any, ...] = ()) -> T:
    """An instance of the dataclass ``cls`` from the mapping ``data`` (at ``path`` of the document ``where``).

    Raises:
        ConfigError: ``file:line: key.path: problem`` for a missing required key, a key ``cls`` does not declare,
            a value of the wrong type or out of its bounds, or what ``cls.__post_init__`` refuses (a ValueError).
    """
    if not isinstance(data, dict):
        raise _error(where, path, f"expected a mapping, got {type(data).__name__} {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for key in data:
        if key not in fields:
            raise _error(where, path + (key,), f"unknown key; expected one of {sorted(fields)}")
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name not in data:
            if f.default is _MISSING and f.default_factory is _MISSING:
                raise _error(where, path + (name,), "missing required key")
            continue
        kwargs[name] = _convert(hints[name], data[name], where, path + (name,), dict(f.metadata))
    try:
        return cls(**kwargs)
    except ValueError as exc:
        if isinstance(exc, ConfigError):
            raise
        raise _error(where, path, str(exc)) from None


def load_schema(cls: type[T], path: str | Path, section: tuple[Any, ...] = ()) -> T:
    """Read the YAML file ``path`` (limits and encoding checks of :func:`tms_common.config.load_yaml`) and return
    ``cls`` from its mapping at ``section`` (the whole document by default)."""
    data, where = load_yaml(path)
    for i, key in enumerate(section):
        if not isinstance(data, dict) or key not in data:
            raise _error(where, section[: i + 1], "missing required key")
        data = data[key]
    return read_schema(cls, data, where, tuple(section))


class Reader:
    """One mapping of a YAML document plus where it came from, for documents whose shape depends on their values.

    Every accessor raises :class:`ConfigError` naming the file, the line and the key path, so a typo in a
    machine or site YAML points at itself instead of surfacing later as a KeyError.
    """

    def __init__(self, data: Any, where: Where, path: tuple[Any, ...] = ()) -> None:
        self.where = where
        self.path = path
        if not isinstance(data, dict):
            raise self.error(path, f"expected a mapping, got {type(data).__name__} {data!r}")
        self.data = data

    def error(self, path: tuple[Any, ...], problem: str) -> ConfigError:
        return _error(self.where, path, problem)

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

    def schema(self, cls: type[T], key: str | None = None) -> T:
        """This mapping (or its ``key``) read as the schema dataclass ``cls`` (:func:`read_schema`)."""
        if key is None:
            return read_schema(cls, self.data, self.where, self.path)
        return read_schema(cls, self.raw(key), self.where, self.path + (key,))

    def number(
        self, key: str, *, lo: float | None = None, hi: float | None = None, default: float | None = None
    ) -> float:
        if default is not None and key not in self.data:
            return float(default)
        return float(_number(self.raw(key), self.where, self.path + (key,), False, lo, hi))

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
