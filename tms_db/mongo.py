"""The MongoDB backend (pymongo): the original's database, for sites that run a MongoDB server or replica set.

Atomicity comes from MongoDB itself: ``find_one_and_update`` with ``$set`` / ``$inc`` / ``$push`` /
``$currentDate`` is atomic per document, and compare-and-set puts the expected value into the filter.
Validation of the *resulting* shape (e.g. a scalar into a waypoint record) reads the current document
first; that check is advisory under concurrent writers, the update itself is atomic.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import bson
import bson.errors

from tms_db.data import INSERTED_FIELD, RESERVED_TYPES
from tms_db.errors import RecordNotFound, StoreError, ValidationError
from tms_db.schema import is_number, is_waypoint_record, validate_fields, validate_parameter
from tms_db.store import (
    DATABASE,
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
    parameter_key,
    prevalidate_import,
)

#: MongoDB's code for "Transaction numbers are only allowed on a replica set member or mongos" (a standalone server)
_NO_TRANSACTIONS = 20
#: [s] how long a call waits for a server to answer before StoreError (serverSelectionTimeoutMS, connectTimeoutMS)
SERVER_TIMEOUT_S = 5.0
#: [s] the longest a server that is connected may take over one reply (socketTimeoutMS): a hung server, a big restore
SOCKET_TIMEOUT_S = 30.0
#: the unique index the store keeps on each collection's key (created on open)
_UNIQUE_INDEX = {"task": "task_by_id", "parameter": "parameter_by_key"}

__all__ = ["MongoStore", "SERVER_TIMEOUT_S", "SOCKET_TIMEOUT_S"]


def _redacted(uri: str) -> str:
    """``uri`` without its password (``mongodb://user:***@host``): messages and logs name the server, never it."""
    scheme, sep, rest = uri.partition("://")
    userinfo, at, hosts = rest.partition("@")
    if not at or ":" not in userinfo.split("/")[0]:
        return uri
    return f"{scheme}{sep}{userinfo.split(':', 1)[0]}:***@{hosts}"


def _reason(exc: Exception, timeout_s: float | None) -> str:
    """A pymongo error in one line: a server gone or not answering says so and after how long."""
    text = " ".join(str(exc).split())
    if len(text) > 300:
        text = text[:300] + " ..."
    from pymongo.errors import ConnectionFailure  # pymongo is loaded only with a MongoStore (see __init__)

    kind = type(exc).__name__
    if isinstance(exc, ConnectionFailure):  # gone, unreachable, or silent past socketTimeoutMS
        after = f" within {timeout_s:g} s" if timeout_s and kind == "ServerSelectionTimeoutError" else ""
        return f"the server did not answer{after} ({kind}: {text})"
    return f"{kind}: {text}"


def _call_text(name: str, args: tuple, kwargs: dict) -> str:
    """``get_task(5)``: what a failed call was doing, each argument shortened (imports carry whole documents)."""
    def short(value: Any) -> str:
        text = repr(value)
        return text if len(text) <= 60 else text[:57] + "..."
    return f"{name}({', '.join([*map(short, args), *(f'{k}={short(v)}' for k, v in kwargs.items())])})"


def _reporting_server_errors(cls: type) -> type:
    """Wrap every public method of ``cls`` so a pymongo error (server gone, refused command) leaves it as a
    :class:`StoreError` naming the server, the call and the cause, never as a raw pymongo traceback."""
    def guard(name: str, method: Any) -> Any:
        if inspect.isgeneratorfunction(method):
            @functools.wraps(method)
            def generator(self: MongoStore, *args: Any, **kwargs: Any) -> Any:
                try:
                    yield from method(self, *args, **kwargs)
                except self._errors.PyMongoError as exc:
                    raise self._server_error(_call_text(name, args, kwargs), exc) from None
            return generator

        @functools.wraps(method)
        def call(self: MongoStore, *args: Any, **kwargs: Any) -> Any:
            try:
                return method(self, *args, **kwargs)
            except self._errors.PyMongoError as exc:
                raise self._server_error(_call_text(name, args, kwargs), exc) from None
        return call

    for name in dir(cls):
        method = getattr(cls, name)
        if not name.startswith("_") and inspect.isfunction(method) and name not in ("close",):
            setattr(cls, name, guard(name, method))
    return cls


@_reporting_server_errors
class MongoStore(Store):
    """Store in MongoDB database ``database`` (default: the URI's database, else ``rostmsdb``)."""

    def __init__(self, uri: str, *, database: str | None = None, timeout_s: float = SERVER_TIMEOUT_S) -> None:
        # the client is loaded only for a mongodb:// URI: the embedded store needs just bson
        import pymongo
        from pymongo import uri_parser
        from pymongo.errors import PyMongoError

        self._pymongo = pymongo
        self._errors = pymongo.errors
        try:
            parsed = uri_parser.parse_uri(uri)
        except (PyMongoError, ValueError) as exc:
            raise StoreError(f"db uri {_redacted(uri)!r}: {exc}") from None
        self.database = database or parsed.get("database") or DATABASE
        self.uri = uri
        # bounded waits (the URI's own options win): a server that is gone is reported after timeout_s, not never
        given = {k.lower() for k in parsed.get("options", {})}
        bounds = {k: int(v * 1000) for k, v in (("serverSelectionTimeoutMS", timeout_s),
                                                 ("connectTimeoutMS", timeout_s),
                                                 ("socketTimeoutMS", SOCKET_TIMEOUT_S)) if k.lower() not in given}
        self.timeout_s = timeout_s
        try:
            self._client = pymongo.MongoClient(uri, tz_aware=True, **bounds)
            self.timeout_s = self._client.options.server_selection_timeout  # the URI's, when it gives one
            self._client.admin.command("ping")
        except PyMongoError as exc:
            raise StoreError(f"MongoDB {_redacted(uri)}: opening the store failed: {_reason(exc, self.timeout_s)}"
                             ) from None
        self._db = self._client[self.database]
        self._tasks = self._db["task"]
        self._params = self._db["parameter"]
        # Unique keys, as the embedded store's: without them two concurrent upserts of one task id or record both
        # insert, and a restore of a record already stored adds a second one. Partial: the original's older
        # records have no record_name (keyed by parameter_id), and any number of those may exist.
        for coll, keys, name, partial in (
            (self._tasks, [("task_id", 1)], "task_by_id", {"task_id": {"$type": "number"}}),
            (self._params, [("record_name", 1), ("model_name", 1)], "parameter_by_key",
             {"record_name": {"$type": "string"}}),
        ):
            try:
                coll.create_index(keys, name=name, unique=True, partialFilterExpression=partial)
            except PyMongoError:  # an existing database with duplicate keys or other indexes still works
                pass

    def __repr__(self) -> str:  # nodes log it: never the URI's password
        return f"MongoStore({_redacted(self.uri)!r}, database={self.database!r})"

    def _server_error(self, what: str, exc: Exception) -> StoreError:
        return StoreError(f"MongoDB {_redacted(self.uri)} (database {self.database!r}): {what} failed: "
                          f"{_reason(exc, self.timeout_s)}")

    # ---- tasks -----------------------------------------------------------------------------------
    def get_task(self, task_id: int) -> dict:
        check_task_id(task_id)
        doc = self._tasks.find_one({"task_id": task_id})
        if doc is None:
            raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")
        return doc

    def add_task(self, xml: str, task_id: int | None = None, description: str = "", model_name: str | None = None,
                 *, replace: bool = False, blackboard: dict | None = None) -> int:
        doc = build_task_doc(xml, task_id, description, model_name, blackboard)
        for _attempt in range(20):
            tid = task_id
            if tid is None:
                existing = {
                    d["task_id"]: d.get("task_sequence", "")
                    for d in self._tasks.find({}, {"task_id": 1, "task_sequence": 1})
                    if isinstance(d.get("task_id"), int)
                }
                tid = choose_task_id(existing, doc["task_sequence"])
            elif self._tasks.find_one({"task_id": tid}) is not None:
                if not replace:
                    raise StoreError(f"task_id {tid}: already exists (pass replace=True / --replace to overwrite)")
                self._tasks.replace_one({"task_id": tid}, {"task_id": tid, **doc})
                return tid
            # Claim the id atomically: insert only if no document has it (upsert with $setOnInsert).
            try:
                res = self._tasks.update_one({"task_id": tid}, {"$setOnInsert": {"task_id": tid, **doc}}, upsert=True)
            except self._errors.DuplicateKeyError:  # another writer claimed it after our read: choose again
                continue
            if res.upserted_id is not None:
                return tid
        raise StoreError("add_task: could not claim a free task_id after 20 attempts (concurrent writers?)")

    def list_tasks(self) -> list[dict]:
        return list(self._tasks.find({}).sort("task_id", 1))

    def remove_task(self, task_id: int) -> None:
        check_task_id(task_id)
        if self._tasks.delete_one({"task_id": task_id}).deleted_count == 0:
            raise RecordNotFound(f"task_id {task_id}: no such task in collection 'task'")

    # ---- parameters ------------------------------------------------------------------------------
    @staticmethod
    def _filter(record_name: str, model_name: str | None) -> dict:
        return {"record_name": record_name, "model_name": model_name} if model_name else {"record_name": record_name}

    def _not_found(self, record_name: str, model_name: str | None, fields: Iterable[str] = ()) -> RecordNotFound:
        fields = list(fields)
        text = param_filter_text(record_name, model_name) + " not found in collection 'parameter'"
        if fields:
            text += f" (setting field(s) {', '.join(map(repr, fields))})"
        if model_name:
            others = sorted(str(d.get("model_name", "")) for d in self._params.find({"record_name": record_name}))
            if others:
                text += f"; it exists for model(s) {others}"
        return RecordNotFound(text)

    def get_parameter(self, model_name: str | None, record_name: str) -> dict:
        check_record_name(record_name)
        doc = self._params.find_one(self._filter(record_name, model_name), sort=[("_id", 1)])
        if doc is None:
            raise self._not_found(record_name, model_name)
        return doc

    def get_record(self, record_name: str) -> dict:
        return self.get_parameter(None, record_name)

    def list_parameters(self, model_name: str | None = None) -> list[dict]:
        return list(self._params.find({"model_name": model_name} if model_name else {}).sort("_id", 1))

    def _current(self, record_name: str, model_name: str | None) -> dict | None:
        return self._params.find_one(self._filter(record_name, model_name), sort=[("_id", 1)])

    def set_fields(self, record_name: str, fields: Mapping[str, Any], *, model_name: str | None = None,
                   upsert: bool = False) -> dict:
        check_record_name(record_name)
        validate_fields(record_name, fields, protected=("_id", "record_name", "model_name"))
        for _attempt in range(3):
            current = self._current(record_name, model_name)
            if current is None and not upsert:
                raise self._not_found(record_name, model_name, fields)
            merged = dict(current or self._filter(record_name, model_name))
            merged.update(fields)
            merged["timestamps"] = now_utc()
            stamp = self._stamp(merged)
            validate_parameter(merged)
            try:
                doc = self._params.find_one_and_update(
                    {"_id": current["_id"]} if current else self._filter(record_name, model_name),
                    {"$set": dict(fields), **stamp},
                    upsert=current is None, return_document=self._pymongo.ReturnDocument.AFTER,
                )
            except self._errors.DuplicateKeyError:
                doc = None
            if doc is not None:
                return doc
            # Another writer created the record between the read and this upsert (the unique key refuses a second
            # one: MongoDB says DuplicateKeyError, SecantusDB answers no document) or removed it: read it again.
            if not upsert:
                raise self._not_found(record_name, model_name, fields)
        raise StoreError(f"{param_filter_text(record_name, model_name)}: set_fields gave up after 3 attempts "
                         "(concurrent writers creating and removing the record)")

    @staticmethod
    def _stamp(merged: dict) -> dict:
        """The update's ``timestamps`` part: ``$currentDate``, except in a waypoint record, which the original's
        array reader reads field by field as arrays (a Date there throws): no stamp, an old one removed."""
        if is_waypoint_record(merged):
            merged.pop("timestamps", None)
            return {"$unset": {"timestamps": ""}}
        return {"$currentDate": {"timestamps": True}}

    def append_fields(self, record_name: str, values: Mapping[str, Any], *, model_name: str | None = None) -> dict:
        check_record_name(record_name)
        validate_fields(record_name, values, protected=("_id", "record_name", "model_name"))
        current = self._current(record_name, model_name)
        if current is None:
            raise self._not_found(record_name, model_name)
        merged = appended(current, values, record_name, model_name)  # advisory: the $push below is the write
        stamp = self._stamp(merged)
        validate_parameter(merged)
        try:  # one atomic update: concurrent appenders each push onto the arrays as they are on the server
            doc = self._params.find_one_and_update(
                self._filter(record_name, model_name), {"$push": dict(values), **stamp},
                return_document=self._pymongo.ReturnDocument.AFTER, sort=[("_id", 1)],
            )
        except self._errors.OperationFailure as exc:
            # a field became a non-array after our read ("The field 'x' must be an array but is of type double"):
            # the same refusal as above, from the record as it is now
            if "must be an array" not in str(exc):
                raise
            now = self._current(record_name, model_name)
            if now is None:
                raise self._not_found(record_name, model_name) from None
            appended(now, values, record_name, model_name)
            raise ValidationError(f"{param_filter_text(record_name, model_name)}: cannot append to field(s) "
                                  f"{', '.join(map(repr, values))}: {_reason(exc, None)}") from None
        if doc is None:  # removed after our read
            raise self._not_found(record_name, model_name)
        return doc

    def compare_and_set(self, record_name: str, field: str, expected: Any, new: Any, *,
                        model_name: str | None = None) -> bool:
        check_record_name(record_name)
        validate_fields(record_name, {field: new}, protected=("_id", "record_name", "model_name"))
        current = self._current(record_name, model_name)
        if current is None:
            raise self._not_found(record_name, model_name, (field,))
        merged = {**current, field: new}
        stamp = self._stamp(merged)
        validate_parameter(merged)
        res = self._params.update_one(
            {"_id": current["_id"], field: {"$eq": expected}},
            {"$set": {field: new}, **stamp},
        )
        return res.modified_count == 1 or res.matched_count == 1

    def increment(self, record_name: str, field: str, by: int | float = 1, *, model_name: str | None = None) -> Any:
        check_record_name(record_name)
        validate_fields(record_name, {field: by}, protected=("_id", "record_name", "model_name"))
        if not is_number(by):
            raise ValidationError(f"record {record_name!r}: field {field!r}: increment {by!r} is not a number")
        try:
            doc = self._params.find_one_and_update(
                self._filter(record_name, model_name),
                {"$inc": {field: by}, "$currentDate": {"timestamps": True}},
                return_document=self._pymongo.ReturnDocument.AFTER, sort=[("_id", 1)],
            )
        except self._errors.OperationFailure as exc:
            raise ValidationError(f"record {record_name!r}: field {field!r}: cannot increment: {exc}") from None
        if doc is None:
            raise self._not_found(record_name, model_name, (field,))
        return doc[field]

    def _put_parameter(self, doc: dict, session: Any = None) -> None:
        key = {"record_name": doc["record_name"], "model_name": doc.get("model_name")}
        if doc.get("model_name") is None:
            key["model_name"] = {"$in": [None, ""]}
        current = self._params.find_one(key, session=session)
        if current is not None:
            doc.setdefault("_id", current["_id"])
            if doc["_id"] != current["_id"]:
                self._params.delete_one({"_id": current["_id"]}, session=session)
                self._params.insert_one(doc, session=session)
            else:
                self._params.replace_one({"_id": current["_id"]}, doc, session=session)
        else:
            self._params.insert_one(doc, session=session)

    def upsert_parameter(self, doc: Mapping[str, Any]) -> None:
        checked = self._checked_parameter(doc)
        try:
            self._put_parameter(dict(checked))
        except self._errors.DuplicateKeyError:  # another writer created the record after our read: replace it now
            self._put_parameter(dict(checked))

    def _in_transaction(self, write: Any) -> bool:
        """Run ``write(session)`` in a transaction; False (nothing written) when the server has none (standalone)."""
        try:
            with self._client.start_session() as session:
                session.with_transaction(write)
            return True
        except self._errors.OperationFailure as exc:
            if exc.code == _NO_TRANSACTIONS or "Transaction numbers are only allowed" in str(exc):
                return False
            raise

    def _put_parameters(self, checked: list[dict]) -> int:
        if self._in_transaction(lambda session: [self._put_parameter(dict(d), session) for d in checked]):
            return len(checked)
        # No transactions (a standalone server): validated above, so only the server can fail midway; say exactly where.
        for i, doc in enumerate(checked):
            try:
                self._put_parameter(doc)
            except self._errors.PyMongoError as exc:
                raise StoreError(f"document {i}: write failed: {exc}; documents 0..{i - 1} are stored, {i}.."
                                 f"{len(checked) - 1} are not (this MongoDB server has no transactions)") from None
        return len(checked)

    def remove_parameter(self, record_name: str, *, model_name: str | None = None) -> None:
        check_record_name(record_name)
        current = self._current(record_name, model_name)
        if current is None or self._params.delete_one({"_id": current["_id"]}).deleted_count == 0:
            raise self._not_found(record_name, model_name)

    # ---- environment data (the original's tms_db_writer / tms_db_reader) --------------------------
    def _insert_data(self, doc: dict) -> str:
        collection = self._db[doc["type"]]
        if doc["type"] not in self._time_indexed:  # the original's set_time_index, once per collection and process
            collection.create_index([("time", self._pymongo.DESCENDING)])
            self._time_indexed.add(doc["type"])
        return str(collection.insert_one(doc).inserted_id)

    @property
    def _time_indexed(self) -> set[str]:
        if not hasattr(self, "_time_indexed_set"):
            self._time_indexed_set: set[str] = set()
        return self._time_indexed_set

    def _find_data(self, kind: str, ident: int, name: str, latest_only: bool) -> list[dict]:
        flt: dict[str, Any] = {"id": ident, "name": name} if name else {"id": ident}
        order = -1 if latest_only else 1
        cursor = self._db[kind].find(flt).sort([("time", order), ("_id", order)])
        return list(cursor.limit(1) if latest_only else cursor)

    def _data_types(self) -> list[str]:
        return sorted(n for n in self._db.list_collection_names()
                      if n not in RESERVED_TYPES and not n.startswith("system.")
                      and self._db[n].estimated_document_count() > 0)

    def _prune_data(self, kind: str, cutoff: Any, max_count: int | None) -> int:
        collection = self._db[kind]
        removed = 0
        if cutoff is not None:
            removed += collection.delete_many({INSERTED_FIELD: {"$lt": cutoff}}).deleted_count
        if max_count is not None:
            old = [d["_id"] for d in collection.find({}, {"_id": 1}).sort([("time", -1), ("_id", -1)]).skip(max_count)]
            if old:
                removed += collection.delete_many({"_id": {"$in": old}}).deleted_count
        return removed

    # ---- blobs: pymongo's GridFS on this database -------------------------------------------------
    @property
    def _fs(self) -> Any:
        import gridfs

        if not hasattr(self, "_gridfs"):
            self._gridfs = gridfs.GridFS(self._db)
        return self._gridfs

    def _put_blob(self, data: bytes, filename: str | None, fields: dict) -> str:
        if filename is not None:
            fields = {"filename": filename, **fields}
        return str(self._fs.put(data, **fields))  # GridFS removes the chunks it wrote when a put fails

    def _find_blobs(self, flt: dict) -> list[dict]:
        files = self._db["fs.files"].find(flt).sort([("time", 1), ("uploadDate", 1), ("_id", 1)])
        return [{**{k: v for k, v in d.items() if k != "md5"}, "_id": str(d["_id"])} for d in files]

    def _get_blob(self, oid: Any, file_id: str) -> bytes:
        import gridfs.errors

        try:
            return self._fs.get(oid).read()
        except gridfs.errors.NoFile:
            raise RecordNotFound(f"blob {file_id!r}: no such blob") from None

    def _delete_blob(self, oid: Any, file_id: str) -> None:
        if self._db["fs.files"].find_one({"_id": oid}, {"_id": 1}) is None:
            raise RecordNotFound(f"blob {file_id!r}: no such blob")
        self._fs.delete(oid)

    # ---- collections -----------------------------------------------------------------------------
    def collection_names(self) -> list[str]:
        return sorted(n for n in self._db.list_collection_names() if self._db[n].estimated_document_count() > 0)

    def export_collection(self, name: str) -> Iterator[dict]:
        yield from self._db[name].find({}).sort("_id", 1)

    def import_collections(self, batches: Iterable[tuple[str, Iterable[Mapping[str, Any]]]], *,
                           drop: bool = False) -> list[ImportResult]:
        batches = [(name, [dict(d) if isinstance(d, Mapping) else d for d in docs]) for name, docs in batches]

        def storable(doc: Mapping[str, Any]) -> None:
            try:
                bson.encode(doc)  # one unencodable document would otherwise fail the whole batch
            except bson.errors.BSONError as exc:
                raise ValidationError(str(exc)) from None

        results = [ImportResult(rejected=prevalidate_import(name, docs, storable)) for name, docs in batches]
        if not any(r.rejected for r in results) and not drop:
            # every key already stored, as the embedded store reports them (the unique indexes stop at the first)
            for result, (name, docs) in zip(results, batches, strict=True):
                result.rejected += self._already_stored(name, docs)
        if any(r.rejected for r in results):
            return results
        failed: list[tuple[int, Exception]] = []

        def write(session: Any) -> None:
            if drop:
                for name in dict.fromkeys(n for n, _ in batches):
                    self._db[name].delete_many({}, session=session)
            for k, (name, docs) in enumerate(batches):
                if docs:
                    try:
                        self._db[name].insert_many(docs, ordered=True, session=session)
                    except self._errors.BulkWriteError as exc:
                        failed.append((k, exc))
                        raise

        try:
            if self._in_transaction(write):
                for result, (_name, docs) in zip(results, batches, strict=True):
                    result.loaded = len(docs)
                return results
        except self._errors.BulkWriteError:  # the transaction is aborted: nothing stored
            k, exc = failed[-1]
            for err in exc.details.get("writeErrors", []):
                doc = batches[k][1][err["index"]]
                results[k].rejected.append(
                    Rejected(err["index"], document_label(doc), err.get("errmsg", "write error"))
                )
            return results
        # A standalone server (no transactions): validated above, so only a key already stored or the server can
        # fail; ordered inserts stop at the first failure, and the result says exactly what is stored.
        failed.clear()
        stopped = False
        for k, (name, docs) in enumerate(batches):
            if stopped:
                results[k].not_written = list(range(len(docs)))
                continue
            if drop:
                self._db[name].delete_many({})
            try:
                if docs:
                    self._db[name].insert_many(docs, ordered=True)
                results[k].loaded = len(docs)
            except self._errors.BulkWriteError as exc:
                n = exc.details.get("nInserted", 0)
                errs = exc.details.get("writeErrors", [])
                index = errs[0]["index"] if errs else n
                results[k].loaded = n
                results[k].rejected.append(Rejected(index, document_label(docs[index]),
                                                    errs[0].get("errmsg", "write error") if errs else "write error"))
                results[k].not_written = list(range(index + 1, len(docs)))
                stopped = True
        return results

    def _already_stored(self, name: str, docs: list[Any]) -> list[Rejected]:
        """The documents of an import whose ``_id``, ``task_id`` or (model_name, record_name) collection ``name``
        already holds (a missing model_name counts as "", as in the embedded store)."""
        coll = self._db[name]

        def taken(field: str, values: list[Any], key: Any) -> set:
            found: set = set()
            for k in range(0, len(values), 5000):  # a query stays far below the 16 MiB BSON limit
                found |= {key(d) for d in coll.find({field: {"$in": values[k:k + 5000]}}, {field: 1, "model_name": 1})}
            return found

        ids = taken("_id", [d["_id"] for d in docs if "_id" in d], lambda d: str(d["_id"]))
        tids = taken("task_id", [d["task_id"] for d in docs if "task_id" in d], lambda d: d.get("task_id")) \
            if name == "task" else set()
        keys = taken("record_name", sorted({k[1] for d in docs if (k := parameter_key(d))}), parameter_key) \
            if name == "parameter" else set()
        rejected = []
        for i, doc in enumerate(docs):
            if "_id" in doc and str(doc["_id"]) in ids:
                what = f"_id {doc['_id']}"
            elif name == "task" and doc.get("task_id") in tids:
                what = f"task_id {doc['task_id']!r}"
            elif name == "parameter" and parameter_key(doc) in keys:
                model, record = parameter_key(doc)
                what = f"record {record!r} of model {model!r}"
            else:
                continue
            rejected.append(Rejected(i, document_label(doc), f"{what} already in the store"))
        return rejected

    def check(self) -> list[str]:
        problems = []
        for name in ("task", "parameter"):
            try:
                result = self._db.command("validate", name)
            except self._errors.OperationFailure as exc:
                if "ns does not exist" in str(exc) or "NamespaceNotFound" in str(exc):
                    continue
                problems.append(f"{name}: validate failed: {exc}")
                continue
            if not result.get("valid", False):
                problems.append(f"{name}: {result.get('errors')}")
            index = _UNIQUE_INDEX[name]
            if not any(i.get("name") == index and i.get("unique") for i in self._db[name].list_indexes()):
                problems.append(f"{name}: no unique index {index!r} (the store creates it on open; it fails when "
                                "two documents share a key): concurrent writers may create duplicates")
            for doc in self._db[name].find({}).sort("_id", 1):
                problems += check_document(name, doc)
        return problems

    def close(self) -> None:
        self._client.close()
