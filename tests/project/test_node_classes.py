"""One node shape: every node of the project is a module-level ``class X(Node)`` in ``<package>/nodes/<executable>.py``.

Discovery is generic: every ``<package>/nodes/*.py`` of the project is imported, and the rclpy Node subclasses
it defines are collected. A module named by a console script ([project.scripts] of pyproject.toml) defines
exactly one; any other module there (helpers such as ``tms_db/nodes/common.py``) defines none. Then every node
class is constructed, all in this one process and context (as a composed process would), each with the
usual rclpy keyword arguments, and all are destroyed. An ast scan checks that no class of the packages is
defined inside a function (where the discovery could not see it).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import os
import socket
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.parent.name for p in ROOT.glob("*/__init__.py") if p.parent.name not in ("tests", "tms_msg"))


def _scripts() -> dict[str, str]:
    """console-script name -> module, from pyproject.toml."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    return {name: target.partition(":")[0] for name, target in scripts.items()}


def _node_modules() -> list[str]:
    return sorted(f"{pkg}.nodes.{f.stem}" for pkg in PACKAGES for f in (ROOT / pkg / "nodes").glob("*.py")
                  if f.stem != "__init__")


def _node_classes(module_name: str) -> list[type]:
    from rclpy.node import Node

    module = importlib.import_module(module_name)
    return [obj for obj in vars(module).values()
            if inspect.isclass(obj) and issubclass(obj, Node) and obj.__module__ == module_name]


def test_no_class_is_defined_inside_a_function():
    nested = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(), str(path))
            for fn in ast.walk(tree):
                if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                    nested += [f"{path.relative_to(ROOT)}:{c.lineno} class {c.name} in {fn.name}()"
                               for c in ast.walk(fn) if isinstance(c, ast.ClassDef)]
    assert not nested, "classes defined inside functions (move them to module level):\n" + "\n".join(nested)


def test_every_node_module_defines_one_module_level_node_class():
    script_modules = set(_scripts().values())
    modules = _node_modules()
    found = {m: [c.__name__ for c in _node_classes(m)] for m in modules}
    node_modules = [m for m in modules if m in script_modules]
    assert node_modules, "no node modules found"
    wrong = {m: names for m, names in found.items() if len(names) != (1 if m in script_modules else 0)}
    assert not wrong, f"expected one Node class per console-script module and none elsewhere: {wrong}"
    assert sum(len(n) for n in found.values()) == len(node_modules)
    # a node module is named after its executable: <package>/nodes/<executable>.py
    for name, module in _scripts().items():
        if ".nodes." in module and module.rpartition(".")[2] != name.replace("-", "_"):
            # the task scheduler's modules keep their names until their node shape moves them
            assert module.startswith(("tms_ts.", "tms_if_opera.")), f"{name} lives in {module}, not .nodes.{name}"


@pytest.fixture
def context(domain, tmp_path):
    import rclpy
    from rclpy.context import Context

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _overrides(tmp: Path) -> dict[str, object]:
    """Parameters every node may need to start here, as in the paper launch: simulated time (the plant on
    wall time), a temp DB seeded with ``config/seeds/paper.yaml``, CAN on in-process virtual channels, a
    free web port. Overrides of parameters a node does not declare are ignored by rclpy, so one set serves all.
    """
    from tms_db import open_store
    from tms_db.cli import seed

    db = tmp / "db"
    db.mkdir(exist_ok=True)
    store = open_store(path=str(db))
    try:
        seed(store, ROOT / "config" / "seeds" / "paper.yaml")
    finally:
        store.close()
    values: dict[str, object] = {
        "use_sim_time": True, "machine": "zx200", "db_path": str(db), "runs_dir": str(tmp / "runs"),
        "port": _free_tcp_port(),
        "can_interface": "virtual", "can_channel": f"node_classes_{os.getpid()}_zx200",
    }
    for machine in ("zx200", "ic120"):
        values[f"{machine}_can_interface"] = "virtual"
        values[f"{machine}_can_channel"] = f"node_classes_{os.getpid()}_{machine}"
    return values


#: per executable (module name), what differs from the paper launch's common parameters
SPECIFIC: dict[str, dict[str, object]] = {
    "sim_plant": {"use_sim_time": False},
    # a vessel controller serves a crawler carrier (it refuses an excavator, naming it)
    "vessel_controller": {"machine": "ic120"},
    "ic120_vessel": {"machine": "ic120"},
}


def test_every_node_class_is_built_and_destroyed_in_one_process(context, tmp_path):
    from rclpy.parameter import Parameter

    classes = [c for m in _node_modules() for c in _node_classes(m)]
    assert classes
    common = _overrides(tmp_path)
    other_port = _free_tcp_port()
    while other_port == common["port"]:
        other_port = _free_tcp_port()
    specific = {
        **SPECIFIC,
        # the recorder needs a new bag directory; the Foxglove server and the panel each bind a port of their own
        "tms_ur_recorder": {"output": str(tmp_path / "bag")},
        "tms_ur_foxglove": {"port": other_port},
    }
    nodes, failures = [], []
    try:
        for cls in classes:
            values = {**common, **specific.get(cls.__module__.rpartition(".")[2], {})}
            overrides = [Parameter(k, value=v) for k, v in values.items()]
            try:
                nodes.append(cls(context=context, parameter_overrides=overrides))
            except Exception as exc:  # noqa: BLE001 - collect every failure, then report them together
                failures.append(f"{cls.__module__}.{cls.__name__}: {type(exc).__name__}: {exc}")
        assert not failures, "node classes that could not be built:\n" + "\n".join(failures)
        names = sorted(n.get_fully_qualified_name() for n in nodes)
        assert len(names) == len(classes), names
        for node in nodes:  # the rclpy keyword arguments reached rclpy's Node
            assert node.context is context
    finally:
        for node in reversed(nodes):
            node.destroy_node()
    print(f"{len(nodes)} node classes built and destroyed in process {os.getpid()}", file=sys.stderr)
