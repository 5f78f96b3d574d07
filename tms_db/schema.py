"""Shape rules of the original ROS2-TMS documents, and helpers that read fields with clear errors.

Documents follow the original's tms_db (irvs/ros2_tms_for_construction): tasks ``{task_id, type: "task", model_name,
description, task_sequence}``; parameter records ``{model_name?, type?, record_name, ...payload}``.
Payload families checked here:

* ZX200 joint pose ``trajectory: 1`` + ``swing_joint, boom_joint, arm_joint, bucket_joint`` numbers;
* Cartesian pose ``pose: 1`` + ``x, y, z, qx, qy, qz, qw`` numbers;
* ``position_with_angle: 1`` + ``x, y, z, theta_w`` numbers; ``target_angle`` a number;
* array family (waypoints): once any pose key (``x, y, z, qx, qy, qz, qw, yaw, theta_w``) holds an
  array, every field but :data:`ARRAY_READER_SKIPS` (``_id, model_name, type, record_name``) must be an array of
  numbers, the pose keys all of the same length: the original's C++ getter
  (``tms_ts_subtask/subtask_node_base.hpp``, ``CustomGetParamFromDB``) calls ``get_array()`` on every other field
  and throws on anything else, ``description`` and ``timestamps`` included; we refuse the document instead
  (the store writes no ``timestamps`` into such a record, see :func:`is_waypoint_record`).

Anything else (global-blackboard groups, the original's collision-object records) may hold any
JSON/BSON value: bool, int, float, string, null, arrays, sub-documents, datetimes, binary data
(``bytes``, ``bson.Binary``: the original stores collision-object meshes so). ``type`` is any string:
``static`` / ``dynamic`` / ``parameter`` are the ones the stack reads, the original also writes others
(a collision object's ``type`` is whatever its writer was given).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping
from typing import Any

from tms_db.errors import ValidationError

__all__ = [
    "META_FIELDS",
    "ARRAY_READER_SKIPS",
    "POSE_KEYS",
    "is_waypoint_record",
    "MAX_DOCUMENT_BYTES",
    "document_size",
    "check_document_size",
    "is_number",
    "validate_parameter",
    "validate_field_name",
    "validate_fields",
    "normalise_task_xml",
    "detect_model_names",
    "require_numbers",
    "require_arrays",
]

#: Fields that are bookkeeping, not payload (the original getters skip them).
META_FIELDS = frozenset({"_id", "model_name", "type", "record_name", "description", "timestamps"})
#: Fields the original's waypoint (array) reader skips; it reads every other field of such a record as an array.
ARRAY_READER_SKIPS = frozenset({"_id", "model_name", "type", "record_name"})
#: Keys whose values are poses (scalar family) or waypoint arrays (array family).
POSE_KEYS = ("x", "y", "z", "qx", "qy", "qz", "qw", "yaw", "theta_w")
_FAMILIES = {
    "trajectory": ("swing_joint", "boom_joint", "arm_joint", "bucket_joint"),
    "pose": ("x", "y", "z", "qx", "qy", "qz", "qw"),
    "position_with_angle": ("x", "y", "z", "theta_w"),
}
_PORT_KEY_RE = re.compile(r"\{([^{}]+)\}")
#: [bytes] the largest document (task or record) an import, a restore or ``upsert_parameter`` stores: MongoDB's own
#: limit (16 MiB of BSON), so whatever loads here also loads into MongoDB. Measured by :func:`document_size`.
MAX_DOCUMENT_BYTES = 16 * 1024 * 1024


def is_number(value: Any) -> bool:
    """True for a finite int or float that is not a bool (bool is its own type in BSON)."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return True
    return isinstance(value, float) and math.isfinite(value)


def _where(doc: Mapping[str, Any]) -> str:
    record = doc.get("record_name", "?")
    model = doc.get("model_name")
    return f"record {record!r}" + (f" (model {model!r})" if model else "")


def validate_field_name(record: str, name: Any) -> None:
    """A field name is a non-empty string, not starting with ``$`` and without ``.`` (MongoDB rules)."""
    if not isinstance(name, str) or not name:
        raise ValidationError(f"record {record!r}: field name {name!r} must be a non-empty string")
    if name.startswith("$") or "." in name:
        raise ValidationError(f"record {record!r}: field {name!r}: names must not start with '$' or contain '.'")


