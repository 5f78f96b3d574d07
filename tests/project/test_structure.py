"""The code's shape as docs/architecture.md states it, read from the source (no import is executed):

- a machine is known by its name: no string literal of a machine name or kind, and no machine type compared with
  a literal (use the type constants of tms_model.machines), in shared code outside the kind registries (names come from
  config/, trees/ and parameters);
- dependencies point one way: a package imports only packages on lower levels of the module hierarchy, and the
  modules of one package import each other without a cycle;
- no project import hides inside a function body (the way a cycle is papered over).
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]

#: docs/architecture.md "Module hierarchy": package -> level (a package imports only lower levels)
LEVELS = {
    "tms_common": 1,
    "tms_model": 2, "tms_db": 2,
    "com3_can": 3, "sim_bridge": 3, "tms_rp": 3, "tms_rc": 3, "tms_sp": 3,
    "tms_if_opera": 4,
    "tms_ts": 5,
    "tms_ur": 6, "tms_launch": 6,
}
#: modules on a level of their own: the ``tms-db`` command checks a tree with the scheduler's loader before the
#: store takes it, an application above tms_ts
MODULE_LEVELS = {"tms_db.cli": 6}
#: same-level pairs the architecture allows (sim_bridge speaks COM3 through com3_can's codecs and buses)
SIDEWAYS = {("sim_bridge", "com3_can")}


def _level(module: str) -> int:
    return MODULE_LEVELS.get(module, LEVELS[module.split(".")[0]])

#: the kind registries: the one place per package that maps machine types or kinds to code, or that holds the
#: original's interface names (which contain the original's machine names), with why
REGISTRIES = {
    "tms_model/machines.py": "the machine types and their parsers",
    "com3_can/profiles/__init__.py": "machine type -> COM3 converter profile",
    "sim_bridge/profiles/__init__.py": "machine type -> plant profile",
    "tms_ts/subtask_specs.py": "the subtask table: the original's subtask names, which machine kind serves which",
    "tms_if_opera/interface.py": "the original's ZX200 planning action and topic names",
}


def _machine_words() -> tuple[set[str], set[str]]:
    """(machine names and kinds, machine types) from the project's configuration."""
    kinds = {p.stem for p in (ROOT / "config" / "machines").glob("*.yaml")}
    site = yaml.safe_load((ROOT / "config" / "site.yaml").read_text())
    names = set(site.get("machines", {}))
    types = {yaml.safe_load(p.read_text())["type"] for p in (ROOT / "config" / "machines").glob("*.yaml")}
    return kinds | names, types


def _modules(package: str) -> Iterator[Path]:
    yield from sorted((ROOT / package).rglob("*.py"))


