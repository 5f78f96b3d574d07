"""The store API every module uses: :class:`Store`, which both backends implement and which behave the same (one
test suite runs against both); :func:`tms_db.backend.open_store` picks the backend by URI.

Collections and shapes are the original's (database ``rostmsdb``): ``task`` documents
``{task_id, type: "task", model_name, description, task_sequence}``; ``parameter`` documents
``{model_name?, type?, record_name, ...payload}`` looked up by (model_name, record_name), and global
blackboard groups in ``parameter`` looked up by ``record_name`` alone. Every write through
``set_fields`` / ``append_fields`` / ``compare_and_set`` / ``increment`` stamps ``timestamps`` (UTC datetime,
millisecond precision, as MongoDB's ``$currentDate``). Values keep their types: bool stays bool, int stays int.
"""

from __future__ import annotations

import abc
import datetime as _dt
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bson import ObjectId
from bson.errors import InvalidId

from tms_db.data import (
    DEFAULT_MAX_BLOB_BYTES,
    check_blob,
    check_blob_filter,
    check_data_document,
    check_data_query,
    check_prune,
)
from tms_db.errors import RecordNotFound, StoreError, ValidationError
from tms_db.schema import (
    check_document_size,
    detect_model_names,
    is_number,
    normalise_task_xml,
    validate_parameter,
)

__all__ = [
    "Store", "default_path", "now_utc", "values_equal", "DATABASE", "COLLECTIONS",
    "ImportResult", "Rejected", "check_import_document", "document_label", "prevalidate_import", "import_key",
    "parameter_key", "check_document", "parse_file_id", "appended",
]

DATABASE = "rostmsdb"
COLLECTIONS = ("task", "parameter")
_MISSING = object()


def default_path() -> Path:
    """Directory of the embedded store: ``$TMS_DB_PATH`` else ``~/.local/share/tms/db``."""
    env = os.environ.get("TMS_DB_PATH")
    return Path(env).expanduser() if env else Path.home() / ".local" / "share" / "tms" / "db"


