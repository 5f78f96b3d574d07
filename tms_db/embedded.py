"""The embedded backend: a small document store on SQLite, safe across processes.

Why not montydb: montydb was measured (sqlite storage) losing ``$inc`` updates across processes
(4 x 1,000 increments left the counter at 177). Here every document is one row holding its JSON body,
and every read-modify-write (set fields, append to arrays, compare-and-set, increment, add task) runs inside one
``BEGIN IMMEDIATE`` transaction, so writers in different processes serialise on SQLite's write lock and
no update is lost. Writers first take an ``flock`` on ``write.lock`` next to the database: the kernel
wakes the next writer as soon as the lock is free, where SQLite's own busy handler would sleep
(milliseconds) and poll. The database runs in WAL mode: readers never block writers or each other and
always see a whole committed document (a row is replaced atomically, so no torn document). With
``synchronous=NORMAL`` a committed transaction survives the writing process being killed (SIGKILL);
pass ``synchronous="FULL"`` to also survive power loss at some cost in write rate.

Values keep their types through JSON: bool, int (any size), float, str, null, arrays, sub-documents;
the BSON types JSON lacks are stored in their MongoDB Extended JSON form and read back as the same
Python values pymongo gives: datetimes as ``{"$date": "<ISO-8601 UTC>"}`` (timezone-aware UTC),
binary data as ``{"$binary": {"base64", "subType"}}`` (``bytes`` for subtype 0, as the original's
collision meshes, else ``bson.Binary``), ``Decimal128`` as ``{"$numberDecimal"}``; ``_id`` is a
``bson.ObjectId`` kept in its own column.
"""

from __future__ import annotations

import base64
import contextlib
import datetime as _dt
import errno
import fcntl
import json
import os
import sqlite3
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

from bson import Binary, Decimal128, ObjectId

from tms_db.data import BLOB_CHUNK_BYTES, BLOB_COLLECTIONS, INSERTED_FIELD, blob_sort_key
from tms_db.errors import RecordNotFound, StorageFullError, StorageReadOnlyError, StoreError, ValidationError
from tms_db.schema import is_number, is_waypoint_record, validate_fields, validate_parameter
from tms_db.store import (
    _MISSING,
    ImportResult,
    Rejected,
    Store,
    appended,
    build_task_doc,
    check_document,
    check_record_name,
    check_task_id,
    choose_task_id,
    document_label,
    now_utc,
    param_filter_text,
    prevalidate_import,
    values_equal,
)

__all__ = ["EmbeddedStore", "DB_FILE", "encode_body", "decode_body"]

DB_FILE = "rostmsdb.sqlite3"
#: [pages] a writer whose checkpoints run in the background still checkpoints itself past this WAL size (40 MB)
BACKSTOP_CHECKPOINT_PAGES = 10_000
LOCK_FILE = "write.lock"
SCHEMA_VERSION = "1"
T = TypeVar("T")
_INT64_MAX = 2**63 - 1


class _RefusedError(Exception):
    """Raised inside an import's transaction to roll it back once every document has been tried."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS documents (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    collection TEXT NOT NULL,
    oid TEXT NOT NULL,
    task_id INTEGER,
    model_name TEXT,
    record_name TEXT,
    body TEXT NOT NULL,
    UNIQUE (collection, oid)
);
CREATE UNIQUE INDEX IF NOT EXISTS task_by_id ON documents (task_id) WHERE collection = 'task';
CREATE UNIQUE INDEX IF NOT EXISTS parameter_by_key ON documents (record_name, model_name)
    WHERE collection = 'parameter';
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE INDEX IF NOT EXISTS data_by_id_time ON documents
    (collection, json_extract(body, '$.id'), json_extract(body, '$.time') DESC)
    WHERE collection NOT IN ('task', 'parameter');
CREATE TABLE IF NOT EXISTS blob_files (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    oid TEXT NOT NULL UNIQUE,
    body TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS blob_chunks (
    oid TEXT NOT NULL UNIQUE,
    file_oid TEXT NOT NULL,
    n INTEGER NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (file_oid, n)
);
"""
#: The condition every query on data collections repeats word for word, so SQLite can use the partial index.
_DATA = "collection NOT IN ('task', 'parameter')"


def _default(value: Any) -> Any:
    if isinstance(value, _dt.datetime):
        if value.tzinfo is None:
            value = value.replace(tzinfo=_dt.UTC)
        value = value.astimezone(_dt.UTC)
        return {"$date": value.strftime("%Y-%m-%dT%H:%M:%S.") + f"{value.microsecond // 1000:03d}Z"}
    if isinstance(value, ObjectId):
        return {"$oid": str(value)}
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, bytes | bytearray):  # bson.Binary is a bytes subclass that carries its subtype
        subtype = value.subtype if isinstance(value, Binary) else 0
        return {"$binary": {"base64": base64.b64encode(value).decode("ascii"), "subType": f"{subtype:02x}"}}
    if isinstance(value, Decimal128):
        return {"$numberDecimal": str(value)}
    raise TypeError(f"unsupported value type {type(value).__name__}")