def _check_value(where: str, field: str, value: Any, depth: int = 0) -> None:
    if value is None or isinstance(value, bool | int | str | bytes | _dt.datetime):
        return
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValidationError(f"{where}: field {field!r}: non-finite number {value!r}")
        return
    if depth > 20:
        raise ValidationError(f"{where}: field {field!r}: nested deeper than 20 levels")
    if isinstance(value, list | tuple):
        for item in value:
            _check_value(where, field, item, depth + 1)
        return
    if isinstance(value, Mapping):
        for key, item in value.items():
            if not isinstance(key, str):
                raise ValidationError(f"{where}: field {field!r}: sub-document key {key!r} is not a string")
            _check_value(where, field, item, depth + 1)
        return
    if type(value).__name__ in ("ObjectId", "Int64", "Decimal128"):  # bson types pass through
        return
    raise ValidationError(f"{where}: field {field!r}: unsupported value type {type(value).__name__} ({value!r})")


def validate_parameter(doc: Mapping[str, Any]) -> None:
    """Check a parameter / blackboard document; raise :class:`ValidationError` naming record and field."""
    if not isinstance(doc, Mapping):
        raise ValidationError(f"parameter document must be a mapping, got {type(doc).__name__}")
    record = doc.get("record_name")
    if not isinstance(record, str) or not record:
        raise ValidationError(f"parameter document {dict(doc)!r:.120}: field 'record_name' must be a non-empty string")
    where = _where(doc)
    model = doc.get("model_name")
    if model is not None and not isinstance(model, str):
        raise ValidationError(f"{where}: field 'model_name' must be a string, got {model!r}")
    kind = doc.get("type")
    if kind is not None and not isinstance(kind, str):
        raise ValidationError(f"{where}: field 'type' must be a string, got {kind!r}")
    if "description" in doc and not isinstance(doc["description"], str):
        raise ValidationError(f"{where}: field 'description' must be a string, got {doc['description']!r}")
    for name, value in doc.items():
        validate_field_name(record, name)
        _check_value(where, name, value)

    payload = {k: v for k, v in doc.items() if k not in META_FIELDS}
    if is_waypoint_record(doc):
        # Array family: the original getter reads every field but ARRAY_READER_SKIPS as an array of numbers.
        length = None
        for name, value in doc.items():
            if name in ARRAY_READER_SKIPS:
                continue
            if not isinstance(value, list | tuple):
                raise ValidationError(
                    f"{where}: field {name!r}: waypoint records need arrays of numbers in every field but "
                    f"{', '.join(sorted(ARRAY_READER_SKIPS))} (the original's array reader throws on anything else), "
                    f"got {type(value).__name__} {value!r:.60}"
                )
            for i, item in enumerate(value):
                if not is_number(item):
                    raise ValidationError(f"{where}: field {name!r}[{i}]: expected a number, got {item!r}")
            if length is None:
                length = len(value)
            elif len(value) != length and name in POSE_KEYS:
                raise ValidationError(
                    f"{where}: field {name!r}: {len(value)} elements, other waypoint fields have {length}"
                )
        return
    for marker, fields in _FAMILIES.items():
        if marker in payload:
            require_numbers(doc, (marker,) + fields)
    if "target_angle" in payload:
        require_numbers(doc, ("target_angle",))


def is_waypoint_record(doc: Mapping[str, Any]) -> bool:
    """True for the array family: any pose key (:data:`POSE_KEYS`) holds an array."""
    return any(isinstance(doc.get(k), list | tuple) for k in POSE_KEYS)


def validate_fields(record: str, fields: Mapping[str, Any], *, protected: Iterable[str] = ("_id",)) -> None:
    """Check a ``{field: value}`` update: names legal, values storable, protected fields untouched."""
    if not isinstance(fields, Mapping) or not fields:
        raise ValidationError(f"record {record!r}: fields to set must be a non-empty mapping, got {fields!r}")
    protected = set(protected)
    for name, value in fields.items():
        validate_field_name(record, name)
        if name in protected:
            raise ValidationError(f"record {record!r}: field {name!r} cannot be set")
        _check_value(f"record {record!r}", name, value)


def require_numbers(doc: Mapping[str, Any], fields: Iterable[str]) -> tuple[float, ...]:
    """Read numeric scalar fields of a record; missing or non-numeric -> ValidationError naming it."""
    out = []
    for name in fields:
        if name not in doc:
            raise ValidationError(f"{_where(doc)}: field {name!r} is missing")
        value = doc[name]
        if not is_number(value):
            raise ValidationError(f"{_where(doc)}: field {name!r}: expected a number, got {value!r}")
        out.append(value)
    return tuple(out)


