"""The hierarchy points one way: tms_rc and tms_rp import nothing of each other; tms_model imports only below it."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _imports(package: str) -> dict[str, set[str]]:
    """module file -> top-level packages it imports (every import statement, also inside functions)."""
    out: dict[str, set[str]] = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        names: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
        out[str(path.relative_to(ROOT))] = names
    return out


def test_tms_rc_and_tms_rp_do_not_import_each_other() -> None:
    rc = {f: n for f, n in _imports("tms_rc").items() if "tms_rp" in n}
    rp = {f: n for f, n in _imports("tms_rp").items() if "tms_rc" in n}
    assert len(_imports("tms_rc")) > 5 and len(_imports("tms_rp")) > 5  # the scan saw the packages
    assert rc == {}, f"tms_rc imports tms_rp: {sorted(rc)}"
    assert rp == {}, f"tms_rp imports tms_rc: {sorted(rp)}"


def test_tms_model_imports_only_what_is_below_it() -> None:
    allowed = {"tms_model", "tms_common", "numpy", "pinocchio", "pyproj", "yaml", "__future__"}
    stdlib = {"math", "functools", "dataclasses", "pathlib", "types", "typing", "collections", "re", "xml"}
    bad = {f: sorted(n - allowed - stdlib) for f, n in _imports("tms_model").items() if n - allowed - stdlib}
    assert bad == {}


def test_tms_model_has_no_project_import_inside_a_function() -> None:
    project = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    bad = []
    for path in sorted((ROOT / "tms_model").rglob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                for node in ast.walk(fn):
                    if isinstance(node, ast.ImportFrom | ast.Import):
                        name = node.module if isinstance(node, ast.ImportFrom) else node.names[0].name
                        if name and name.split(".")[0] in project:
                            bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {name}")
    assert bad == []
