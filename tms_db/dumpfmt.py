"""Dump / restore files: MongoDB Extended JSON (canonical), one document per line, readable by ``mongoimport``.

Layout: ``DIR/<database>/<collection>.json`` (``mongoimport --db rostmsdb --collection task
--file DIR/rostmsdb/task.json``). Canonical mode keeps every type exact across tools: ``{"$numberInt"}``,
``{"$numberLong"}``, ``{"$numberDouble"}``, ``{"$date"}``, ``{"$oid"}``, plain ``true``/``false``.
``restore`` also reads JSON arrays (``mongoexport --jsonArray``) and ``mongodump`` BSON files
(``DIR/rostmsdb/<collection>.bson``), so the original's seed dumps load unchanged, binary fields
included. A bad document is reported (file, ``_id`` or line, reason) and the others load.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import bson
import bson.errors
from bson import json_util

from tms_db.errors import StoreError
from tms_db.store import DATABASE, Store

__all__ = ["dump", "restore", "RestoreResult", "read_collection_file", "dumps_doc"]

_OPTS = json_util.JSONOptions(json_mode=json_util.JSONMode.CANONICAL, tz_aware=True, tzinfo=bson.tz_util.utc)


def dumps_doc(doc: dict) -> str:
    """One document as canonical Extended JSON text."""
    return json_util.dumps(doc, json_options=_OPTS)


def dump(store: Store, directory: str | Path) -> dict[str, int]:
    """Write every collection to ``directory/<database>/<collection>.json``; returns counts per collection."""
    out = Path(directory) / (store.database or DATABASE)
    out.mkdir(parents=True, exist_ok=True)
    counts = {}
    for name in store.collection_names():
        path = out / f"{name}.json"
        tmp = path.with_suffix(".json.tmp")
        n = 0
        with tmp.open("w", encoding="utf-8") as fh:
            for doc in store.export_collection(name):
                fh.write(dumps_doc(doc) + "\n")
                n += 1
        tmp.replace(path)
        counts[name] = n
    return counts


def read_collection_file(path: Path, problems: list[str]) -> Iterator[tuple[str, dict]]:
    """(where, document) for each document of one dump file (.json lines or array, or .bson); ``where``
    is ``line N`` (JSON lines), ``element N`` (JSON array) or ``document N`` (BSON), counted from 1.

    A line or element that is not a document is reported in ``problems`` by file and line (element)
    and skipped; a BSON stream cannot be resynchronised after a corrupt document, so reading stops
    there, reported by the file and the number of documents read before it.
    """
    if path.suffix == ".bson":
        n = 0
        try:
            with path.open("rb") as fh:
                for doc in bson.decode_file_iter(fh, codec_options=bson.CodecOptions(tz_aware=True)):
                    n += 1
                    yield f"document {n}", doc
        except bson.errors.BSONError as exc:
            problems.append(f"{path}: document {n + 1}: not BSON ({exc}); the rest of the file is not read")
        return
    text = path.read_text(encoding="utf-8")
    if text.lstrip().startswith("["):
        try:
            docs = json_util.loads(text, json_options=_OPTS)
        except ValueError as exc:
            raise StoreError(f"{path}: malformed JSON array: {exc}") from None
        for i, doc in enumerate(docs, 1):
            if isinstance(doc, dict):
                yield f"element {i}", doc
            else:
                problems.append(f"{path}: element {i} is not a document")
        return
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            doc = json_util.loads(line, json_options=_OPTS)
        except ValueError as exc:
            problems.append(f"{path}:{lineno}: malformed Extended JSON: {exc}")
            continue
        if isinstance(doc, dict):
            yield f"line {lineno}", doc
        else:
            problems.append(f"{path}:{lineno}: not a document")


@dataclass
class RestoreResult:
    """Documents stored per collection, and every document left out, named by file and ``_id`` (or line)."""

    counts: dict[str, int] = field(default_factory=dict)
    rejected: list[str] = field(default_factory=list)


def restore(store: Store, directory: str | Path, *, drop: bool = False) -> RestoreResult:
    """Load ``directory/<database>/*.json|*.bson`` (or ``directory/*.json|*.bson``) into the store.

    A bad document is reported and left out; the rest of its collection loads.
    """
    directory = Path(directory)
    base = directory / (store.database or DATABASE)
    if not base.is_dir():
        base = directory
    files = sorted(p for p in base.glob("*") if p.suffix in (".json", ".bson") and not p.name.endswith(".metadata.json"))
    if not files:
        raise StoreError(f"{directory}: no <collection>.json or .bson files (looked in {base})")
    result = RestoreResult()
    for path in files:
        where, docs = [], []
        for at, doc in read_collection_file(path, result.rejected):
            where.append(at)
            docs.append(doc)
        imported = store.import_documents(path.stem, docs, drop=drop)
        result.counts[path.stem] = imported.loaded
        result.rejected += [f"{path}: {where[r.index]} ({r.label}): {r.reason}" for r in imported.rejected]
    return result
