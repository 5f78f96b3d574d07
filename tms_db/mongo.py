"""The MongoDB backend (pymongo): the original's database, for sites that run a MongoDB server or replica set.

Atomicity comes from MongoDB itself: ``find_one_and_update`` with ``$set`` / ``$inc`` /
``$currentDate`` is atomic per document, and compare-and-set puts the expected value into the filter.
Validation of the *resulting* shape (e.g. a scalar into a waypoint record) reads the current document
first; that check is advisory under concurrent writers, the update itself is atomic.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import bson
import bson.errors

from tms_db.errors import RecordNotFound, StoreError, ValidationError
from tms_db.schema import is_number, validate_fields, validate_parameter
from tms_db.store import (
    DATABASE,
    ImportResult,
    Rejected,
    Store,
    build_task_doc,
    check_import_document,
    check_record_name,
    check_task_id,
    choose_task_id,
    document_label,
    now_utc,
    param_filter_text,
)

__all__ = ["MongoStore"]


class MongoStore(Store):
    """Store in MongoDB database ``database`` (default: the URI's database, else ``rostmsdb``)."""

    def __init__(self, uri: str, *, database: str | None = None, timeout_s: float = 5.0) -> None:
        import pymongo
        from pymongo import uri_parser
        from pymongo.errors import PyMongoError

        self._pymongo = pymongo
        self._errors = pymongo.errors
        try:
            parsed = uri_parser.parse_uri(uri)
        except (PyMongoError, ValueError) as exc:
            raise StoreError(f"db uri {uri!r}: {exc}") from None
        self.database = database or parsed.get("database") or DATABASE
        self.uri = uri
        try:
            self._client = pymongo.MongoClient(uri, tz_aware=True, serverSelectionTimeoutMS=int(timeout_s * 1000))
            self._client.admin.command("ping")
        except PyMongoError as exc:
            raise StoreError(f"MongoDB at {uri!r} unreachable: {exc}") from None
        self._db = self._client[self.database]
        self._tasks = self._db["task"]
        self._params = self._db["parameter"]
        for coll, keys, name in ((self._tasks, [("task_id", 1)], "task_by_id"),
                                 (self._params, [("record_name", 1), ("model_name", 1)], "parameter_by_key")):
            try:
                coll.create_index(keys, name=name)
            except PyMongoError:  # an existing database with other indexes still works
                pass

    def __repr__(self) -> str:
        return f"MongoStore({self.uri!r}, database={self.database!r})"

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
                existing = {d["task_id"]: d.get("task_sequence", "") for d in self._tasks.find({}, {"task_id": 1, "task_sequence": 1})
                            if isinstance(d.get("task_id"), int)}
                tid = choose_task_id(existing, doc["task_sequence"])
            elif self._tasks.find_one({"task_id": tid}) is not None:
                if not replace:
                    raise StoreError(f"task_id {tid}: already exists (pass replace=True / --replace to overwrite)")
                self._tasks.replace_one({"task_id": tid}, {"task_id": tid, **doc})
                return tid
            # Claim the id atomically: insert only if no document has it (upsert with $setOnInsert).
            res = self._tasks.update_one({"task_id": tid}, {"$setOnInsert": {"task_id": tid, **doc}}, upsert=True)
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
        current = self._current(record_name, model_name)
        if current is None and not upsert:
            raise self._not_found(record_name, model_name, fields)
        merged = dict(current or self._filter(record_name, model_name))
        merged.update(fields)
        merged["timestamps"] = now_utc()
        validate_parameter(merged)
        doc = self._params.find_one_and_update(
            {"_id": current["_id"]} if current else self._filter(record_name, model_name),
            {"$set": dict(fields), "$currentDate": {"timestamps": True}},
            upsert=upsert, return_document=self._pymongo.ReturnDocument.AFTER,
        )
        if doc is None:
            raise self._not_found(record_name, model_name, fields)
        return doc

    def compare_and_set(self, record_name: str, field: str, expected: Any, new: Any, *,
                        model_name: str | None = None) -> bool:
        check_record_name(record_name)
        validate_fields(record_name, {field: new}, protected=("_id", "record_name", "model_name"))
        current = self._current(record_name, model_name)
        if current is None:
            raise self._not_found(record_name, model_name, (field,))
        merged = {**current, field: new}
        validate_parameter(merged)
        res = self._params.update_one(
            {"_id": current["_id"], field: {"$eq": expected}},
            {"$set": {field: new}, "$currentDate": {"timestamps": True}},
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

    def upsert_parameter(self, doc: Mapping[str, Any]) -> None:
        validate_parameter(doc)
        doc = dict(doc)
        key = {"record_name": doc["record_name"], "model_name": doc.get("model_name")}
        if doc.get("model_name") is None:
            key["model_name"] = {"$in": [None, ""]}
        current = self._params.find_one(key)
        if current is not None:
            doc.setdefault("_id", current["_id"])
            if doc["_id"] != current["_id"]:
                self._params.delete_one({"_id": current["_id"]})
                self._params.insert_one(doc)
            else:
                self._params.replace_one({"_id": current["_id"]}, doc)
        else:
            self._params.insert_one(doc)

    def remove_parameter(self, record_name: str, *, model_name: str | None = None) -> None:
        check_record_name(record_name)
        current = self._current(record_name, model_name)
        if current is None or self._params.delete_one({"_id": current["_id"]}).deleted_count == 0:
            raise self._not_found(record_name, model_name)

    # ---- collections -----------------------------------------------------------------------------
    def collection_names(self) -> list[str]:
        return sorted(n for n in self._db.list_collection_names() if self._db[n].estimated_document_count() > 0)

    def export_collection(self, name: str) -> Iterator[dict]:
        yield from self._db[name].find({}).sort("_id", 1)

    def import_documents(self, name: str, docs: Iterable[Mapping[str, Any]], *, drop: bool = False) -> ImportResult:
        result = ImportResult()
        good: list[tuple[int, dict]] = []
        for i, doc in enumerate(docs):
            try:
                check_import_document(name, doc)
                bson.encode(doc)  # one unencodable document would otherwise fail the whole batch
            except (ValidationError, bson.errors.BSONError, TypeError) as exc:
                result.rejected.append(Rejected(i, document_label(doc), str(exc)))
                continue
            good.append((i, dict(doc)))
        if drop:
            self._db[name].delete_many({})
        if good:
            try:
                # unordered: MongoDB stores every document it can and reports the others by position
                self._db[name].insert_many([d for _, d in good], ordered=False)
            except self._errors.BulkWriteError as exc:
                for err in exc.details.get("writeErrors", []):
                    i, doc = good[err["index"]]
                    result.rejected.append(Rejected(i, document_label(doc), err.get("errmsg", "write error")))
        result.loaded = len(good) - sum(1 for r in result.rejected if r.index in {i for i, _ in good})
        result.rejected.sort(key=lambda r: r.index)
        return result

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
        return problems

    def close(self) -> None:
        self._client.close()