def require_arrays(doc: Mapping[str, Any], fields: Iterable[str]) -> list[tuple[float, ...]]:
    """Read waypoint arrays (one array per field, same length) as a list of per-point tuples."""
    columns = []
    fields = tuple(fields)
    for name in fields:
        if name not in doc:
            raise ValidationError(f"{_where(doc)}: field {name!r} is missing")
        value = doc[name]
        if not isinstance(value, list | tuple):
            raise ValidationError(f"{_where(doc)}: field {name!r}: expected an array of numbers, got scalar {value!r}")
        for i, item in enumerate(value):
            if not is_number(item):
                raise ValidationError(f"{_where(doc)}: field {name!r}[{i}]: expected a number, got {item!r}")
        if columns and len(value) != len(columns[0]):
            raise ValidationError(
                f"{_where(doc)}: field {name!r}: {len(value)} elements, field {fields[0]!r} has {len(columns[0])}"
            )
        columns.append(value)
    return list(zip(*columns, strict=True))


def normalise_task_xml(xml: str, task: str = "new task") -> str:
    """Parse a BehaviorTree XML and return it as one line (lines stripped), as the original generator stores it.

    Raises :class:`ValidationError` naming the task and ``task_sequence`` when the XML does not parse or has
    no ``<BehaviorTree>``.
    """
    if not isinstance(xml, str) or not xml.strip():
        raise ValidationError(f"{task}: field 'task_sequence': empty behavior-tree XML")
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        line, col = exc.position
        raise ValidationError(
            f"{task}: field 'task_sequence': XML does not parse at line {line}, column {col}: {exc}"
        ) from None
    if root.find("BehaviorTree") is None and root.tag != "BehaviorTree":
        raise ValidationError(f"{task}: field 'task_sequence': no <BehaviorTree> element under <{root.tag}>")
    parts: list[str] = []
    for line in xml.splitlines():
        line = line.strip()
        if not line:
            continue
        if parts and not parts[-1].endswith(">"):
            parts.append(" ")  # inside a tag or text: keep attributes / words split over lines apart
        parts.append(line)
    one_line = "".join(parts)
    try:
        ET.fromstring(one_line)
    except ET.ParseError as exc:  # pragma: no cover - joining must never break a parsing document
        raise ValidationError(f"{task}: field 'task_sequence': one-line form does not parse: {exc}") from None
    return one_line


def detect_model_names(xml: str, blackboard: Mapping[str, Any] | None = None) -> str:
    """The machines a task's leaves drive, comma-joined in document order: the ``model_name`` port of every node
    inside a ``<BehaviorTree>``.

    The node palette (``<TreeNodesModel>``, Groot's list of node types with their default ports) names machines
    the task may never drive, so it is not read. (The original's task_generator.py searched the whole text for
    every machine name it knew: a tree driving two machines with a third machine's leaf type in its palette was
    recorded as driving all three.) A port ``model_name="{key}"`` names the machine the task parameter ``key`` holds
    (``blackboard``, the task document's field) when it is text; without it that leaf names no machine.
    """
    root = ET.fromstring(xml)
    trees = [root] if root.tag == "BehaviorTree" else root.findall("BehaviorTree")
    seen: list[str] = []
    for tree in trees:
        for el in tree.iter():
            raw = el.get("model_name")
            if raw is None:
                continue
            name = raw.strip()
            m = _PORT_KEY_RE.fullmatch(name)
            if m:
                value = (blackboard or {}).get(m.group(1))
                name = value.strip() if isinstance(value, str) else ""
            name = name.strip("/")
            if name and name not in seen:
                seen.append(name)
    return ",".join(seen)


def document_size(doc: Mapping[str, Any]) -> int:
    """[bytes] a document's size as MongoDB counts it (its BSON); a document BSON cannot hold (an int past 64 bits,
    which the embedded store keeps) is measured by its JSON text instead."""
    import bson

    try:
        return len(bson.encode(doc))
    except (bson.errors.BSONError, OverflowError, TypeError, ValueError):
        import json

        return len(json.dumps(doc, default=str, ensure_ascii=False).encode("utf-8", "surrogatepass"))


def check_document_size(doc: Mapping[str, Any], where: str) -> None:
    """ValidationError naming ``where`` when ``doc`` is over :data:`MAX_DOCUMENT_BYTES`."""
    size = document_size(doc)
    if size > MAX_DOCUMENT_BYTES:
        raise ValidationError(f"{where}: document is {size:,} bytes, over the limit of {MAX_DOCUMENT_BYTES:,} "
                              "(MAX_DOCUMENT_BYTES, MongoDB's 16 MiB)")
