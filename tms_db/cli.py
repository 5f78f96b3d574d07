"""``tms-db``: the command line of the document store.

::

    tms-db [--uri mongodb://...] [--path DIR] COMMAND
      task add FILE.xml [--id N] [--description TEXT] [--model-name M] [--replace]
      task list | task show ID | task remove ID
      param import FILE.yaml          (a list of documents, or {parameters: [...]})
      param get RECORD [--model-name M]
      param set RECORD FIELD=VALUE... [--model-name M] [--upsert]   (VALUE parsed as JSON: true, 3, 1.5, "s")
      dump DIR | restore DIR [--drop] (MongoDB Extended JSON, one document per line; mongoimport reads it)
      seed paper|fleet|original_202412 [--file config/seeds/<name>.yaml]
      check                           (the store's consistency check)

The store is chosen as in :func:`tms_db.open_store`: ``--uri`` (default ``$TMS_DB_URI``) for MongoDB,
else the embedded store at ``--path`` (default ``$TMS_DB_PATH`` else ``~/.local/share/tms/db``).
Exit codes: 0 done, 1 store or input error (message names file / record / field; a restore that left out
bad documents, each named by file and _id, after loading the others), 2 usage.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from bson import json_util

from tms_common.config import load_yaml, repo_root
from tms_common.errors import TmsError
from tms_db import dumpfmt
from tms_db.errors import StoreError, ValidationError
from tms_db.store import Store, open_store

__all__ = ["main", "import_parameters", "seed"]

_RELAXED = json_util.JSONOptions(json_mode=json_util.JSONMode.RELAXED, tz_aware=True)
PAPER_SEED = Path("config/seeds/paper.yaml")


def _print_doc(doc: dict) -> None:
    print(json.dumps(json.loads(json_util.dumps(doc, json_options=_RELAXED)), indent=2, ensure_ascii=False))


def import_parameters(store: Store, path: str | Path, docs: Any = None, where: Any = None,
                      key_path: tuple = ()) -> int:
    """Upsert the parameter documents of a YAML file; errors carry ``file:line``."""
    if docs is None:
        docs, where = load_yaml(path)
        if isinstance(docs, dict) and "parameters" in docs:
            docs, key_path = docs["parameters"], ("parameters",)
        elif isinstance(docs, dict):
            docs = [docs]
    if not isinstance(docs, list):
        raise StoreError(f"{path}:{where.line_of(key_path)}: expected a list of parameter documents")
    for i, doc in enumerate(docs):
        try:
            store.upsert_parameter(doc)
        except ValidationError as exc:
            raise ValidationError(f"{path}:{where.line_of(key_path + (i,))}: {exc}") from None
    return len(docs)


def seed(store: Store, seed_file: str | Path) -> tuple[int, int]:
    """Load a seed file ``{tasks: [{task_id, file, description, model_name?, blackboard?}], parameters: [...]}``;
    idempotent. A task's ``blackboard`` gives its parameters (initial blackboard entries, e.g. ``{machine: ic120_1}``).

    Task files are relative to the project root (else to the seed file's folder). Returns
    (tasks, parameters) loaded.
    """
    seed_file = Path(seed_file)
    if not seed_file.is_file():
        raise StoreError(f"{seed_file}: seed file not found")
    data, where = load_yaml(seed_file)
    if not isinstance(data, dict):
        raise StoreError(f"{seed_file}:1: expected a mapping with keys 'tasks' and 'parameters'")
    unknown = sorted(set(data) - {"tasks", "parameters", "description"})
    if unknown:
        raise StoreError(f"{seed_file}:{where.line_of((unknown[0],))}: unknown key(s) {unknown}; "
                         "expected 'tasks' and 'parameters'")
    tasks = data.get("tasks") or []
    if not isinstance(tasks, list):
        raise StoreError(f"{seed_file}:{where.line_of(('tasks',))}: 'tasks' must be a list")
    for i, entry in enumerate(tasks):
        line = where.line_of(("tasks", i))
        if not isinstance(entry, dict) or "task_id" not in entry or "file" not in entry:
            raise StoreError(f"{seed_file}:{line}: each task needs 'task_id' and 'file'")
        xml_path = Path(entry["file"])
        if not xml_path.is_absolute():
            candidates = [repo_root() / xml_path, seed_file.parent / xml_path]
            xml_path = next((c for c in candidates if c.is_file()), candidates[0])
        try:
            xml = xml_path.read_text(encoding="utf-8")
        except OSError as exc:
            raise StoreError(f"{seed_file}:{line}: task file {entry['file']}: {exc.strerror}") from None
        try:
            store.add_task(xml, task_id=entry["task_id"], description=entry.get("description", ""),
                           model_name=entry.get("model_name"), replace=True, blackboard=entry.get("blackboard"))
        except ValidationError as exc:
            raise ValidationError(f"{seed_file}:{line}: {xml_path}: {exc}") from None
    n_params = 0
    if data.get("parameters"):
        n_params = import_parameters(store, seed_file, data["parameters"], where, ("parameters",))
    return len(tasks), n_params


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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tms-db", description="The TMS document store (tasks, parameters, blackboard).")
    p.add_argument("--uri", default=os.environ.get("TMS_DB_URI") or None, help="mongodb://... (default $TMS_DB_URI)")
    p.add_argument("--path", default=None, help="embedded store directory (default $TMS_DB_PATH or ~/.local/share/tms/db)")
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
    s.add_argument("name", choices=["paper", "fleet", "original_202412"])
    s.add_argument("--file", default=None, help="seed file (default config/seeds/<name>.yaml)")
    sub.add_parser("check", help="run the store's consistency check")
    return p


def _run(args: argparse.Namespace) -> int:
    with open_store(uri=args.uri, path=args.path) as store:
        if args.cmd == "task":
            if args.task_cmd == "add":
                try:
                    xml = Path(args.file).read_text(encoding="utf-8")
                except OSError as exc:
                    raise StoreError(f"{args.file}: {exc.strerror}") from None
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
            result = dumpfmt.restore(store, args.dir, drop=args.drop)
            print(", ".join(f"{k}: {v}" for k, v in result.counts.items()), "restored")
            for line in result.rejected:
                print(f"tms-db: left out: {line}", file=sys.stderr)
            if result.rejected:
                print(f"tms-db: {len(result.rejected)} document(s) left out; the others are restored", file=sys.stderr)
                return 1
        elif args.cmd == "seed":
            seed_file = Path(args.file) if args.file else repo_root() / PAPER_SEED.with_name(f"{args.name}.yaml")
            if not args.file and not seed_file.is_file():
                raise StoreError(f"{seed_file}: seed file not found; pass --file SEED.yaml")
            n_tasks, n_params = seed(store, seed_file)
            print(f"seed {args.name}: {n_tasks} task(s), {n_params} parameter document(s) from {seed_file}")
        elif args.cmd == "check":
            problems = store.check()
            for line in problems:
                print(line)
            print("consistent" if not problems else f"{len(problems)} problem(s)")
            return 1 if problems else 0
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return _run(args)
    except TmsError as exc:
        print(f"tms-db: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
