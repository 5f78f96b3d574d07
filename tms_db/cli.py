"""``tms-db``: the command line of the document store.

::

    tms-db [--uri mongodb://...] [--path DIR] COMMAND
      task add FILE.xml [--id N] [--description TEXT] [--model-name M] [--replace]
                                      (checked as the task manager checks it at start: tms_ts.loader.check_tree)
      task list | task show ID | task remove ID
      param import FILE.yaml          (a list of documents, or {parameters: [...]})
      param get RECORD [--model-name M]
      param set RECORD FIELD=VALUE... [--model-name M] [--upsert]   (VALUE parsed as JSON: true, 3, 1.5, "s")
      dump DIR | restore DIR [--drop] (MongoDB Extended JSON, one document per line; mongoimport reads it)
      seed paper|fleet|original_202412|design_trench|design_embankment [--file config/seeds/<name>.yaml]
      design put FILE.yaml            (one design document or {designs: [...]}, checked by Design.from_dict)
      design list | design show NAME  (the newest stored version; collection ``design``, tms_db.design)
      check                           (the store's consistency check)

The store is chosen as in :func:`tms_db.open_store`: ``--uri`` (default ``$TMS_DB_URI``) for MongoDB,
else the embedded store at ``--path`` (default ``$TMS_DB_PATH`` else ``~/.local/share/tms/db``).

``param import``, ``restore`` and ``seed`` are all or nothing: every document is checked first and with any
refused nothing is stored; each refused one is named on its own line (file and line or document number, why).
Every error ends with one line ``tms-db: error: ...`` on stderr, never a traceback, and the exit code says which
kind (:data:`EXIT_CODES`, the table in tms_db/README.md).
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import sys
import traceback
from pathlib import Path
from typing import Any

from bson import json_util

from tms_common.config import load_yaml, read_utf8, repo_root
from tms_common.errors import TmsError
from tms_db import dumpfmt
from tms_db.backend import open_store
from tms_db.design import get_design, list_designs, put_design
from tms_db.errors import (
    InputRefusedError,
    StorageFullError,
    StorageReadOnlyError,
    StoreError,
    ValidationError,
)
from tms_db.schema import check_document_size, validate_parameter
from tms_db.store import Store, build_task_doc, check_import_document, parameter_key
from tms_rp.excavation.design import Design, DesignError
from tms_ts.limits import MAX_TREE_BYTES, check_tree_size, task_id_problem
from tms_ts.loader import check_tree

__all__ = ["main", "import_parameters", "check_parameters", "seed", "check_designs", "EXIT_CODES"]

#: exit code -> meaning; the same table is in tms_db/README.md
EXIT_CODES = {
    0: "done",
    1: "refused input or store error (the last line names file / record / field; nothing of a refused input is stored)",
    2: "usage (unknown command or option, bad argument)",
    3: "disk full (ENOSPC): nothing of the write that met it is stored",
    4: "storage read-only or not permitted (database directory, file system)",
    70: "internal error (a bug: the line names the exception; TMS_DEBUG=1 prints the traceback)",
    130: "interrupted (Ctrl-C)",
}

_RELAXED = json_util.JSONOptions(json_mode=json_util.JSONMode.RELAXED, tz_aware=True)
PAPER_SEED = Path("config/seeds/paper.yaml")


def _print_doc(doc: dict) -> None:
    print(json.dumps(json.loads(json_util.dumps(doc, json_options=_RELAXED)), indent=2, ensure_ascii=False))


def check_parameters(path: str | Path, docs: Any, where: Any, key_path: tuple = ()) -> list[str]:
    """Every problem of the parameter documents of one file, one line each naming ``file:line``: a document the
    store refuses (shape, size: :data:`tms_db.schema.MAX_DOCUMENT_BYTES`) and two with the same (model_name,
    record_name), naming both lines."""
    if not isinstance(docs, list):
        return [f"{path}:{where.line_of(key_path)}: expected a list of parameter documents"]
    problems: list[str] = []
    first: dict[tuple[str, str], int] = {}
    for i, doc in enumerate(docs):
        line = where.line_of(key_path + (i,))
        try:
            validate_parameter(doc)
            check_document_size(doc, f"record {doc['record_name']!r}")
        except ValidationError as exc:
            problems.append(f"{path}:{line}: {exc}")
            continue
        # YAML has no ObjectId: a stored text _id breaks reads
        if "_id" in doc and type(doc["_id"]).__name__ != "ObjectId":
            problems.append(f"{path}:{line}: record {doc['record_name']!r}: field '_id' {doc['_id']!r} is not an "
                            "ObjectId (YAML cannot give one; leave '_id' out and the store assigns it)")
            continue
        key = parameter_key(doc)
        if key in first:
            problems.append(f"{path}:{line}: duplicate record {key[1]!r} of model {key[0]!r}: "
                            f"also at line {first[key]} (one file names each record once)")
        else:
            first[key] = line
    return problems


def import_parameters(store: Store, path: str | Path, docs: Any = None, where: Any = None,
                      key_path: tuple = ()) -> int:
    """Upsert the parameter documents of a YAML file, all or nothing: every document is checked first
    (:func:`check_parameters`) and with any refused, InputRefusedError lists each by ``file:line`` and nothing is
    stored; then all are written in one transaction."""
    if docs is None:
        docs, where = load_yaml(path)
        if isinstance(docs, dict) and "parameters" in docs:
            docs, key_path = docs["parameters"], ("parameters",)
        elif isinstance(docs, dict):
            docs = [docs]
    problems = check_parameters(path, docs, where, key_path)
    if problems:
        total = len(docs) if isinstance(docs, list) else 0
        raise InputRefusedError(f"{path}: {len(problems)} problem(s) in {total} parameter document(s); "
                                "nothing imported", problems)
    return store.upsert_parameters(docs)


def check_designs(path: str | Path, docs: Any, where: Any, key_path: tuple = ()) -> list[dict]:
    """The design documents of a YAML file, each checked by ``Design.from_dict`` and returned in its stored form
    (``to_dict``: defaults filled in, the area polygon given); StoreError naming ``file:line`` and the key."""
    if not isinstance(docs, list):
        raise StoreError(f"{path}:{where.line_of(key_path) if key_path else 1}: designs must be a list of documents")
    out = []
    for i, doc in enumerate(docs):
        try:
            out.append(Design.from_dict(doc).to_dict())
        except DesignError as exc:
            raise ValidationError(f"{path}:{where.line_of((*key_path, i))}: {exc}") from None
    names = [d["name"] for d in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValidationError(f"{path}: design name(s) {twice} given more than once")
    return out


def seed(store: Store, seed_file: str | Path) -> tuple[int, int]:
    """Load a seed file ``{tasks: [{task_id, file, description, model_name?, blackboard?}], parameters: [...],
    designs: [...]}`` (``designs``: design surfaces, :mod:`tms_db.design`, checked by ``Design.from_dict``);
    idempotent. A task's ``blackboard`` gives its parameters (initial blackboard entries, e.g. ``{machine: <machine
    name>}``).

    Task files are relative to the project root (else to the seed file's folder). Returns
    (tasks, parameters) loaded.
    """
    seed_file = Path(seed_file)
    if not seed_file.is_file():
        raise StoreError(f"{seed_file}: seed file not found")
    data, where = load_yaml(seed_file)
    if not isinstance(data, dict):
        raise StoreError(f"{seed_file}:1: expected a mapping with keys 'tasks' and 'parameters'")
    unknown = sorted(set(data) - {"tasks", "parameters", "designs", "description"})
    if unknown:
        raise StoreError(f"{seed_file}:{where.line_of((unknown[0],))}: unknown key(s) {unknown}; "
                         "expected 'tasks', 'parameters' and 'designs'")
    tasks = data.get("tasks") or []
    if not isinstance(tasks, list):
        raise StoreError(f"{seed_file}:{where.line_of(('tasks',))}: 'tasks' must be a list")
    # Everything is read and checked before anything is written: a bad parameter or task leaves the store as it was.
    params = data.get("parameters") or []
    problems = check_parameters(seed_file, params, where, ("parameters",))
    if problems:
        raise InputRefusedError(f"{seed_file}: {len(problems)} problem(s) in its parameters; nothing seeded", problems)
    designs = check_designs(seed_file, data["designs"], where, ("designs",)) if data.get("designs") else []
    loaded: list[tuple[int, dict, str, Path]] = []
    for i, entry in enumerate(tasks):
        line = where.line_of(("tasks", i))
        if not isinstance(entry, dict) or "task_id" not in entry or "file" not in entry:
            raise StoreError(f"{seed_file}:{line}: each task needs 'task_id' and 'file'")
        if not isinstance(entry["file"], str) or not entry["file"]:
            raise StoreError(f"{seed_file}:{line}: 'file' must be a file name, got {entry['file']!r}")
        xml_path = Path(entry["file"])
        if not xml_path.is_absolute():
            candidates = [repo_root() / xml_path, seed_file.parent / xml_path]
            xml_path = next((c for c in candidates if c.is_file()), candidates[0])
        if not xml_path.exists():
            raise StoreError(f"{seed_file}:{line}: task file {entry['file']}: No such file")
        # at most a tree's size (never read further: a careless path to /dev/zero), UTF-8, named by byte offset
        xml = read_utf8(xml_path, f"{seed_file}:{line}: task file", limit=MAX_TREE_BYTES, limit_name="MAX_TREE_BYTES")
        try:
            build_task_doc(xml, entry["task_id"], entry.get("description", ""), entry.get("model_name"),
                           entry.get("blackboard"))
            check_task_tree({"task_id": entry["task_id"], "task_sequence": xml, "blackboard": entry.get("blackboard")},
                            source=str(xml_path))
        except (TmsError, ValueError) as exc:
            raise ValidationError(f"{seed_file}:{line}: {xml_path}: {exc}") from None
        loaded.append((line, entry, xml, xml_path))
    for line, entry, xml, xml_path in loaded:
        try:
            store.add_task(xml, task_id=entry["task_id"], description=entry.get("description", ""),
                           model_name=entry.get("model_name"), replace=True, blackboard=entry.get("blackboard"))
        except ValidationError as exc:
            raise ValidationError(f"{seed_file}:{line}: {xml_path}: {exc}") from None
    n_params = store.upsert_parameters(params) if params else 0
    for design in designs:
        put_design(store, design)
    return len(tasks), n_params


def check_task_tree(doc: dict, source: str | None = None) -> None:
    """Load a task document's tree as the task manager does at start (``tms_ts.loader.check_tree``, as ``task add``:
    no ROS, no store), so a restore refuses and ``check`` reports a tree the manager would refuse. Lives
    here, in the command line, an application above the scheduler, so that the store itself never imports tms_ts
    (which uses it)."""
    problem = task_id_problem(doc.get("task_id"))  # the id a start message can name (int32)
    if problem:
        raise ValidationError(problem)
    check_tree(doc["task_sequence"], source=source or f"task_id {doc.get('task_id')}", blackboard=doc.get("blackboard"))


def _parse_assignments(items: list[str]) -> dict[str, Any]:
    fields: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise ValidationError(f"{item!r}: expected FIELD=VALUE")
        try:
            fields[name] = json.loads(text)
        except ValueError:
            fields[name] = text  # bare words are strings
    return fields


class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line (exit 2), as every other error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"tms-db: error: {message} (usage: {self.prog} --help)\n")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="tms-db", description="The TMS document store (tasks, parameters, blackboard).",
                epilog="exit codes: " + "; ".join(f"{k} {v.split(' (')[0]}" for k, v in EXIT_CODES.items()))
    p.add_argument("--uri", default=os.environ.get("TMS_DB_URI") or None, help="mongodb://... (default $TMS_DB_URI)")
    p.add_argument(
        "--path", default=None, help="embedded store directory (default $TMS_DB_PATH or ~/.local/share/tms/db)"
    )
    sub = p.add_subparsers(dest="cmd", required=True)

    task = sub.add_parser("task", help="task trees").add_subparsers(dest="task_cmd", required=True)
    add = task.add_parser("add", help="add a behavior-tree XML")
    add.add_argument("file")
    add.add_argument("--id", type=int, default=None)
    add.add_argument("--description", default="")
    add.add_argument("--model-name", default=None)
    add.add_argument("--replace", action="store_true")
    task.add_parser("list", help="list tasks")
    show = task.add_parser("show", help="print one task document")
    show.add_argument("task_id", type=int)
    rm = task.add_parser("remove", help="remove a task")
    rm.add_argument("task_id", type=int)

    param = sub.add_parser("param", help="parameter records").add_subparsers(dest="param_cmd", required=True)
    imp = param.add_parser("import", help="upsert parameter documents from YAML")
    imp.add_argument("file")
    get = param.add_parser("get", help="print one record")
    get.add_argument("record_name")
    get.add_argument("--model-name", default=None)
    pset = param.add_parser("set", help="set fields of one record")
    pset.add_argument("record_name")
    pset.add_argument("assignments", nargs="+", metavar="FIELD=VALUE")
    pset.add_argument("--model-name", default=None)
    pset.add_argument("--upsert", action="store_true")
    param.add_parser("list", help="list records")

    d = sub.add_parser("dump", help="write every collection as Extended JSON under DIR")
    d.add_argument("dir")
    r = sub.add_parser("restore", help="load a dump directory (json or bson)")
    r.add_argument("dir")
    r.add_argument("--drop", action="store_true", help="empty each restored collection first")
    s = sub.add_parser("seed", help="load a named seed")
    s.add_argument("name", choices=["paper", "fleet", "original_202412", "design_trench",
                                                "design_embankment"])
    s.add_argument("--file", default=None, help="seed file (default config/seeds/<name>.yaml)")
    sub.add_parser("check", help="run the store's consistency check")

    design = sub.add_parser("design", help="design surfaces (collection design)").add_subparsers(
        dest="design_cmd", required=True)
    dput = design.add_parser("put", help="store design documents from YAML (a new version of each)")
    dput.add_argument("file")
    design.add_parser("list", help="list the stored designs")
    dshow = design.add_parser("show", help="print the newest version of one design")
    dshow.add_argument("name")
    return p


def _design_file(path: str) -> list[dict]:
    """The checked design documents of ``path`` (one document, a list, or ``{designs: [...]}``)."""
    if not Path(path).is_file():
        raise StoreError(f"{path}: design file not found")
    docs, where = load_yaml(path)
    key_path: tuple = ()
    if isinstance(docs, dict) and "designs" in docs:
        docs, key_path = docs["designs"], ("designs",)
    elif isinstance(docs, dict):
        docs = [docs]
    return check_designs(path, docs, where, key_path)


def _checked_task_file(path: str, task_id: int | None) -> str:
    """The text of the tree file ``path`` for ``task add``, checked as the task manager checks a tree at start.

    Before the store is opened, so a refused tree stores nothing: the id in the interface types' int32 range
    (1..2**31-1), the file at most ``tms_ts.limits.MAX_TREE_BYTES``, UTF-8, and the tree loaded by the manager's
    own loader without ROS (``tms_ts.loader.check_tree``: limits, node ids, ports, SubTrees, leaf names). Errors name
    the file and the line and column in it (the store keeps a one-line form; the user's text is checked here).
    """
    if task_id is not None:
        problem = task_id_problem(task_id)
        if problem:
            raise ValidationError(f"--id {task_id}: {problem}")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise StoreError(f"{path}: {exc.strerror}") from None
    check_tree_size(data, path)
    try:
        xml = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ValidationError(f"{path}:{line}: not UTF-8 (byte {exc.start + 1}: 0x{data[exc.start]:02x})") from None
    check_tree(xml, source=path)
    return xml


def _run(args: argparse.Namespace) -> int:
    xml = _checked_task_file(args.file, args.id) if args.cmd == "task" and args.task_cmd == "add" else None
    designs = _design_file(args.file) if args.cmd == "design" and args.design_cmd == "put" else None
    with open_store(uri=args.uri, path=args.path) as store:
        if args.cmd == "task":
            if args.task_cmd == "add":
                try:
                    tid = store.add_task(xml, task_id=args.id, description=args.description,
                                         model_name=args.model_name, replace=args.replace)
                except ValidationError as exc:
                    raise ValidationError(f"{args.file}: {exc}") from None
                print(f"task_id {tid}")
            elif args.task_cmd == "list":
                for t in store.list_tasks():
                    print(f"{t.get('task_id')}\t{t.get('model_name', '')}\t{t.get('description', '')}")
            elif args.task_cmd == "show":
                _print_doc(store.get_task(args.task_id))
            else:
                store.remove_task(args.task_id)
                print(f"removed task_id {args.task_id}")
        elif args.cmd == "param":
            if args.param_cmd == "import":
                print(f"{import_parameters(store, args.file)} parameter document(s) imported")
            elif args.param_cmd == "get":
                _print_doc(store.get_parameter(args.model_name, args.record_name))
            elif args.param_cmd == "set":
                _print_doc(store.set_fields(args.record_name, _parse_assignments(args.assignments),
                                            model_name=args.model_name, upsert=args.upsert))
            else:
                for doc in store.list_parameters():
                    print(f"{doc.get('model_name', '')}\t{doc.get('type', '')}\t{doc.get('record_name')}")
        elif args.cmd == "dump":
            counts = dumpfmt.dump(store, args.dir)
            print(", ".join(f"{k}: {v}" for k, v in counts.items()) or "nothing to dump", f"-> {args.dir}")
        elif args.cmd == "restore":
            result = dumpfmt.restore(store, args.dir, drop=args.drop, check_task=check_task_tree)
            for line in result.rejected:
                print(f"tms-db: refused: {line}", file=sys.stderr)
            if result.partial:  # a MongoDB server without transactions failed midway: say exactly what is stored
                for line in result.partial:
                    print(f"tms-db: partly stored: {line}", file=sys.stderr)
                raise StoreError(f"restore {args.dir}: the server failed midway (no transactions): "
                                 + ", ".join(f"{k}: {v}" for k, v in result.counts.items()) + " stored, the rest not")
            if result.rejected:
                raise InputRefusedError(f"restore {args.dir}: {len(result.rejected)} document(s) refused "
                                        "(listed above); nothing restored", [])
            print(", ".join(f"{k}: {v}" for k, v in result.counts.items()), "restored")
        elif args.cmd == "seed":
            seed_file = Path(args.file) if args.file else repo_root() / PAPER_SEED.with_name(f"{args.name}.yaml")
            if not args.file and not seed_file.is_file():
                raise StoreError(f"{seed_file}: seed file not found; pass --file SEED.yaml")
            n_tasks, n_params = seed(store, seed_file)
            print(f"seed {args.name}: {n_tasks} task(s), {n_params} parameter document(s) from {seed_file}")
        elif args.cmd == "design":
            if args.design_cmd == "put":
                for design in designs or []:
                    print(f"design {design['name']!r} ({design['kind']}): {put_design(store, design)}")
            elif args.design_cmd == "list":
                for name in list_designs(store):
                    print(name)
            else:
                _print_doc(get_design(store, args.name))
        elif args.cmd == "check":
            problems = store.check()
            for doc in store.list_tasks():  # the trees as the task manager loads them
                try:
                    check_import_document("task", doc)
                except ValidationError:
                    continue  # store.check() has named it
                try:
                    check_task_tree(doc)
                except Exception as exc:  # noqa: BLE001 - whatever the loader raises, the task cannot start
                    problems.append(f"task ({doc.get('task_id')}): {exc}")
            for line in problems:
                print(line)
            print("consistent" if not problems else f"{len(problems)} problem(s)")
            if problems:
                raise StoreError(f"check: {len(problems)} problem(s) in the store (listed on stdout)")
    return 0


def _fail(code: int, text: str) -> int:
    print(f"tms-db: error: {' '.join(str(text).split())}", file=sys.stderr)  # one line, whatever the message holds
    return code


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return _run(args)
    except InputRefusedError as exc:
        for line in exc.problems:
            print(f"tms-db: refused: {' '.join(line.split())}", file=sys.stderr)
        return _fail(1, str(exc))
    except StorageFullError as exc:
        return _fail(3, str(exc))
    except StorageReadOnlyError as exc:
        return _fail(4, str(exc))
    except TmsError as exc:
        return _fail(1, str(exc))
    except UnicodeDecodeError as exc:
        name = getattr(args, "file", None) or getattr(args, "dir", None) or "input"
        return _fail(1, f"{name}: not UTF-8 text: byte 0x{exc.object[exc.start]:02x} at byte offset {exc.start}")
    except BrokenPipeError:
        # the reader of the output went away (`tms-db task list | head`): stop quietly, as Python's docs advise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            return _fail(3, f"{where}disk full (ENOSPC): {exc.strerror}")
        if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            return _fail(4, f"{where}read-only or not permitted: {exc.strerror}")
        return _fail(1, f"{where}{exc.strerror or exc}")
    except RecursionError:
        return _fail(1, "input nested too deep to read")
    except MemoryError:
        return _fail(1, "out of memory reading the input")
    except KeyboardInterrupt:
        return _fail(130, "interrupted")
    except Exception as exc:  # noqa: BLE001 - a bug still ends in one line, the traceback only on request
        if os.environ.get("TMS_DEBUG"):
            traceback.print_exc()
        return _fail(70, f"internal error: {type(exc).__name__}: {exc}")


if __name__ == "__main__":
    sys.exit(main())