def now_utc() -> _dt.datetime:
    """Current UTC time truncated to milliseconds (the precision of a BSON Date)."""
    now = _dt.datetime.now(_dt.UTC)
    return now.replace(microsecond=now.microsecond // 1000 * 1000)


def values_equal(current: Any, expected: Any) -> bool:
    """Equality as a MongoDB filter sees it: bool never equals a number, 1 equals 1.0, None matches missing."""
    if current is _MISSING:
        current = None
    if isinstance(current, bool) or isinstance(expected, bool):
        return type(current) is type(expected) and current == expected
    if is_number(current) and is_number(expected):
        return current == expected
    if isinstance(current, list | tuple) and isinstance(expected, list | tuple):
        return len(current) == len(expected) and all(values_equal(a, b) for a, b in zip(current, expected, strict=True))
    if isinstance(current, Mapping) and isinstance(expected, Mapping):
        return list(current) == list(expected) and all(values_equal(current[k], expected[k]) for k in current)
    return type(current) is type(expected) and current == expected


def appended(doc: Mapping[str, Any], values: Mapping[str, Any], record_name: str, model_name: str | None) -> dict:
    """A copy of ``doc`` with each ``values[k]`` appended to its array ``k`` (missing: a new array), what
    :meth:`Store.append_fields` writes; ValidationError naming the record and the first field (in ``values``' order)
    that holds something else."""
    merged = dict(doc)
    for key, value in values.items():
        old = merged.get(key, [])
        if not isinstance(old, list):
            raise ValidationError(f"{param_filter_text(record_name, model_name)}: field {key!r}: holds {old!r}, "
                                  "not an array to append to")
        merged[key] = [*old, value]
    return merged


def check_task_id(task_id: Any) -> int:
    """A task id is a positive int (not a bool); anything else -> ValidationError naming it."""
    if isinstance(task_id, bool) or not isinstance(task_id, int) or task_id <= 0:
        raise ValidationError(f"task_id {task_id!r}: must be a positive integer")
    return task_id


def check_record_name(record_name: Any) -> str:
    if not isinstance(record_name, str) or not record_name:
        raise ValidationError(f"record_name {record_name!r}: must be a non-empty string")
    return record_name


@dataclass(frozen=True)
class Rejected:
    """One document an import refused: its position in the input, its label (``_id``), and why."""

    index: int
    label: str
    reason: str
    #: a duplicate: the position of the first document with the same key in the same input
    first: int | None = None

    def __str__(self) -> str:
        same = f" (the same as document {self.first})" if self.first is not None else ""
        return f"document {self.index} ({self.label}): {self.reason}{same}"


@dataclass
class ImportResult:
    """What :meth:`Store.import_documents` did: documents stored, and each refused one by its id.

    An import is all or nothing: with any document refused, ``loaded`` is 0 and nothing of the input is stored.
    Only a MongoDB server without transactions can fail midway through writing a validated input: then
    ``loaded`` documents (positions ``0 .. loaded-1``) are stored, ``rejected`` names the one that failed and
    ``not_written`` the positions after it.
    """

    loaded: int = 0
    rejected: list[Rejected] = field(default_factory=list)
    not_written: list[int] = field(default_factory=list)


def document_label(doc: Any) -> str:
    """How a report names a document: its ``_id``, else its key fields."""
    if not isinstance(doc, Mapping):
        return f"a {type(doc).__name__}, not a document"
    if "_id" in doc:
        return f"_id {doc['_id']}"
    keys = [f"{k} {doc[k]!r}" for k in ("task_id", "model_name", "record_name") if k in doc]
    return ", ".join(keys) or "no _id"


def check_import_document(collection: str, doc: Any) -> None:
    """The minimum a document needs to be found again and used: ValidationError naming the field otherwise.

    Imports store documents as they are (like ``mongoimport``): shapes are checked on the next write,
    not here, so the original's records load unchanged (parameter documents without ``record_name``
    included: its older ones are keyed by ``parameter_id``). A task needs its integer ``task_id`` and its
    XML text, which must parse and hold a ``<BehaviorTree>``, or no look-up finds it and no start can run it.
    No document over :data:`tms_db.schema.MAX_DOCUMENT_BYTES`.
    """
    if not isinstance(doc, Mapping):
        raise ValidationError(f"not a document ({type(doc).__name__})")
    if collection == "task":
        tid = doc.get("task_id")
        if isinstance(tid, bool) or not isinstance(tid, int) or tid <= 0:
            raise ValidationError(f"field 'task_id' must be a positive integer, got {tid!r}")
        if not isinstance(doc.get("task_sequence"), str):
            raise ValidationError(
                f"field 'task_sequence' must be a string, got {type(doc.get('task_sequence')).__name__}"
            )
        normalise_task_xml(doc["task_sequence"], f"task_id {tid}")
    check_document_size(doc, "document")


def parameter_key(doc: Mapping[str, Any]) -> tuple[str, str] | None:
    """(model_name, record_name) a parameter document is found by (a missing model_name is ""), None without a
    record_name (the original's older documents, keyed by ``parameter_id``)."""
    record = doc.get("record_name")
    if not isinstance(record, str):
        return None
    model = doc.get("model_name")
    return (model if isinstance(model, str) else "", record)


def import_key(collection: str, doc: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """The unique keys of a document in the input of an import: its ``_id``, a task's ``task_id``, a parameter's
    (model_name, record_name); as (text naming it, value)."""
    keys: list[tuple[str, Any]] = []
    if "_id" in doc:
        keys.append((f"_id {doc['_id']}", ("_id", str(doc["_id"]))))
    if collection == "task" and "task_id" in doc:
        keys.append((f"task_id {doc['task_id']!r}", ("task_id", repr(doc["task_id"]))))
    elif collection == "parameter":
        key = parameter_key(doc)
        if key is not None:
            keys.append((f"record {key[1]!r} of model {key[0]!r}", key))
    return keys


def prevalidate_import(collection: str, docs: list[Any], check: Any = None) -> list[Rejected]:
    """Every document of one import input that would be refused: :func:`check_import_document` (and ``check``, a
    backend's own test raising ``ValidationError`` / ``TypeError`` / ``ValueError``), and duplicates inside the
    input, each naming the first document with that key."""
    rejected: list[Rejected] = []
    seen: dict[Any, int] = {}
    for i, doc in enumerate(docs):
        label = document_label(doc)
        try:
            check_import_document(collection, doc)
            if check is not None:
                check(doc)
        except (TypeError, ValueError, OverflowError) as exc:
            rejected.append(Rejected(i, label, str(exc)))
            continue
        for text, key in import_key(collection, doc):
            if key in seen:
                rejected.append(Rejected(i, label, f"duplicate {text}", first=seen[key]))
                break
        else:
            for _text, key in import_key(collection, doc):
                seen[key] = i
    return rejected


def check_document(collection: str, doc: Mapping[str, Any]) -> list[str]:
    """What ``check`` finds wrong with one stored document: a task whose id or XML is unusable; a record whose
    ``type`` is not text, a ``static`` / ``dynamic`` record (the ones the stack reads by name) without its
    ``record_name`` (``model_name`` is optional: the global blackboard's records have none), a record whose payload
    breaks its family's shape
    (:func:`tms_db.schema.validate_parameter`)."""
    label = document_label(doc)
    try:
        if collection == "task":
            check_import_document("task", doc)
        elif collection == "parameter":
            kind = doc.get("type")
            if kind is not None and not isinstance(kind, str):
                return [f"parameter ({label}): field 'type' must be a string, got {kind!r}"]
            if kind in ("static", "dynamic") and (
                not isinstance(doc.get("record_name"), str) or not doc["record_name"]
            ):
                return [f"parameter ({label}): a {kind} record needs a non-empty 'record_name', got "
                        f"{doc.get('record_name')!r}"]
            if "record_name" in doc or kind in ("static", "dynamic"):
                validate_parameter(doc)
    except (ValidationError, TypeError, ValueError) as exc:
        return [f"{collection} ({label}): {exc}"]
    return []


def parse_file_id(file_id: Any) -> Any:
    """The ObjectId a blob's id text names; RecordNotFound naming it when it cannot name one."""
    if isinstance(file_id, ObjectId):
        return file_id
    try:
        return ObjectId(file_id)
    except (InvalidId, TypeError):
        raise RecordNotFound(f"blob {file_id!r}: no such blob (not a file id)") from None


class Store(abc.ABC):
    """Tasks, parameters and the global blackboard; one implementation per backend.

    Reads return plain dicts (``_id`` is a ``bson.ObjectId``). Writes are atomic per document;
    concurrent writers in separate processes never lose updates.
    """

    database: str = DATABASE
    #: [bytes] the largest blob ``put_blob`` stores (an ``open_store`` option)
    max_blob_bytes: int = DEFAULT_MAX_BLOB_BYTES

    # ---- tasks ------------------------------------------------------------------------------------
    @abc.abstractmethod
    def get_task(self, task_id: int) -> dict:
        """The task document with ``task_id``; RecordNotFound naming the id when absent."""

    @abc.abstractmethod
    def add_task(
        self, xml: str, task_id: int | None = None, description: str = "", model_name: str | None = None,
        *, replace: bool = False, blackboard: dict | None = None,
    ) -> int:
        """Store a behavior tree; returns its task id.

        The XML must parse (ValidationError naming the task and ``task_sequence`` otherwise) and is
        stored as one line, as the original ``task_generator`` does. Without ``task_id`` the new id is
        the smallest free positive id, and a tree already stored (same one-line text, or contained in
        a stored one) is refused naming the existing id. With ``task_id`` taken, StoreError unless
        ``replace``. ``model_name`` defaults to the machine names found in the XML, comma-joined.
        ``blackboard``: the task's parameters, initial blackboard entries (name -> bool/number/text) set before
        its tree is loaded (``{machine: ic120_1}``; tms_ts.loader), stored in the field ``blackboard`` beside the
        original's fields.
        """

    @abc.abstractmethod
    def list_tasks(self) -> list[dict]:
        """Every task document, by task id."""

    @abc.abstractmethod
    def remove_task(self, task_id: int) -> None:
        """Delete a task; RecordNotFound when absent."""

    # ---- parameters / blackboard ------------------------------------------------------------------
    @abc.abstractmethod
    def get_parameter(self, model_name: str | None, record_name: str) -> dict:
        """The record (model_name, record_name); an empty/None model_name looks up by record_name only."""

    @abc.abstractmethod
    def get_record(self, record_name: str) -> dict:
        """The first record named ``record_name`` (global blackboard lookup, as ``find_one({record_name})``)."""

    @abc.abstractmethod
    def list_parameters(self, model_name: str | None = None) -> list[dict]:
        """Every parameter document (of one model when given), in insertion order."""

    @abc.abstractmethod
    def set_fields(
        self, record_name: str, fields: Mapping[str, Any], *, model_name: str | None = None, upsert: bool = False
    ) -> dict:
        """Atomically set ``fields`` of one record and stamp ``timestamps``; returns the new document.

        Unknown record (and not ``upsert``): RecordNotFound naming record and fields. A result that
        breaks the record's shape (e.g. a scalar into a waypoint record): ValidationError naming the
        field; nothing is written then.
        """

    @abc.abstractmethod
    def append_fields(self, record_name: str, values: Mapping[str, Any], *, model_name: str | None = None) -> dict:
        """Atomically append ``values[k]`` to the array in field ``k`` of one record, for every ``k`` at once (as
        MongoDB's ``$push``; a missing field becomes a one-element array), stamp as ``set_fields``; returns the new
        document. One atomic update per record: appenders in other processes never lose each other's values.

        Unknown record: RecordNotFound naming it (as ``get_parameter``). A field holding anything but an array:
        ValidationError ``record ...: field 'x': holds 1.5, not an array to append to``; a result that breaks the
        record's shape: ValidationError naming the field; nothing is written then.
        """

    @abc.abstractmethod
    def compare_and_set(
        self, record_name: str, field: str, expected: Any, new: Any, *, model_name: str | None = None
    ) -> bool:
        """Set ``field`` to ``new`` only if it currently equals ``expected`` (type-aware); True if set."""

    @abc.abstractmethod
    def increment(self, record_name: str, field: str, by: int | float = 1, *, model_name: str | None = None) -> Any:
        """Atomically add ``by`` to a numeric field (missing counts as 0, as ``$inc``); returns the new value."""

    @abc.abstractmethod
    def upsert_parameter(self, doc: Mapping[str, Any]) -> None:
        """Validate and store a whole parameter document, replacing the one with the same (model_name, record_name)."""

    @abc.abstractmethod
    def remove_parameter(self, record_name: str, *, model_name: str | None = None) -> None:
        """Delete one record; RecordNotFound when absent."""

    # ---- whole collections (dump / restore) ---------------------------------------------------------
    @abc.abstractmethod
    def collection_names(self) -> list[str]:
        """Names of the collections that hold documents."""

    @abc.abstractmethod
    def export_collection(self, name: str) -> Iterator[dict]:
        """Every document of a collection, unchanged (with ``_id``)."""

    def import_documents(self, name: str, docs: Iterable[Mapping[str, Any]], *, drop: bool = False) -> ImportResult:
        """Insert documents as they are (like ``mongoimport``); ``drop`` empties the collection first.

        All or nothing: every document is checked first (:func:`prevalidate_import`: a task without its id or with
        XML that does not parse, a value the backend cannot store, a document over the size limit, two with the
        same key); with any refused, each is reported by position and ``_id`` and nothing is stored. Then all are
        written in one transaction (a key already in the store refuses the whole input too).
        """
        return self.import_collections([(name, docs)], drop=drop)[0]

    @abc.abstractmethod
    def import_collections(self, batches: Iterable[tuple[str, Iterable[Mapping[str, Any]]]], *,
                           drop: bool = False) -> list[ImportResult]:
        """:meth:`import_documents` for several inputs (collection name, documents) at once, all or nothing
        together; one result per input, in order."""

    def upsert_parameters(self, docs: Iterable[Mapping[str, Any]]) -> int:
        """:meth:`upsert_parameter` for many documents, all or nothing: every one is validated first (the first
        refusal raises ValidationError naming its position: ``document N: ...``), then all are written in one
        transaction (:meth:`_put_parameters`). Returns the number written."""
        checked = []
        for i, doc in enumerate(docs):
            try:
                checked.append(self._checked_parameter(doc))
            except ValidationError as exc:
                raise ValidationError(f"document {i}: {exc}") from None
        return self._put_parameters(checked)

    def _checked_parameter(self, doc: Mapping[str, Any]) -> dict:
        """A copy of parameter document ``doc`` fit to store (shape of its family, size); a backend adds its own
        checks. ValidationError naming the record otherwise."""
        validate_parameter(doc)
        check_document_size(doc, f"record {doc['record_name']!r}")
        return dict(doc)

    @abc.abstractmethod
    def _put_parameters(self, checked: list[dict]) -> int:
        """Write documents :meth:`_checked_parameter` returned, all in one transaction; the number written."""

    # ---- environment data (the original's Tmsdb collections) -----------------------------------------
    def insert_data(self, doc: Mapping[str, Any]) -> str:
        """Store a ``Tmsdb``-shaped document ``{time, type, id, name, msg, ...}`` in the collection named by its
        ``type``, as the original's ``tms_db_writer`` (``msg`` already decoded from JSON), with a descending index on
        ``time``; the store adds :data:`tms_db.data.INSERTED_FIELD` (UTC datetime) for :meth:`prune_data`. Refused
        with ValidationError naming the field (:func:`tms_db.data.check_data_document`). Returns the new ``_id``."""
        return self._insert_data(check_data_document(doc, now_utc()))

    def find_data(self, type: str, id: int, *, name: str = "", latest_only: bool = False) -> list[dict]:
        """As the original's ``tms_db_reader``: documents of collection ``type`` with ``{"id": id}`` (and
        ``{"name": name}`` when ``name`` is not empty), ascending by ``time`` (then insertion order);
        ``latest_only``: ``[the newest]`` or ``[]``. An unknown collection gives ``[]``."""
        check_data_query(type, id, name)
        return self._find_data(type, id, name, latest_only)

    def data_types(self) -> list[str]:
        """The data collections that hold documents (not ``task``, ``parameter``, GridFS's), sorted."""
        return self._data_types()

    def prune_data(self, type: str, *, max_age_s: float | None = None, max_count: int | None = None) -> int:
        """Retention: remove documents of collection ``type`` stored more than ``max_age_s`` ago (by the store's
        insertion stamp; documents without one, e.g. restored from the original's dumps, are kept) and those
        beyond the newest ``max_count`` by ``time``; in one transaction (embedded). Returns how many were
        removed."""
        check_prune(type, max_age_s, max_count)
        cutoff = None if max_age_s is None else now_utc() - _dt.timedelta(seconds=max_age_s)
        return self._prune_data(type, cutoff, max_count)

    # ---- binary objects (GridFS) --------------------------------------------------------------------
    def put_blob(self, data: bytes, *, filename: str | None, **fields: Any) -> str:
        """Store ``data`` as ``gridfs.GridFS.put(data, filename=..., **fields)``: ``fields`` (the original: time,
        type, id) become top-level fields of the file document. Over :attr:`max_blob_bytes`:
        :class:`tms_db.errors.BlobTooLarge` naming filename, size and limit, nothing stored. All or nothing.
        Returns the file id as text."""
        check_blob(data, filename, fields, self.max_blob_bytes)
        return self._put_blob(bytes(data), filename, dict(fields))

    def find_blobs(self, filter: Mapping[str, Any] | None = None, *, latest_only: bool = False) -> list[dict]:
        """File documents (no data): ``_id`` (text), ``filename``, ``length``, ``chunkSize``, ``uploadDate`` and the
        fields given to :meth:`put_blob`, matching ``filter`` (equality on top-level fields), ascending by ``time``
        then ``uploadDate``; ``latest_only``: ``[the newest]`` or ``[]``."""
        found = self._find_blobs(check_blob_filter(filter))
        return found[-1:] if latest_only else found

    def get_blob(self, file_id: str) -> bytes:
        """The bytes of blob ``file_id``; RecordNotFound naming the id."""
        return self._get_blob(parse_file_id(file_id), file_id)

    def delete_blob(self, file_id: str) -> None:
        """Delete blob ``file_id`` (file document and chunks together); RecordNotFound naming the id."""
        self._delete_blob(parse_file_id(file_id), file_id)

    @abc.abstractmethod
    def _insert_data(self, doc: dict) -> str:
        """Insert a checked data document; its ``_id`` as text."""

    @abc.abstractmethod
    def _find_data(self, kind: str, ident: int, name: str, latest_only: bool) -> list[dict]:
        """:meth:`find_data` after its checks."""

    @abc.abstractmethod
    def _data_types(self) -> list[str]:
        """:meth:`data_types`."""

    @abc.abstractmethod
    def _prune_data(self, kind: str, cutoff: _dt.datetime | None, max_count: int | None) -> int:
        """Delete documents stamped before ``cutoff`` and those past the newest ``max_count``; how many."""

    @abc.abstractmethod
    def _put_blob(self, data: bytes, filename: str | None, fields: dict) -> str:
        """Store checked blob arguments, all or nothing; the file id as text."""

    @abc.abstractmethod
    def _find_blobs(self, flt: dict) -> list[dict]:
        """Every file document matching ``flt``, in :meth:`find_blobs`' order."""

    @abc.abstractmethod
    def _get_blob(self, oid: Any, file_id: str) -> bytes:
        """Bytes of blob ``oid``; RecordNotFound naming ``file_id``."""

    @abc.abstractmethod
    def _delete_blob(self, oid: Any, file_id: str) -> None:
        """Delete blob ``oid``; RecordNotFound naming ``file_id``."""

    @abc.abstractmethod
    def check(self) -> list[str]:
        """The store's own consistency check: a list of problems, empty when consistent."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release connections and files."""

    def checkpoint_in_background(self, period_s: float) -> None:  # noqa: B027 - a no-op unless the backend needs it
        """Keep a writer's commits short: a backend that sometimes does maintenance work inside a commit moves it to
        a background thread run every ``period_s`` [s] (the embedded store: SQLite's WAL checkpoint). For a caller
        with a deadline per write, the task manager's tick. Nothing to do for MongoDB."""

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def build_task_doc(xml: str, task_id: int | None, description: str, model_name: str | None,
                   blackboard: dict | None = None) -> dict:
    """The task document for ``add_task`` (without ``task_id`` when it is still to be chosen)."""
    label = f"task_id {task_id}" if task_id is not None else "new task"
    if task_id is not None:
        check_task_id(task_id)
    if not isinstance(description, str):
        raise ValidationError(f"{label}: field 'description' must be a string, got {description!r}")
    sequence = normalise_task_xml(xml, label)
    if model_name is not None and not isinstance(model_name, str):
        raise ValidationError(f"{label}: field 'model_name' must be a string, got {model_name!r}")
    doc = {"task_id": task_id, "type": "task", "model_name": model_name, "description": description,
           "task_sequence": sequence}
    if blackboard is not None:
        if not isinstance(blackboard, dict):
            raise ValidationError(f"{label}: field 'blackboard' must be a mapping of name: value, got {blackboard!r}")
        for key, value in blackboard.items():
            if not isinstance(key, str) or not key or key.startswith("$") or "." in key:
                raise ValidationError(f"{label}: field 'blackboard': key {key!r} must be a name (no '$', '.')")
            if not isinstance(value, bool | int | float | str):
                raise ValidationError(
                    f"{label}: field 'blackboard': key {key!r} = {value!r} must be a bool, number or text"
                )
        doc["blackboard"] = dict(blackboard)
    if model_name is None:  # the machines its leaves name (model_name="{machine}": the task's parameter)
        doc["model_name"] = detect_model_names(sequence, blackboard)
    if task_id is None:
        del doc["task_id"]
    return doc


def choose_task_id(existing: Mapping[int, str], sequence: str) -> int:
    """Smallest free positive id (the original generator's rule); refuse a tree already stored."""
    for tid, stored in existing.items():
        if sequence in stored:
            raise StoreError(
                f"task already stored as task_id {tid} (same behavior tree); remove it or pass an explicit id"
            )
    tid = 1
    while tid in existing:
        tid += 1
    return tid


def param_filter_text(record_name: str, model_name: str | None) -> str:
    return f"record {record_name!r}" + (f" of model {model_name!r}" if model_name else "")