def _binary(spec: Any) -> Any:
    data = base64.b64decode(spec["base64"])
    subtype = int(spec["subType"], 16)
    return data if subtype == 0 else Binary(data, subtype)  # pymongo also gives bytes for subtype 0


def _hook(obj: dict) -> Any:
    if len(obj) == 1:
        if "$date" in obj and isinstance(obj["$date"], str):
            return _dt.datetime.strptime(obj["$date"], "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=_dt.UTC)
        if "$oid" in obj and isinstance(obj["$oid"], str):
            return ObjectId(obj["$oid"])
        if "$binary" in obj and isinstance(obj["$binary"], dict):
            return _binary(obj["$binary"])
        if "$numberDecimal" in obj and isinstance(obj["$numberDecimal"], str):
            return Decimal128(obj["$numberDecimal"])
    return obj


def encode_body(doc: Mapping[str, Any]) -> str:
    """JSON text of a document without ``_id`` (types preserved; see module docstring)."""
    return json.dumps({k: v for k, v in doc.items() if k != "_id"}, default=_default, allow_nan=False,
                      separators=(",", ":"), ensure_ascii=False)


def decode_body(oid: str, body: str) -> dict:
    """The document stored as ``body`` with its ``_id``."""
    doc = {"_id": ObjectId(oid)}
    doc.update(json.loads(body, object_hook=_hook))
    return doc


def _key_columns(collection: str, doc: Mapping[str, Any]) -> tuple[Any, Any, Any]:
    """(task_id, model_name, record_name) index columns of a document."""
    if collection == "task":
        tid = doc.get("task_id")
        return (tid if isinstance(tid, int) and not isinstance(tid, bool) else None), None, None
    if collection == "parameter":
        record = doc.get("record_name")
        model = doc.get("model_name")
        return None, (model if isinstance(model, str) else ""), (record if isinstance(record, str) else None)
    return None, None, None


class EmbeddedStore(Store):
    """Document store in ``<directory>/rostmsdb.sqlite3``; one connection per process, shared by its threads."""

    def __init__(
        self, directory: str | os.PathLike, *, synchronous: str = "NORMAL", busy_timeout_s: float = 60.0
    ) -> None:
        self.directory = Path(directory)
        if synchronous.upper() not in ("NORMAL", "FULL"):
            raise StoreError(f"synchronous {synchronous!r}: expected NORMAL or FULL")
        self._synchronous = synchronous.upper()
        self._busy_timeout_s = busy_timeout_s
        self.file = self.directory / DB_FILE
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise self._storage_error(exc, f"cannot create directory {self.directory}") from None
        self.file = self.directory / DB_FILE
        self._lock = threading.RLock()
        self._conn: sqlite3.Connection | None = None
        self._lock_fd: int | None = None
        self._pid = -1
        self._checkpointer: threading.Thread | None = None
        self._checkpoint_stop = threading.Event()
        self._connect()

    def __repr__(self) -> str:
        return f"EmbeddedStore({str(self.directory)!r})"

    # ---- connection ------------------------------------------------------------------------------
    def _read_only(self) -> bool:
        """True when the store's directory (or its file system, or its database file) cannot be written; checked by
        the kernel, so a read-only mount or an immutable directory counts for root too."""
        try:
            if os.statvfs(self.directory).f_flag & os.ST_RDONLY:
                return True
            return not os.access(self.directory, os.W_OK) or (self.file.exists() and not os.access(self.file, os.W_OK))
        except OSError:
            return False

    def _no_space(self) -> bool:
        """True when the store's file system has no block left (SQLite reports some writes that meet a full disk,
        growing its -shm file, as a plain I/O error)."""
        try:
            return os.statvfs(self.directory).f_bavail == 0
        except OSError:
            return False

    def _storage_error(self, exc: BaseException, doing: str = "") -> StoreError:
        """One error naming the cause: disk full, read-only storage, else the backend's message."""
        text = str(exc) if not isinstance(exc, OSError) or exc.errno is None else (exc.strerror or str(exc))
        where = f"embedded store {self.file}" + (f": {doing}" if doing else "")
        code = getattr(exc, "sqlite_errorcode", None)
        if (
            (isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT))
            or code == sqlite3.SQLITE_FULL
            or "database or disk is full" in text
            or (isinstance(exc, sqlite3.OperationalError) and self._no_space())
        ):
            return StorageFullError(f"{where}: disk full (ENOSPC): {text}; nothing of this write was stored")
        if (isinstance(exc, OSError) and exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM)) \
                or code == sqlite3.SQLITE_READONLY or "readonly database" in text \
                or (isinstance(exc, sqlite3.Error) and self._read_only()):
            return StorageReadOnlyError(f"database directory {self.directory} is read-only ({text})")
        return StoreError(f"{where}: {text}")

    def _connect(self) -> sqlite3.Connection:
        if self._conn is not None and self._pid == os.getpid():
            return self._conn
        conn = None
        try:
            self._lock_fd = os.open(self.directory / LOCK_FILE, os.O_CREAT | os.O_RDWR, 0o666)
            conn = sqlite3.connect(
                self.file, timeout=self._busy_timeout_s, isolation_level=None, check_same_thread=False
            )
            # a new database's switch to WAL needs a lock SQLite's busy handler does not wait for: two processes
            # opening one new store at once (a launch's writer and reader) failed one of them "database is locked";
            # the store's cross-process lock puts them in turn (the second finds WAL already set)
            with self._write_lock():
                conn.execute("PRAGMA journal_mode=WAL")
            conn.execute(f"PRAGMA synchronous={self._synchronous}")
            self._conn = conn
            self._pid = os.getpid()
            self._transaction(lambda c: c.executescript(_SCHEMA) and None, script=True)
            self._transaction(lambda c: c.execute(
                "INSERT OR IGNORE INTO meta (key, value) VALUES ('schema_version', ?)", (SCHEMA_VERSION,)))
        except (sqlite3.Error, OSError, StoreError) as exc:
            self._conn = None
            if conn is not None:
                conn.close()
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None
            if isinstance(exc, StoreError):
                raise
            raise self._storage_error(exc, "cannot open") from None
        return conn

    @contextlib.contextmanager
    def _write_lock(self) -> Iterator[None]:
        assert self._lock_fd is not None
        fcntl.flock(self._lock_fd, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(self._lock_fd, fcntl.LOCK_UN)

    def _transaction(self, body: Callable[[sqlite3.Connection], T], *, script: bool = False) -> T:
        """Run ``body`` in one BEGIN IMMEDIATE transaction under the cross-process write lock.

        A failure rolls the whole transaction back; SQLite's own errors become one StoreError naming the cause
        (disk full: SQLite has then already rolled back itself, and a second ROLLBACK would replace the cause with
        "no transaction is active")."""
        with self._lock:
            conn = self._connect()
            with self._write_lock():
                try:
                    if script:  # executescript commits on its own
                        return body(conn)
                    conn.execute("BEGIN IMMEDIATE")
                    result = body(conn)
                    conn.execute("COMMIT")
                    return result
                except BaseException as exc:
                    if conn.in_transaction:
                        with contextlib.suppress(sqlite3.Error):  # the cause is the exception on its way out
                            conn.execute("ROLLBACK")
                    if isinstance(exc, sqlite3.Error):
                        raise self._storage_error(exc) from None
                    raise

    def _query(self, sql: str, args: tuple = ()) -> list[tuple]:
        with self._lock:
            try:
                return self._connect().execute(sql, args).fetchall()
            except sqlite3.Error as exc:
                raise self._storage_error(exc) from None

    # ---- tasks -----------------------------------------------------------------------------------
    def get_task(self, task_id: int) -> dict:
        check_task_id(task_id)
        if task_id > _INT64_MAX:  # no such row can exist (SQLite's integers are 64-bit)
            raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")
        rows = self._query("SELECT oid, body FROM documents WHERE collection='task' AND task_id=?", (task_id,))
        if not rows:
            raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")
        return decode_body(*rows[0])

    def add_task(self, xml: str, task_id: int | None = None, description: str = "", model_name: str | None = None,
                 *, replace: bool = False, blackboard: dict | None = None) -> int:
        doc = build_task_doc(xml, task_id, description, model_name, blackboard)

        def insert(conn: sqlite3.Connection) -> int:
            tid = task_id
            if tid is None:
                existing = {}
                for body, tid_ in conn.execute("SELECT body, task_id FROM documents WHERE collection='task'"):
                    existing[tid_] = json.loads(body).get("task_sequence", "")
                tid = choose_task_id(existing, doc["task_sequence"])
            else:
                row = conn.execute("SELECT oid FROM documents WHERE collection='task' AND task_id=?", (tid,)).fetchone()
                if row is not None:
                    if not replace:
                        raise StoreError(f"task_id {tid}: already exists (pass replace=True / --replace to overwrite)")
                    conn.execute("DELETE FROM documents WHERE collection='task' AND task_id=?", (tid,))
            full = {"task_id": tid, **doc}
            conn.execute("INSERT INTO documents (collection, oid, task_id, body) VALUES ('task', ?, ?, ?)",
                         (str(ObjectId()), tid, encode_body(full)))
            return tid

        return self._transaction(insert)

    def list_tasks(self) -> list[dict]:
        rows = self._query("SELECT oid, body FROM documents WHERE collection='task' ORDER BY task_id")
        return [decode_body(*row) for row in rows]

    def remove_task(self, task_id: int) -> None:
        check_task_id(task_id)
        if task_id > _INT64_MAX:
            raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")

        def delete(conn: sqlite3.Connection) -> None:
            cur = conn.execute("DELETE FROM documents WHERE collection='task' AND task_id=?", (task_id,))
            if cur.rowcount == 0:
                raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")

        self._transaction(delete)

    # ---- parameters ------------------------------------------------------------------------------
    @staticmethod
    def _select_param(model_name: str | None) -> tuple[str, Callable[[str], tuple]]:
        if model_name:
            return ("SELECT seq, oid, body FROM documents WHERE collection='parameter' AND record_name=? "
                    "AND model_name=?", lambda r: (r, model_name))
        return ("SELECT seq, oid, body FROM documents WHERE collection='parameter' AND record_name=? "
                "ORDER BY seq LIMIT 1", lambda r: (r,))

    def _not_found(self, record_name: str, model_name: str | None, fields: Iterable[str] = ()) -> RecordNotFound:
        fields = list(fields)
        text = param_filter_text(record_name, model_name) + " not found in collection 'parameter'"
        if fields:
            text += f" (setting field(s) {', '.join(map(repr, fields))})"
        if model_name:
            others = self._query("SELECT model_name FROM documents WHERE collection='parameter' AND record_name=?",
                                 (record_name,))
            if others:
                text += f"; it exists for model(s) {sorted(o[0] for o in others)}"
        return RecordNotFound(text)

    def get_parameter(self, model_name: str | None, record_name: str) -> dict:
        check_record_name(record_name)
        sql, args = self._select_param(model_name)
        rows = self._query(sql, args(record_name))
        if not rows:
            raise self._not_found(record_name, model_name)
        return decode_body(*rows[0][1:])

    def get_record(self, record_name: str) -> dict:
        return self.get_parameter(None, record_name)

    def list_parameters(self, model_name: str | None = None) -> list[dict]:
        if model_name:
            rows = self._query("SELECT oid, body FROM documents WHERE collection='parameter' AND model_name=? "
                               "ORDER BY seq", (model_name,))
        else:
            rows = self._query("SELECT oid, body FROM documents WHERE collection='parameter' ORDER BY seq")
        return [decode_body(*row) for row in rows]

    def _modify(self, record_name: str, model_name: str | None, change: Callable[[dict], T], *,
                upsert: bool = False, fields: Iterable[str] = ()) -> tuple[T, dict]:
        """Read-modify-write one parameter document in one transaction; ``change`` edits it in place."""
        check_record_name(record_name)
        sql, args = self._select_param(model_name)

        def run(conn: sqlite3.Connection) -> tuple[T, dict]:
            row = conn.execute(sql, args(record_name)).fetchone()
            if row is None:
                if not upsert:
                    raise self._not_found(record_name, model_name, fields)
                seq, doc = None, {"_id": ObjectId(), "record_name": record_name}
                if model_name:
                    doc["model_name"] = model_name
            else:
                seq, doc = row[0], decode_body(row[1], row[2])
            result = change(doc)
            if result is False:  # compare-and-set miss: nothing to write
                return result, doc
            if is_waypoint_record(doc):  # the original's array reader would throw on a Date: no stamp there
                doc.pop("timestamps", None)
            else:
                doc["timestamps"] = now_utc()
            validate_parameter(doc)
            _tid, model, record = _key_columns("parameter", doc)
            if seq is None:
                conn.execute("INSERT INTO documents (collection, oid, model_name, record_name, body) "
                             "VALUES ('parameter', ?, ?, ?, ?)", (str(doc["_id"]), model, record, encode_body(doc)))
            else:
                conn.execute("UPDATE documents SET body=? WHERE seq=?", (encode_body(doc), seq))
            return result, doc

        return self._transaction(run)

    def set_fields(self, record_name: str, fields: Mapping[str, Any], *, model_name: str | None = None,
                   upsert: bool = False) -> dict:
        validate_fields(record_name, fields, protected=("_id", "record_name", "model_name"))
        return self._modify(record_name, model_name, lambda doc: doc.update(fields), upsert=upsert, fields=fields)[1]

    def append_fields(self, record_name: str, values: Mapping[str, Any], *, model_name: str | None = None) -> dict:
        validate_fields(record_name, values, protected=("_id", "record_name", "model_name"))
        # read, append and write in one BEGIN IMMEDIATE transaction under the write lock (_modify): appenders in
        # other processes wait for it, and each appends to the arrays the previous one committed
        return self._modify(record_name, model_name,
                            lambda doc: doc.update(appended(doc, values, record_name, model_name)))[1]

    def compare_and_set(self, record_name: str, field: str, expected: Any, new: Any, *,
                        model_name: str | None = None) -> bool:
        validate_fields(record_name, {field: new}, protected=("_id", "record_name", "model_name"))

        def change(doc: dict) -> bool:
            if not values_equal(doc.get(field, _MISSING), expected):
                return False
            doc[field] = new
            return True

        return self._modify(record_name, model_name, change, fields=(field,))[0]

    def increment(self, record_name: str, field: str, by: int | float = 1, *, model_name: str | None = None) -> Any:
        validate_fields(record_name, {field: by}, protected=("_id", "record_name", "model_name"))
        if not is_number(by):
            raise ValidationError(f"record {record_name!r}: field {field!r}: increment {by!r} is not a number")

        def change(doc: dict) -> Any:
            current = doc.get(field, 0)
            if not is_number(current):
                raise ValidationError(
                    f"record {record_name!r}: field {field!r}: cannot increment non-number {current!r}"
                )
            doc[field] = current + by
            return doc[field]

        return self._modify(record_name, model_name, change, fields=(field,))[0]

    def _checked_parameter(self, doc: Mapping[str, Any]) -> dict:
        doc = super()._checked_parameter(doc)
        if doc.get("_id") is not None and not isinstance(doc["_id"], ObjectId):  # stored, no read could decode it
            raise ValidationError(f"record {doc['record_name']!r}: field '_id' {doc['_id']!r} is not an ObjectId "
                                  "(the embedded store keys documents by ObjectId; leave it out to get one)")
        return doc

    @staticmethod
    def _put_parameter(conn: sqlite3.Connection, doc: dict) -> None:
        _tid, model, record = _key_columns("parameter", doc)
        row = conn.execute("SELECT seq, oid FROM documents WHERE collection='parameter' AND record_name=? "
                           "AND model_name=?", (record, model)).fetchone()
        try:
            if row is not None:
                doc.setdefault("_id", ObjectId(row[1]))
                conn.execute(
                    "UPDATE documents SET oid=?, body=? WHERE seq=?", (str(doc["_id"]), encode_body(doc), row[0])
                )
            else:
                oid = str(doc.get("_id") or ObjectId())
                conn.execute("INSERT INTO documents (collection, oid, model_name, record_name, body) "
                             "VALUES ('parameter', ?, ?, ?, ?)", (oid, model, record, encode_body(doc)))
        except sqlite3.IntegrityError:
            raise ValidationError(f"{param_filter_text(record, model)}: _id {doc.get('_id')} is already another "
                                  "document's") from None

    def upsert_parameter(self, doc: Mapping[str, Any]) -> None:
        doc = self._checked_parameter(doc)
        self._transaction(lambda conn: self._put_parameter(conn, doc))

    def _put_parameters(self, checked: list[dict]) -> int:
        def put(conn: sqlite3.Connection) -> int:
            for doc in checked:
                self._put_parameter(conn, doc)
            return len(checked)

        return self._transaction(put)

    def remove_parameter(self, record_name: str, *, model_name: str | None = None) -> None:
        check_record_name(record_name)

        def delete(conn: sqlite3.Connection) -> None:
            if model_name:
                cur = conn.execute(
                    "DELETE FROM documents WHERE collection='parameter' AND record_name=? AND model_name=?",
                    (record_name, model_name),
                )
            else:
                cur = conn.execute("DELETE FROM documents WHERE seq = (SELECT seq FROM documents WHERE "
                                   "collection='parameter' AND record_name=? ORDER BY seq LIMIT 1)", (record_name,))
            if cur.rowcount == 0:
                raise self._not_found(record_name, model_name)

        self._transaction(delete)

    # ---- environment data ------------------------------------------------------------------------
    # Data collections are rows of ``documents`` like task and parameter; the partial expression index
    # ``data_by_id_time`` on (collection, id, time) serves the original reader's query.
    def _insert_data(self, doc: dict) -> str:
        oid = str(ObjectId())
        body = encode_body(doc)
        self._transaction(lambda conn: conn.execute(
            "INSERT INTO documents (collection, oid, body) VALUES (?, ?, ?)", (doc["type"], oid, body)))
        return oid

    def _find_data(self, kind: str, ident: int, name: str, latest_only: bool) -> list[dict]:
        if ident > _INT64_MAX or ident < -_INT64_MAX - 1:
            return []
        sql = (f"SELECT oid, body FROM documents WHERE collection=? AND {_DATA} AND json_extract(body, '$.id')=? "
               "AND json_type(body, '$.id') IN ('integer', 'real')")
        args: tuple = (kind, ident)
        if name:
            sql += " AND json_extract(body, '$.name')=? AND json_type(body, '$.name')='text'"
            args += (name,)
        if latest_only:
            sql += " ORDER BY json_extract(body, '$.time') DESC, seq DESC LIMIT 1"
        else:
            sql += " ORDER BY json_extract(body, '$.time'), seq"
        return [decode_body(*row) for row in self._query(sql, args)]

    def _data_types(self) -> list[str]:
        return [r[0] for r in self._query(f"SELECT DISTINCT collection FROM documents WHERE {_DATA} "
                                          "ORDER BY collection")]

    def _prune_data(self, kind: str, cutoff: _dt.datetime | None, max_count: int | None) -> int:
        def prune(conn: sqlite3.Connection) -> int:
            removed = 0
            if cutoff is not None:  # the stamp is {"$date": ISO text}, which orders as the time it names
                stamp = _default(cutoff)["$date"]
                removed += conn.execute(
                    f"DELETE FROM documents WHERE collection=? AND {_DATA} AND "
                    f"json_extract(body, '$.{INSERTED_FIELD}.\"$date\"') < ?", (kind, stamp)).rowcount
            if max_count is not None:
                removed += conn.execute(
                    f"DELETE FROM documents WHERE seq IN (SELECT seq FROM documents WHERE collection=? AND {_DATA} "
                    "ORDER BY json_extract(body, '$.time') DESC, seq DESC LIMIT -1 OFFSET ?)", (kind, max_count)
                ).rowcount
            return removed

        return self._transaction(prune)

    # ---- blobs -----------------------------------------------------------------------------------
    # GridFS's layout in two tables: ``blob_files`` (the file document) and ``blob_chunks`` (255 kB pieces), both
    # written in one transaction, so a crash mid-put leaves no half file.
    @staticmethod
    def _write_chunk(conn: sqlite3.Connection, file_oid: str, n: int, data: bytes) -> None:
        conn.execute("INSERT INTO blob_chunks (oid, file_oid, n, data) VALUES (?, ?, ?, ?)",
                     (str(ObjectId()), file_oid, n, data))

    def _put_blob(self, data: bytes, filename: str | None, fields: dict) -> str:
        oid = str(ObjectId())
        doc: dict[str, Any] = {"chunkSize": BLOB_CHUNK_BYTES, "length": len(data), "uploadDate": now_utc()}
        if filename is not None:
            doc["filename"] = filename
        doc.update(fields)
        body = encode_body(doc)

        def put(conn: sqlite3.Connection) -> None:
            conn.execute("INSERT INTO blob_files (oid, body) VALUES (?, ?)", (oid, body))
            for n, start in enumerate(range(0, len(data), BLOB_CHUNK_BYTES)):
                self._write_chunk(conn, oid, n, data[start:start + BLOB_CHUNK_BYTES])

        self._transaction(put)
        return oid

    def _find_blobs(self, flt: dict) -> list[dict]:
        found = []
        for seq, oid, body in self._query("SELECT seq, oid, body FROM blob_files"):
            doc = decode_body(oid, body)
            if all(values_equal(doc.get(k, _MISSING), v) for k, v in flt.items()):
                found.append((blob_sort_key(doc, seq), doc))
        found.sort(key=lambda item: item[0])
        return [{**doc, "_id": str(doc["_id"])} for _key, doc in found]

    def _get_blob(self, oid: Any, file_id: str) -> bytes:
        def read(conn: sqlite3.Connection) -> bytes:  # one transaction: the file and its chunks from one snapshot
            row = conn.execute("SELECT body FROM blob_files WHERE oid=?", (str(oid),)).fetchone()
            if row is None:
                raise RecordNotFound(f"blob {file_id!r}: no such blob")
            length = json.loads(row[0]).get("length")
            chunks = conn.execute("SELECT n, data FROM blob_chunks WHERE file_oid=? ORDER BY n", (str(oid),)).fetchall()
            if [n for n, _ in chunks] != list(range(len(chunks))):
                raise StoreError(f"blob {file_id!r}: chunks missing (have {[n for n, _ in chunks]})")
            data = b"".join(d for _, d in chunks)
            if length != len(data):
                raise StoreError(f"blob {file_id!r}: {len(data)} bytes in its chunks, its file document says {length}")
            return data

        with self._lock:
            conn = self._connect()
            try:
                conn.execute("BEGIN")
                try:
                    return read(conn)
                finally:
                    conn.execute("COMMIT")
            except sqlite3.Error as exc:
                raise self._storage_error(exc) from None

    def _delete_blob(self, oid: Any, file_id: str) -> None:
        def delete(conn: sqlite3.Connection) -> None:
            if conn.execute("DELETE FROM blob_files WHERE oid=?", (str(oid),)).rowcount == 0:
                raise RecordNotFound(f"blob {file_id!r}: no such blob")
            conn.execute("DELETE FROM blob_chunks WHERE file_oid=?", (str(oid),))

        self._transaction(delete)

    # ---- collections -----------------------------------------------------------------------------
    def collection_names(self) -> list[str]:
        names = [r[0] for r in self._query("SELECT DISTINCT collection FROM documents ORDER BY collection")]
        if self._query("SELECT 1 FROM blob_files LIMIT 1"):  # blobs dump as GridFS's two collections, as mongodump
            names += [n for n in BLOB_COLLECTIONS if self._query(
                f"SELECT 1 FROM {'blob_files' if n == 'fs.files' else 'blob_chunks'} LIMIT 1")]
        return sorted(names)

    def export_collection(self, name: str) -> Iterator[dict]:
        if name == "fs.files":
            for oid, body in self._query("SELECT oid, body FROM blob_files ORDER BY seq"):
                yield decode_body(oid, body)
            return
        if name == "fs.chunks":
            for oid, file_oid, n, data in self._query(
                    "SELECT oid, file_oid, n, data FROM blob_chunks ORDER BY file_oid, n"):
                yield {"_id": ObjectId(oid), "files_id": ObjectId(file_oid), "n": n, "data": bytes(data)}
            return
        for row in self._query("SELECT oid, body FROM documents WHERE collection=? ORDER BY seq", (name,)):
            yield decode_body(*row)

    def import_collections(self, batches: Iterable[tuple[str, Iterable[Mapping[str, Any]]]], *,
                           drop: bool = False) -> list[ImportResult]:
        batches = [(name, list(docs)) for name, docs in batches]
        for name, _docs in batches:
            if not isinstance(name, str) or not name or name.startswith("$"):
                raise ValidationError(f"collection name {name!r}: must be a non-empty string")

        def storable(doc: Mapping[str, Any]) -> None:
            oid = doc.get("_id")
            if oid is not None and not isinstance(oid, ObjectId):
                raise ValidationError(f"_id {oid!r} is not an ObjectId (the embedded store keys documents by ObjectId)")
            encode_body(doc)  # TypeError / ValueError: a value JSON cannot keep (a set, NaN)

        def storable_chunk(doc: Mapping[str, Any]) -> None:
            storable(doc)
            if not isinstance(doc.get("files_id"), ObjectId):
                raise ValidationError(f"field 'files_id' {doc.get('files_id')!r} is not an ObjectId")
            if isinstance(doc.get("n"), bool) or not isinstance(doc.get("n"), int) or doc["n"] < 0:
                raise ValidationError(f"field 'n' {doc.get('n')!r} is not a chunk number")
            if not isinstance(doc.get("data"), bytes):
                raise ValidationError(f"field 'data' is not binary data ({type(doc.get('data')).__name__})")

        results = [ImportResult(rejected=prevalidate_import(name, docs, storable_chunk if name == "fs.chunks"
                                                            else storable)) for name, docs in batches]
        if any(r.rejected for r in results):
            return results

        def put(conn: sqlite3.Connection) -> list[ImportResult]:
            if drop:
                for name in dict.fromkeys(n for n, _ in batches):
                    if name in BLOB_COLLECTIONS:  # GridFS's collections are the blob tables
                        conn.execute(f"DELETE FROM {'blob_files' if name == 'fs.files' else 'blob_chunks'}")
                    else:
                        conn.execute("DELETE FROM documents WHERE collection=?", (name,))
            for (name, docs), result in zip(batches, results, strict=True):
                for i, doc in enumerate(docs):
                    tid, model, record = _key_columns(name, doc)
                    try:
                        if name == "fs.files":
                            conn.execute("INSERT INTO blob_files (oid, body) VALUES (?, ?)",
                                         (str(doc.get("_id") or ObjectId()), encode_body(doc)))
                        elif name == "fs.chunks":
                            conn.execute("INSERT INTO blob_chunks (oid, file_oid, n, data) VALUES (?, ?, ?, ?)",
                                         (str(doc.get("_id") or ObjectId()), str(doc["files_id"]), doc["n"],
                                          doc["data"]))
                        else:
                            conn.execute(
                                "INSERT INTO documents (collection, oid, task_id, model_name, record_name, body) "
                                "VALUES (?, ?, ?, ?, ?, ?)",
                                (name, str(doc.get("_id") or ObjectId()), tid, model, record, encode_body(doc)))
                    except sqlite3.IntegrityError:
                        key = (f"task_id {tid}" if name == "task" else f"record {record!r} of model {model!r}"
                               if name == "parameter" else "chunk (files_id, n)" if name == "fs.chunks" else "key")
                        result.rejected.append(Rejected(i, document_label(doc), f"_id or {key} already in the store "
                                                                                "or in another input"))
                    else:
                        result.loaded += 1
            if any(r.rejected for r in results):
                raise _RefusedError  # every document was tried, so each refusal is reported; now undo them all
            return results

        try:
            return self._transaction(put)
        except _RefusedError:
            for result in results:
                result.loaded = 0
            return results

    def check(self) -> list[str]:
        problems: list[str] = []
        try:
            rows = self._query("PRAGMA integrity_check")
        except StoreError as exc:
            return [str(exc)]
        problems += [f"sqlite integrity: {r[0]}" for r in rows if r[0] != "ok"]
        for seq, collection, oid, tid, model, record, body in self._query(
            "SELECT seq, collection, oid, task_id, model_name, record_name, body FROM documents ORDER BY seq"
        ):
            try:
                doc = decode_body(oid, body)
            except (ValueError, TypeError) as exc:
                problems.append(f"{collection} row {seq} (_id {oid}): body is not a JSON document: {exc}")
                continue
            if not isinstance(doc, dict):
                problems.append(f"{collection} row {seq} (_id {oid}): body is not an object")
                continue
            if _key_columns(collection, doc) != (tid, model, record):
                problems.append(f"{collection} row {seq} (_id {oid}): index columns do not match the document")
            problems += check_document(collection, doc)
        problems += self._check_blobs()
        return problems

    def _check_blobs(self) -> list[str]:
        """Every blob's chunks are numbered 0.. without gaps and add up to its length; no chunk without its file."""
        problems = []
        chunks: dict[str, list[tuple[int, int]]] = {}
        for file_oid, n, size in self._query("SELECT file_oid, n, length(data) FROM blob_chunks ORDER BY file_oid, n"):
            chunks.setdefault(file_oid, []).append((n, size))
        for oid, body in self._query("SELECT oid, body FROM blob_files ORDER BY seq"):
            have = chunks.pop(oid, [])
            length = json.loads(body).get("length")
            if [n for n, _ in have] != list(range(len(have))) or sum(size for _, size in have) != length:
                problems.append(f"fs.files (_id {oid}): length {length!r}, chunks {[n for n, _ in have]} holding "
                                f"{sum(size for _, size in have)} bytes")
        problems += [f"fs.chunks: {len(have)} chunk(s) of file {oid}, which does not exist"
                     for oid, have in chunks.items()]
        return problems

    def checkpoint_in_background(self, period_s: float) -> None:
        """SQLite's automatic checkpoint runs inside the commit that fills the WAL past 1000 pages: about one
        flag write in 1000 took 4-7 ms (the checkpoint's fsync) where the median took 0.3 ms, and one took 15 ms
        inside the task manager's 50 Hz tick, which then ran late. Here this connection checkpoints itself only
        past :data:`BACKSTOP_CHECKPOINT_PAGES`, and a thread of this store checkpoints (PASSIVE: it never waits
        for or blocks a writer) every ``period_s`` on a connection of its own; other processes' connections keep
        SQLite's default. The WAL restarts from its beginning once a checkpoint has caught up with it between
        two writes; writes back to back that never leave it a gap meet the backstop."""
        if not period_s > 0:
            raise StoreError(f"embedded store {self.file}: checkpoint period must be > 0 s, got {period_s}")
        if self._checkpointer is not None:
            return
        with self._lock:
            # not 0: should the thread never catch up (writes back to back), the writer still bounds the WAL
            self._connect().execute(f"PRAGMA wal_autocheckpoint={BACKSTOP_CHECKPOINT_PAGES}")

        def run() -> None:
            conn = sqlite3.connect(self.file, timeout=self._busy_timeout_s, check_same_thread=False)
            try:
                while not self._checkpoint_stop.wait(period_s):
                    try:
                        conn.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
                    except sqlite3.DatabaseError as exc:  # a busy database: the next period tries again
                        import logging

                        logging.getLogger(__name__).warning(f"embedded store {self.file}: checkpoint failed: {exc}")
            finally:
                conn.close()

        self._checkpoint_stop.clear()  # a store closed before may start its thread again
        self._checkpointer = threading.Thread(target=run, name="tms_db_checkpoint", daemon=True)
        self._checkpointer.start()

    def close(self) -> None:
        if self._checkpointer is not None:
            self._checkpoint_stop.set()
            self._checkpointer.join(timeout=5.0)
            self._checkpointer = None
        with self._lock:
            if self._conn is not None and self._pid == os.getpid():
                self._conn.close()
                if self._lock_fd is not None:
                    os.close(self._lock_fd)
            self._conn = None
            self._lock_fd = None
