"""com3_can's modules import each other one way (no cycle), and every project import sits at module level.

A cycle papered over by an import inside a function hides which module needs which; the output types live in
``com3_can.outputs``, the profile is handed to the core, and the machine description names its DBC, so none is
needed. Every import statement counts, also those under ``if TYPE_CHECKING:``.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "com3_can"
#: the repository's own top-level packages (an import of one of them is a project import)
PROJECT = {p.parent.name for p in ROOT.glob("*/__init__.py")}


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, ast.Module]:
    return {_module(p): ast.parse(p.read_text(), str(p)) for p in sorted((ROOT / PACKAGE).rglob("*.py"))}


def _imported(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
        return [node.module] + [f"{node.module}.{a.name}" for a in node.names]
    return []


def test_the_scan_sees_the_package() -> None:
    mods = _modules()
    assert {"com3_can.bridge_core", "com3_can.outputs", "com3_can.profiles", "com3_can.profiles.base",
            "com3_can.nodes.com3_bridge"} <= set(mods)
    assert {"com3_can", "tms_model", "tms_common"} <= PROJECT


def test_no_project_import_inside_a_function() -> None:
    bad = []
    for name, tree in _modules().items():
        for fn in ast.walk(tree):
            if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                for node in ast.walk(fn):
                    bad += [f"{name}:{node.lineno} {m}" for m in _imported(node)[:1] if m.split(".")[0] in PROJECT]
    assert bad == []


def test_the_import_graph_of_com3_can_is_acyclic() -> None:
    mods = _modules()
    graph = {name: {m for node in ast.walk(tree) for m in _imported(node) if m in mods and m != name}
             for name, tree in mods.items()}
    done: set[str] = set()

    def visit(name: str, path: tuple[str, ...]) -> None:
        if name in path:
            raise AssertionError(f"import cycle: {' -> '.join(path[path.index(name):] + (name,))}")
        if name in done:
            return
        for dep in sorted(graph[name]):
            visit(dep, (*path, name))
        done.add(name)

    for name in sorted(graph):
        visit(name, ())
    # the core and the profiles meet only through the profile base: neither imports the other's module
    assert "com3_can.bridge_core" not in {
        m for n, deps in graph.items() if n.startswith("com3_can.profiles") for m in deps
    }
    assert "com3_can.profiles" not in graph["com3_can.bridge_core"]
