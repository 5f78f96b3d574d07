"""The local blackboard of one task, with BehaviorTree.CPP 3.8.7's typing rules, and the original nodes' text rules.

Each task run owns one :class:`Blackboard` (BT.CPP's per-tree blackboard; the original manager had one per
process). A non-shared SubTree gets a child blackboard whose remapped keys are the parent's entries. The
*global* blackboard is not here: it is documents in the DB (tms_db).

An entry is BT.CPP's ``Blackboard::Entry``: a value with its *original* C++ type (``Any::type()``: ``bool``,
``int``, ``long``, ``unsigned int``, ``double``, ``std::string``) and the port information it was created with
(a declared type or none, and whether strings can be parsed into that type). The rules, from BT.CPP 3.8.7
(``include/behaviortree_cpp_v3/blackboard.h``, ``src/blackboard.cpp``, ``src/xml_parsing.cpp``,
``include/behaviortree_cpp_v3/tree_node.h``, ``utils/safe_any.hpp``, ``utils/convert_impl.hpp``):

* **Declared at load** (``xml_parsing.cpp`` 556-601): a port written ``{key}`` creates entry ``key`` with the
  port's type and its string converter (``InputPort<bool>`` -> ``bool``; an untyped ``InputPort("x")`` -> no
  type), empty. A second typed port of another type on the same key is a load error, unless the entry was
  declared ``std::string`` first (``:577-593``).
* **set() of a new key** (``blackboard.h:105-119``): a string makes an *untyped* entry; any other value an entry
  typed with the value's type but no converter.
* **set() of an existing entry** (``blackboard.h:121-151``): an untyped entry takes anything. A typed entry
  takes its own type; a *string* is parsed with the entry's converter (``convertFromString``, e.g. ``"true"`` ->
  ``bool``); anything else, or a string when the entry has no converter (it was made by set()), is refused:
  ``LogicError "once declared, the type of a port shall not change"``. Through a SubTree's remapping the
  *first* set() from the subtree only checks declared types (``createEntryImpl``, ``blackboard.cpp:96-145``):
  a string is stored as it is.
* **getInput<T>** (``tree_node.h:231-290``): a literal is ``convertFromString<T>``; a ``{key}`` entry holding a
  string is ``convertFromString<T>`` of it when T is not a string; otherwise ``Any::cast<T>`` (numbers convert
  with range and truncation checks, ``bool`` is ``!= 0``, to ``std::string`` is ``std::to_string``: ``true`` ->
  ``"1"``, ``1.5`` -> ``"1.500000"``; a string never casts to a number).
* ``convertFromString`` (``src/basic_types.cpp``): ``bool`` only ``0 1 true TRUE True false FALSE False``;
  ``int`` / ``long`` / ``unsigned`` are ``std::stoi`` / ``stol`` / ``stoul`` (leading blanks, a sign, digits, the
  rest ignored: ``"12abc"`` -> 12); ``double`` is ``std::stod`` (``"1.5m"`` -> 1.5).

What BT.CPP throws is :class:`BlackboardError` here; the node that caused it names itself, its line and the key.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from typing import Any

__all__ = [
    "Blackboard",
    "BlackboardError",
    "Entry",
    "MISSING",
    "BOOL",
    "INT",
    "LONG",
    "UINT",
    "DOUBLE",
    "STRING",
    "ctype_of",
    "convert_from_string",
    "any_cast",
    "cpp_to_string",
    "typed_from_text",
    "mongo_typed_from_text",
    "stoi_prefix",
    "to_text",
]

MISSING: Any = object()

# C++ types as BT.CPP's messages name them (BT::demangle on Linux)
BOOL, INT, LONG, UINT, DOUBLE, STRING = "bool", "int", "long", "unsigned int", "double", "std::string"
_INTEGRAL = frozenset({BOOL, INT, LONG, UINT})  # Any stores these as int64_t (safe_any.hpp:86-89)
_LIMITS = {INT: (-(2**31), 2**31 - 1), LONG: (-(2**63), 2**63 - 1), UINT: (0, 2**32 - 1)}

_INT_RE = re.compile(r"-?\d+")
_FLOAT_RE = re.compile(r"-?\d*\.\d+")
_C_SPACE = " \t\n\v\f\r"  # isspace() in the C locale: what strtol/strtod skip
_STOI_RE = re.compile(r"([+-]?)(\d+)")
_HEX_RE = re.compile(r"[+-]?0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?\d+)?")
_DEC_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_SPECIAL_RE = re.compile(r"([+-]?)(inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?)", re.IGNORECASE)


class BlackboardError(Exception):
    """What BT.CPP 3.8.7 throws on a blackboard access (its text); the calling node adds who and where."""


def ctype_of(value: Any) -> str:
    """The C++ type BT.CPP would hold ``value`` as: Python int -> ``int`` (``long`` beyond 32 bits, or a BSON Int64)."""
    if isinstance(value, bool):
        return BOOL
    if isinstance(value, int):
        if type(value).__name__ == "Int64" or not -(2**31) <= value < 2**31:
            return LONG
        return INT
    if isinstance(value, float):
        return DOUBLE
    if isinstance(value, str):
        return STRING
    return f"python {type(value).__name__}"


class Entry:
    """``Blackboard::Entry``: ``value`` (MISSING while empty) of C++ type ``vtype``; ``port_type`` declared or None."""

    __slots__ = ("value", "vtype", "port_type", "converter")

    def __init__(self, port_type: str | None, converter: bool) -> None:
        self.value: Any = MISSING
        self.vtype: str | None = None
        self.port_type = port_type
        self.converter = converter and port_type is not None

    @property
    def empty(self) -> bool:
        return self.value is MISSING

    def describe(self) -> str:
        declared = f"declared {self.port_type}" if self.port_type else "untyped"
        if self.empty:
            return f"{declared}, never set"
        return f"{declared}, holding {self.vtype} {self.value!r}"


class Blackboard:
    """Key -> :class:`Entry` store of one tree; ``remap`` maps local keys to keys of ``parent`` (a SubTree's ports)."""

    __slots__ = ("_storage", "_parent", "_remap")

    def __init__(self, parent: Blackboard | None = None, remap: dict[str, str] | None = None) -> None:
        self._storage: dict[str, Entry] = {}
        self._parent = parent
        self._remap = dict(remap or {})

    # -- BT.CPP's API ------------------------------------------------------------------------------
    def get_any(self, key: str) -> Entry | None:
        """``getAny``: the entry at ``key`` (following a remapping), possibly empty; None if there is none."""
        entry = self._storage.get(key)
        if entry is None and self._parent is not None and key in self._remap:
            return self._parent.get_any(self._remap[key])
        return entry

    def local_entry(self, key: str) -> Entry | None:
        """``getEntry`` / ``portInfo``: this blackboard's own storage only (no remapping)."""
        return self._storage.get(key)

    def create_entry(self, key: str, port_type: str | None, converter: bool = False) -> Entry:
        """``createEntryImpl``: the existing entry (refusing another declared type), else a new one (in the parent
        when ``key`` is remapped)."""
        entry = self._storage.get(key)
        if entry is not None:
            if entry.port_type is not None and port_type is not None and entry.port_type != port_type:
                raise BlackboardError(
                    "Blackboard: once declared, the type of a port shall not change. Previously declared type "
                    f"[{entry.port_type}] != new type [{port_type}]")
            return entry
        if self._parent is not None and key in self._remap:
            entry = self._parent.create_entry(self._remap[key], port_type, converter)
        else:
            entry = Entry(port_type, converter)
        self._storage[key] = entry
        return entry

    def declare(self, key: str, port_type: str | None) -> None:
        """What the XML parser does for a port written ``{key}`` (xml_parsing.cpp 574-599)."""
        prev = self._storage.get(key)
        if prev is None:
            self.create_entry(key, port_type, converter=True)
            return
        if prev.port_type is not None and port_type is not None and prev.port_type != port_type \
                and prev.port_type != STRING:
            raise BlackboardError(
                f"The creation of the tree failed because the port [{key}] was initially created with type "
                f"[{prev.port_type}] and, later type [{port_type}] was used somewhere else.")

    def set(self, key: str, value: Any, ctype: str | None = None) -> None:
        """``Blackboard::set``: store ``value`` (C++ type ``ctype``, default :func:`ctype_of`) by BT.CPP's rules."""
        ctype = ctype or ctype_of(value)
        entry = self._storage.get(key)
        if entry is None:
            # a string makes an untyped entry, anything else one typed without a converter (blackboard.h:110-116)
            entry = self.create_entry(key, None if ctype == STRING else ctype)
            entry.value, entry.vtype = value, ctype
            return
        declared = entry.port_type
        if declared is not None and declared != ctype:
            if ctype == STRING and entry.converter:
                try:
                    value = convert_from_string(value, declared)
                except ValueError as exc:
                    raise BlackboardError(
                        f"set('{key}', \"{value}\"): the entry was declared {declared} by a port, and "
                        f"convertFromString<{declared}> refuses the text: {exc}") from None
                ctype = declared
            else:
                why = ("(a string is parsed only into an entry a typed port declared; this one was created by "
                       "set() with a value of that type)" if ctype == STRING else "")
                raise BlackboardError(
                    "Blackboard::set() failed: once declared, the type of a port shall not change. Declared type "
                    f"[{declared}] != current type [{ctype}]" + (f" {why}" if why else ""))
        entry.value, entry.vtype = value, ctype

    def cast(self, key: str, target: str) -> Any:
        """``Blackboard::get<T>``: the entry's value as ``target`` (``Any::cast``); MISSING if there is no entry."""
        entry = self.get_any(key)
        if entry is None:
            return MISSING
        if entry.empty:
            raise BlackboardError(f"Any::cast failed because it is empty (entry [{key}] was declared but never set)")
        return any_cast(entry.value, entry.vtype or STRING, target)

    # -- the Python view -----------------------------------------------------------------------------
    def get(self, key: str, default: Any = MISSING) -> Any:
        """The value at ``key``, or ``default`` (MISSING when not given) if absent or never set."""
        entry = self.get_any(key)
        if entry is None or entry.value is MISSING:
            return default
        return entry.value

    def __contains__(self, key: str) -> bool:
        return self.get(key) is not MISSING

    def keys(self) -> Iterator[str]:
        yield from self._storage
        yield from (k for k in self._remap if k not in self._storage)

    def snapshot(self) -> dict[str, Any]:
        """A plain dict of every value visible from here (entries never set are left out), for status and tests."""
        out = {}
        for key in self.keys():
            value = self.get(key)
            if value is not MISSING:
                out[key] = value
        return out


# -- BT.CPP conversions -----------------------------------------------------------------------------------
def stoi_prefix(text: str) -> int | None:
    """``std::stol``'s parse: leading blanks, a sign, digits, the rest ignored; None when there are no digits."""
    m = _STOI_RE.match(text.lstrip(_C_SPACE))
    return int(m.group(1) + m.group(2)) if m else None


def _stod(text: str) -> float:
    body = text.lstrip(_C_SPACE)
    m = _HEX_RE.match(body)
    if m:
        s = m.group(0)
        sign = -1.0 if s.startswith("-") else 1.0
        try:
            value = sign * float.fromhex(s.lstrip("+-"))
        except OverflowError:
            raise ValueError(f"std::stod: {text!r} is out of range (out_of_range)") from None
    else:
        m = _DEC_RE.match(body)
        if m:
            value = float(m.group(0))
            if math.isinf(value):
                raise ValueError(f"std::stod: {text!r} is out of range (out_of_range)")
            if value == 0.0 and any(c in "123456789" for c in m.group(0).split("e")[0].split("E")[0]):
                raise ValueError(f"std::stod: {text!r} underflows (out_of_range)")
        else:
            m = _SPECIAL_RE.match(body)
            if not m:
                raise ValueError(f"expected a number, got {text!r} (std::stod: no conversion)")
            value = float(m.group(1) + ("nan" if m.group(2).lower().startswith("nan") else "inf"))
    return value


def convert_from_string(text: str, ctype: str) -> Any:
    """``BT::convertFromString<T>`` (basic_types.cpp 96-206); ValueError names what was refused."""
    if ctype == STRING:
        return text
    if ctype == BOOL:
        if text in ("1", "true", "TRUE", "True"):
            return True
        if text in ("0", "false", "FALSE", "False"):
            return False
        raise ValueError(
            f"expected a bool (true/false, 1/0), got {text!r} (convertFromString(): invalid bool conversion)"
        )
    if ctype in _LIMITS:
        number = stoi_prefix(text)
        fn = {INT: "stoi", LONG: "stol", UINT: "stoul"}[ctype]
        if number is None:
            kind = "an unsigned integer" if ctype == UINT else "an integer"
            raise ValueError(f"expected {kind}, got {text!r} (std::{fn}: no conversion)")
        if ctype == UINT:
            # unsigned(std::stoul(s)): strtoul negates a '-' modulo 2^64, the cast keeps 32 bits
            if abs(number) > 2**64 - 1:
                raise ValueError(f"{text!r} is out of range of unsigned long (std::stoul: out_of_range)")
            return (number % 2**64) % 2**32
        lo, hi = _LIMITS[ctype]
        if not lo <= number <= hi:
            raise ValueError(f"{text!r} is out of range of {ctype} (std::{fn}: out_of_range)")
        return number
    if ctype == DOUBLE:
        return _stod(text)
    raise ValueError(f"no convertFromString for type {ctype}")


def cpp_to_string(value: Any, vtype: str) -> str:
    """``Any::cast<std::string>`` of a number: ``std::to_string`` (bool -> "1"/"0", double -> "%f")."""
    if vtype == DOUBLE:
        return f"{value:f}"
    return str(int(value))


def any_cast(value: Any, vtype: str, target: str) -> Any:
    """``Any::cast<T>`` (safe_any.hpp 119-247, convert_impl.hpp); ValueError with BT.CPP's reason."""
    if vtype == target:
        return value
    if target == STRING:
        if vtype == STRING:
            return value
        if vtype in _INTEGRAL or vtype == DOUBLE:
            return cpp_to_string(value, vtype)
    elif vtype in _INTEGRAL:
        number = int(value)
        if target == BOOL:
            return number != 0
        if target == DOUBLE:
            if float(number) != number:
                raise ValueError("Floating point truncated")
            return float(number)
        if target in _LIMITS:
            lo, hi = _LIMITS[target]
            if number < lo:
                raise ValueError("Value is negative and can't be converted to signed" if target == UINT
                                 else "Value too small.")
            if number > hi:
                raise ValueError("Value too large.")
            return number
    elif vtype == DOUBLE:
        if target == BOOL:
            return value != 0.0
        if target == DOUBLE:
            return value
        if target in _LIMITS:
            lo, hi = _LIMITS[target]
            if target == UINT and value < 0:
                raise ValueError("Value is negative and can't be converted to signed")
            if target != UINT and value < -hi:
                raise ValueError("Value too small.")
            if math.isnan(value) or value > hi or value != math.trunc(value):
                raise ValueError("Floating point truncated")
            return int(value)
    stored = "SafeAny::SimpleString" if vtype == STRING else vtype
    raise ValueError(f"[Any::convert]: no known safe conversion between [{stored}] and [{target}]")


# -- the original nodes' text rules ---------------------------------------------------------------------------
def typed_from_text(text: str) -> tuple[Any, str]:
    """SetLocalBlackboard's rule -> (value, C++ type): "true"/"false" -> bool, ``^-?\\d+$`` -> int,
    ``^-?\\d*\\.\\d+$`` -> double, else the string.

    The int is read with ``std::istringstream >> int``, which saturates at the int range.
    """
    if text == "true":
        return True, BOOL
    if text == "false":
        return False, BOOL
    if _INT_RE.fullmatch(text):
        lo, hi = _LIMITS[INT]
        return min(max(int(text), lo), hi), INT
    if _FLOAT_RE.fullmatch(text):
        return float(text), DOUBLE
    return text, STRING


def mongo_typed_from_text(text: str) -> Any:
    """MongoValueWriter's rule: "true"/"false" -> bool; containing "." -> ``std::stod``; else ``std::stoi``, and
    the text itself when that finds no digits. ValueError where the original fails the node (``".x"``, out of range).
    """
    if text == "true":
        return True
    if text == "false":
        return False
    if "." in text:
        return _stod(text)
    number = stoi_prefix(text)
    if number is None:
        return text
    lo, hi = _LIMITS[INT]
    if not lo <= number <= hi:
        raise ValueError(f"{text!r} is out of range of int (std::stoi: out_of_range)")
    return number


def to_text(value: Any) -> str:
    """Render a blackboard value as BT.CPP text (bools as true/false), for messages."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
