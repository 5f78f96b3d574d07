"""Environment data: the original's ``Tmsdb`` documents, one collection per ``type``, and binary objects (GridFS).

The original's ``tms_db_writer`` stores each ``tms_msg_db/msg/Tmsdb`` as ``{time, type, id, name, msg}`` (``msg``
the decoded JSON) in the collection named by ``type``, with a descending index on ``time``; ``tms_db_reader`` finds
``{id}`` (plus ``{name}`` when the request's name is not empty) ascending by ``time``, or the newest one. Its GridFS
writer stores terrain files with ``fs.put(data, filename=..., time=..., type=..., id=...)`` and its readers pick the
newest by ``time``. This module holds what both backends share: the checks (errors name the field), the stamp the
store adds for retention, and the shape of a blob's file document.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Mapping
from typing import Any

from tms_db.errors import BlobTooLarge, ValidationError
from tms_db.schema import check_document_size

__all__ = [
    "INSERTED_FIELD",
    "RESERVED_TYPES",
    "DEFAULT_MAX_BLOB_BYTES",
    "BLOB_CHUNK_BYTES",
    "BLOB_COLLECTIONS",
    "BLOB_FILE_FIELDS",
    "check_type",
    "check_data_document",
    "check_data_query",
    "check_blob",
    "check_blob_filter",
    "check_prune",
    "blob_sort_key",
    "data_sort_key",
]

#: Field the store stamps on every ``insert_data`` (a UTC datetime, BSON Date): retention by age reads it. The
#: original's reader copies only time, type, id, name and msg into its ``Tmsdb`` reply, so it never sees this field.
INSERTED_FIELD = "_inserted_at"
#: Collections that are not environment data: the task and parameter collections, and GridFS's own two.
BLOB_COLLECTIONS = ("fs.files", "fs.chunks")
RESERVED_TYPES = frozenset({"task", "parameter", *BLOB_COLLECTIONS})
#: [bytes] default largest blob: a 10 MB heightmap image fits with room to spare
DEFAULT_MAX_BLOB_BYTES = 64 * 1024 * 1024
#: [bytes] chunk size of the embedded store's blobs: GridFS's default (255 kB), so a dump reads like mongodump's
BLOB_CHUNK_BYTES = 255 * 1024
#: Fields of a blob's file document the store sets itself (GridFS's); ``put_blob`` keywords may not name them.
BLOB_FILE_FIELDS = ("_id", "filename", "length", "chunkSize", "uploadDate", "md5")
_MAX_TYPE_CHARS = 120  # MongoDB's namespace ("rostmsdb." + name) is limited to 255 bytes; leave room
_MAX_DEPTH = 100  # BSON nests at most 100 levels


def check_type(kind: Any) -> str:
    """A data collection name: a non-empty string that is not a reserved collection; ValidationError naming it."""
    if not isinstance(kind, str) or not kind:
        raise ValidationError(f"field 'type': must be a non-empty string (the collection name), got {kind!r}")
    if kind in RESERVED_TYPES:
        raise ValidationError(f"field 'type': {kind!r} is a reserved collection (not one for environment data: "
                              f"{', '.join(sorted(RESERVED_TYPES))})")
    if kind.startswith("system."):
        raise ValidationError(f"field 'type': {kind!r}: names starting with 'system.' are MongoDB's own")
    if "$" in kind or "\x00" in kind:
        raise ValidationError(f"field 'type': {kind!r}: a collection name may not contain '$' or NUL")
    if len(kind) > _MAX_TYPE_CHARS:
        raise ValidationError(f"field 'type': {len(kind)} characters, over the limit of {_MAX_TYPE_CHARS}")
    return kind


def _check_int(field: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValidationError(f"field {field!r}: must be an integer, got {value!r}")
    if not -(2**63) <= value < 2**63:
        raise ValidationError(f"field {field!r}: {value} is outside the 64-bit range BSON holds")
    return value


def _check_value(where: str, value: Any, depth: int = 0) -> None:
    """A value JSON / BSON keeps as it is; keys that are strings without a leading ``$`` (the embedded store keeps
    documents as Extended JSON, where ``{"$date": ...}`` would read back as a date), ``.`` or NUL."""
    if value is None or isinstance(value, bool | str | bytes | _dt.datetime):
        return
    if isinstance(value, int):
        _check_int(where, value)
        return
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValidationError(f"field {where!r}: non-finite number {value!r} (JSON has no NaN / inf)")
        return
    if depth >= _MAX_DEPTH:
        raise ValidationError(f"field {where!r}: nested deeper than {_MAX_DEPTH} levels")
    if isinstance(value, list | tuple):
        for i, item in enumerate(value):
            _check_value(f"{where}[{i}]", item, depth + 1)
        return
    if isinstance(value, Mapping):
        for key, item in value.items():
            _check_key(where, key)
            _check_value(f"{where}.{key}", item, depth + 1)
        return
    if type(value).__name__ in ("ObjectId", "Int64", "Decimal128", "Binary"):
        return
    raise ValidationError(f"field {where!r}: {type(value).__name__} {value!r:.80} is not a JSON / BSON value")


def _check_key(where: str, key: Any) -> None:
    if not isinstance(key, str) or not key:
        raise ValidationError(f"field {where!r}: key {key!r} must be a non-empty string")
    if key.startswith("$") or "." in key or "\x00" in key:
        raise ValidationError(f"field {where + '.' if where else ''}{key!r}: names may not start with '$' or "
                              "contain '.' or NUL")


def check_data_document(doc: Any, now: _dt.datetime) -> dict:
    """A copy of a ``Tmsdb``-shaped document fit to store, stamped with :data:`INSERTED_FIELD` = ``now``;
    ValidationError naming the field otherwise (nothing is stored then)."""
    if not isinstance(doc, Mapping):
        raise ValidationError(f"data document must be a mapping, got {type(doc).__name__}")
    check_type(doc.get("type"))
    for name in ("time", "name"):
        if name not in doc:
            raise ValidationError(f"field {name!r}: missing (a Tmsdb document has time, type, id, name, msg)")
        if not isinstance(doc[name], str):
            raise ValidationError(f"field {name!r}: must be a string, got {doc[name]!r}")
    if "id" not in doc:
        raise ValidationError("field 'id': missing (a Tmsdb document has time, type, id, name, msg)")
    _check_int("id", doc["id"])
    if "msg" not in doc:
        raise ValidationError("field 'msg': missing (the decoded JSON of the Tmsdb message's msg)")
    for own in (INSERTED_FIELD, "_id"):
        if own in doc:
            raise ValidationError(f"field {own!r}: set by the store on insert, not by the caller")
    for key, value in doc.items():
        _check_key("", key)
        _check_value(key, value)
    out = dict(doc)
    out[INSERTED_FIELD] = now
    check_document_size(out, f"{doc['type']} document (id {doc['id']}, time {doc['time']!r})")
    return out


def check_data_query(kind: Any, ident: Any, name: Any) -> None:
    check_type(kind)
    _check_int("id", ident)
    if not isinstance(name, str):
        raise ValidationError(f"field 'name': must be a string, got {name!r}")


def check_prune(kind: Any, max_age_s: Any, max_count: Any) -> None:
    check_type(kind)
    if max_age_s is None and max_count is None:
        raise ValidationError(f"prune_data {kind!r}: give max_age_s and / or max_count")
    if max_age_s is not None and (isinstance(max_age_s, bool) or not isinstance(max_age_s, int | float)
                                  or not max_age_s >= 0 or not math.isfinite(max_age_s)):
        raise ValidationError(f"prune_data {kind!r}: max_age_s must be a number >= 0, got {max_age_s!r}")
    if max_count is not None and (isinstance(max_count, bool) or not isinstance(max_count, int) or max_count < 0):
        raise ValidationError(f"prune_data {kind!r}: max_count must be an integer >= 0, got {max_count!r}")


def check_blob(data: Any, filename: Any, fields: Mapping[str, Any], limit: int) -> None:
    """Arguments of ``put_blob``: bytes within ``limit`` (BlobTooLarge naming filename, size, limit), a string
    (or None, as the original's dynamic terrain) filename, fields that are JSON / BSON values and not GridFS's own."""
    if filename is not None and not isinstance(filename, str):
        raise ValidationError(f"blob field 'filename': must be a string, got {filename!r}")
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ValidationError(f"blob {filename!r}: data must be bytes, got {type(data).__name__}")
    size = len(memoryview(data).cast("B"))
    if size > limit:
        raise BlobTooLarge(f"blob {filename!r}: {size:,} bytes, over the store's limit of {limit:,} "
                           "(max_blob_bytes); nothing stored", filename=filename, size=size, limit=limit)
    for key, value in fields.items():
        if key in BLOB_FILE_FIELDS:
            raise ValidationError(f"blob {filename!r}: field {key!r} is set by the store")
        _check_key("", key)
        _check_value(key, value)


def check_blob_filter(flt: Any) -> dict:
    """An equality filter on top-level fields of file documents (no operators)."""
    if flt is None:
        return {}
    if not isinstance(flt, Mapping):
        raise ValidationError(f"blob filter must be a mapping of field: value, got {type(flt).__name__}")
    for key, value in flt.items():
        if key == "_id":
            raise ValidationError("blob filter: field '_id': use get_blob(file_id)")
        _check_key("", key)
        _check_value(key, value)
    return dict(flt)


def _order(value: Any) -> tuple:
    """Sort key of a value in one field: missing / null first (as MongoDB), then numbers, then strings."""
    if value is None:
        return (0, 0)
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (1, value)
    if isinstance(value, str):
        return (2, value)
    return (3, repr(value))


def data_sort_key(doc: Mapping[str, Any], seq: int) -> tuple:
    """Ascending ``time`` (as the original's reader), then insertion order."""
    return (_order(doc.get("time")), seq)


def blob_sort_key(doc: Mapping[str, Any], seq: int) -> tuple:
    """Ascending ``time``, then ``uploadDate``, then insertion order."""
    return (_order(doc.get("time")), doc.get("uploadDate") or _dt.datetime.min.replace(tzinfo=_dt.UTC), seq)
