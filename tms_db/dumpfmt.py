"""Dump / restore files: MongoDB Extended JSON (canonical), one document per line, readable by ``mongoimport``.

Layout: ``DIR/<database>/<collection>.json`` (``mongoimport --db rostmsdb --collection task
--file DIR/rostmsdb/task.json``). Canonical mode keeps every type exact across tools: ``{"$numberInt"}``,
``{"$numberLong"}``, ``{"$numberDouble"}``, ``{"$date"}``, ``{"$oid"}``, plain ``true``/``false``.
``restore`` also reads JSON arrays (``mongoexport --jsonArray``) and ``mongodump`` BSON files
(``DIR/rostmsdb/<collection>.bson``), so the original's seed dumps load unchanged, binary fields
included. A restore is all or nothing: every file is read and every document checked first (a line that is not
JSON, a corrupt BSON document, text that is not UTF-8, a task whose XML does not parse, two documents with the same
key, a document over the size limit); with any refused, each is reported (file, line or document number, ``_id``,
reason) and nothing is stored. Then everything is written in one transaction.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import bson
import bson.errors
from bson import json_util

from tms_db.errors import StoreError
from tms_db.store import DATABASE, ImportResult, Store, document_label, prevalidate_import

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
    there, reported by the file and the number of documents read before it. A file that is not UTF-8 (JSON) is
    reported by the byte offset of the first bad byte and not read.
    """
    if path.suffix == ".bson":
        n = 0
        try:
            with path.open("rb") as fh:
                for doc in bson.decode_file_iter(fh, codec_options=bson.CodecOptions(tz_aware=True)):
                    n += 1
                    yield f"document {n}", doc
        except (bson.errors.BSONError, ValueError, OverflowError) as exc:
            problems.append(f"{path}: document {n + 1}: not BSON ({exc}); the rest of the file cannot be read")
        except RecursionError:
            problems.append(f"{path}: document {n + 1}: nested too deep to read; the rest of the file cannot be read")
        except OSError as exc:
            raise StoreError(f"{path}: cannot read: {exc.strerror or exc}") from None
        return
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StoreError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        problems.append(f"{path}:{line}: not UTF-8 text: byte 0x{data[exc.start]:02x} at byte offset {exc.start}; "
                        "the file is not read")
        return
    if text.lstrip().startswith("["):
        try:
            docs = json_util.loads(text, json_options=_OPTS)
        except (ValueError, TypeError, OverflowError, bson.errors.BSONError) as exc:
            problems.append(f"{path}: malformed JSON array: {exc}")
            return
        except RecursionError:
            problems.append(f"{path}: JSON array nested too deep to read")
            return
        if not isinstance(docs, list):
            problems.append(f"{path}: not a JSON array of documents")
            return
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
        except (ValueError, TypeError, OverflowError, bson.errors.BSONError) as exc:  # bson raises these on bad $-forms
            problems.append(f"{path}:{lineno}: malformed Extended JSON: {exc}")
            continue
        except RecursionError:
            problems.append(f"{path}:{lineno}: JSON nested too deep to read")
            continue
        if isinstance(doc, dict):
            yield f"line {lineno}", doc
        else:
            problems.append(f"{path}:{lineno}: not a document")


@dataclass
class RestoreResult:
    """Documents stored per collection, and every document refused, named by file, line (or document number) and
    ``_id``. With any refused, nothing is stored (``counts`` all 0). ``partial``: only on a MongoDB server without
    transactions, a write that failed midway: each line names what is stored and what is not."""

    counts: dict[str, int] = field(default_factory=dict)
    rejected: list[str] = field(default_factory=list)
    partial: list[str] = field(default_factory=list)


def restore(store: Store, directory: str | Path, *, drop: bool = False,
            check_task: Callable[[dict], None] | None = None) -> RestoreResult:
    """Load ``directory/<database>/*.json|*.bson`` (or ``directory/*.json|*.bson``) into the store, all or nothing.

    ``check_task(doc)``: a further test of each task document (the CLI validates the tree as the task manager
    loads it); its exception's message is the reason the document is refused.
    """
    directory = Path(directory)
    base = directory / (store.database or DATABASE)
    if not base.is_dir():
        base = directory
    files = sorted(
        p for p in base.glob("*") if p.suffix in (".json", ".bson") and not p.name.endswith(".metadata.json")
    )
    if not files:
        raise StoreError(f"{directory}: no <collection>.json or .bson files (looked in {base})")
    result = RestoreResult()
    batches: list[tuple[Path, list[str], list[dict]]] = []
    for path in files:
        where, docs = [], []
        for at, doc in read_collection_file(path, result.rejected):
            if path.stem == "task" and check_task is not None and isinstance(doc, dict):
                try:
                    check_task(doc)
                except Exception as exc:  # noqa: BLE001 - the checker's reason, whatever its type, refuses the document
                    result.rejected.append(f"{path}: {at} ({document_label(doc)}): {exc}")
            where.append(at)
            docs.append(doc)
        batches.append((path, where, docs))
        result.counts.setdefault(path.stem, 0)
    if result.rejected:  # something could not be read or checked: report every other refusal too, store nothing
        imported = [ImportResult(rejected=prevalidate_import(path.stem, docs)) for path, _w, docs in batches]
    else:
        imported = store.import_collections([(path.stem, docs) for path, _w, docs in batches], drop=drop)
    for (path, where, _docs), res in zip(batches, imported, strict=True):
        for r in res.rejected:
            same = f" (the same as {where[r.first]})" if r.first is not None else ""
            result.rejected.append(f"{path}: {where[r.index]} ({r.label}): {r.reason}{same}")
        if res.not_written:
            result.partial.append(f"{path}: {res.loaded} document(s) stored, {len(res.not_written)} not written "
                                  f"(from {where[res.not_written[0]]})")
        result.counts[path.stem] += res.loaded
    if result.rejected and not result.partial:
        result.counts = dict.fromkeys(result.counts, 0)
    return result