def _docstring_nodes(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def test_no_machine_name_or_kind_literal_in_shared_code() -> None:
    words, types = _machine_words()
    assert {"zx200", "ic120_1"} <= words and types, "the test reads the site's machines and kinds"
    token = re.compile(r"(?<![a-z0-9])(" + "|".join(sorted(map(re.escape, words), key=len, reverse=True)) +
                       r")(?![a-z0-9])", re.IGNORECASE)  # "ZX200" and "/Zx120/" name a machine too
    found = []
    for package in LEVELS:
        for path in _modules(package):
            rel = path.relative_to(ROOT).as_posix()
            if rel in REGISTRIES:
                continue
            tree = ast.parse(path.read_text(), rel)
            docs = _docstring_nodes(tree)
            compared = {id(c) for node in ast.walk(tree) if isinstance(node, ast.Compare)
                        for c in ast.walk(node) if isinstance(c, ast.Constant)}
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
                    # a type word is also a plain key name ("excavator: zx200"): compared, it is a branch on type
                    if token.search(node.value) or (node.value.lower() in types and id(node) in compared):
                        found.append(f"{rel}:{node.lineno}: {node.value!r}")
    assert not found, ("machine names, kinds or types as literals in shared code (take them from config or "
                       "parameters, or put them in a kind registry):\n" + "\n".join(found))


def _project_imports(tree: ast.AST) -> Iterator[tuple[ast.AST, str, bool]]:
    """(node, imported module, inside a function) of every import of the project's packages; imports under
    ``if TYPE_CHECKING:`` are left out (they never run)."""

    def visit(node: ast.AST, in_function: bool) -> Iterator[tuple[ast.AST, str, bool]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    yield child, alias.name, in_function
            elif isinstance(child, ast.ImportFrom) and child.level == 0 and child.module:
                for alias in child.names:
                    yield child, f"{child.module}.{alias.name}", in_function
            yield from visit(child, inner)

    for node, name, in_function in visit(tree, False):
        if name.split(".")[0] in LEVELS:
            yield node, name, in_function


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(name: str, known: set[str]) -> str | None:
    """The project module ``name`` refers to (``pkg.mod.Symbol`` -> ``pkg.mod``)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def _graph() -> tuple[dict[str, set[str]], list[str], list[str]]:
    """(module -> project modules it imports at module level, imports inside functions, level breaches)."""
    paths = {_module_name(p): p for package in LEVELS for p in _modules(package)}
    known = set(paths)
    graph: dict[str, set[str]] = {m: set() for m in known}
    in_functions, breaches = [], []
    for module, path in paths.items():
        rel = path.relative_to(ROOT).as_posix()
        for node, name, in_function in _project_imports(ast.parse(path.read_text(), rel)):
            target = _resolve(name, known)
            if target is None or target == module:
                continue
            src, dst = module.split(".")[0], target.split(".")[0]
            if in_function:
                in_functions.append(f"{rel}:{node.lineno}: {name}")
            if src != dst and _level(target) >= _level(module) and (src, dst) not in SIDEWAYS:
                breaches.append(f"{rel}:{node.lineno}: {module} (level {_level(module)}) imports {name} "
                                f"(level {_level(target)})")
            # a package's __init__ re-exports its modules: importing ``pkg.mod`` runs ``pkg`` first, which is
            # no edge of its own
            if not in_function:
                graph[module].add(target)
    return graph, in_functions, breaches


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), within each package."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w.split(".")[0] != v.split(".")[0]:
                continue
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_no_import_cycle_between_modules_of_a_package() -> None:
    graph, _, _ = _graph()
    assert "tms_ts.subtask_specs" in graph and graph["tms_ts.subtask_specs"], "the test sees the project's imports"
    cycles = _cycles(graph)
    assert not cycles, "import cycles between modules of one package:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_project_import_inside_a_function() -> None:
    _, in_functions, _ = _graph()
    assert not in_functions, ("project imports inside function bodies (an import cycle papered over; move it to "
                              "the module's top):\n" + "\n".join(in_functions))


def test_packages_import_only_lower_levels() -> None:
    _, _, breaches = _graph()
    assert not breaches, "imports against docs/architecture.md's module hierarchy:\n" + "\n".join(breaches)


def test_the_cycle_finder_finds_a_cycle() -> None:
    graph = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a"}, "p.d": {"p.a"}, "q.x": {"p.a"}}
    assert _cycles(graph) == [["p.a", "p.b", "p.c"]]


def test_the_store_is_used_through_its_public_api_only() -> None:
    """docs/architecture.md: packages above tms_db import only the names ``tms_db/__init__.py`` exports."""
    found = []
    for package in LEVELS:
        if package == "tms_db":
            continue
        for path in _modules(package):
            rel = path.relative_to(ROOT).as_posix()
            for node, name, _ in _project_imports(ast.parse(path.read_text(), rel)):
                if name.startswith("tms_db.") and not isinstance(node, ast.ImportFrom) or (
                        isinstance(node, ast.ImportFrom) and node.module != "tms_db" and name.startswith("tms_db.")):
                    found.append(f"{rel}:{node.lineno}: {name}")
    assert not found, "imports of tms_db's modules (use `from tms_db import ...`):\n" + "\n".join(found)


def test_tests_mirror_the_packages() -> None:
    """tests/<package> for every package (tests/integration, paper, project, hosts, vcan, bench cut across them)."""
    missing = [p for p in LEVELS if not (ROOT / "tests" / p).is_dir()]
    assert not missing, f"packages without tests/<package>: {missing}"
