"""Launch-file model: parse and validate ``config/launch/*.yaml`` before anything starts.

A launch file::

    name: demo                       # optional, shown in the progress line
    env: {TMS_DB_PATH: runs/db}      # optional, added to every node's environment
    parameters: {use_sim_time: true} # optional, ROS parameters given to every node (a node's own win)
    startup: sequential              # or parallel: start every process at once, then wait for each
    shutdown: parallel               # or reverse: stop the nodes one at a time, last started first, each
                                     # gone before the next is signalled (a scheduler cancels its subtasks
                                     # while their servers and the controllers below are still up)
    nodes:
      - name: talker                 # ROS node name (``-r __node:=talker``); unique
        package: tms_launch          # ament package of the executable
        executable: demo_talker      # found as <prefix>/lib/<package>/<executable>, as ros2 run does
        namespace: /demo             # optional (``-r __ns:=/demo``)
        parameters: {rate_hz: 50.0}  # optional ROS parameters (``-p key:=value``)
        param_files: [config/x.yaml] # optional ``--params-file`` paths, relative to the project root
        arguments: []                # optional extra command-line arguments before ``--ros-args``
        env: {}                      # optional per-node environment
        required: true               # default true: its death stops the launch with an error
        on_exit: shutdown            # optional: when this node exits 0 the whole launch ends with 0
                                     # (a job node, e.g. the experiment supervisor); non-zero is an error
        ready_timeout: 90            # seconds to wait until the node is visible on the ROS graph
        nice: -10                    # optional scheduling niceness of the process and all its threads
                                     # (-20..19, default: the launcher's); below the launcher's needs root
                                     # or CAP_SYS_NICE, else the node runs unchanged and says so
        stop_grace_s: 30             # seconds between SIGINT and SIGTERM when the launch stops (default
                                     # 2.5): a node that writes results on its way out (the experiment
                                     # supervisor's report) gets the time to finish; SIGKILL 1.5 s later

Every problem (malformed YAML, unknown key, unknown executable, duplicate name) is a
:class:`~tms_common.errors.ConfigError` naming the file and line; nothing is started.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tms_common.config import Where, load_yaml, repo_root
from tms_common.errors import ConfigError

NODE_KEYS = {
    "name",
    "package",
    "executable",
    "namespace",
    "parameters",
    "param_files",
    "arguments",
    "env",
    "required",
    "ready_timeout",
    "on_exit",
    "nice",
    "stop_grace_s",
}
TOP_KEYS = {"name", "nodes", "env", "parameters", "startup", "shutdown"}
STARTUP = {"sequential", "parallel"}
SHUTDOWN = {"parallel", "reverse"}
ON_EXIT = {"error", "shutdown"}
DEFAULT_STOP_GRACE_S = 2.5  # SIGINT -> SIGTERM when a node has no stop_grace_s


@dataclass(frozen=True)
class NodeSpec:
    """One node of a launch file, validated and resolved to an executable path."""

    name: str
    package: str
    executable: str
    path: Path
    namespace: str = "/"
    parameters: dict[str, Any] = field(default_factory=dict)
    param_files: tuple[Path, ...] = ()
    arguments: tuple[str, ...] = ()
    env: dict[str, str] = field(default_factory=dict)
    required: bool = True
    ready_timeout: float = 90.0
    on_exit: str = "error"
    nice: int | None = None
    stop_grace_s: float = DEFAULT_STOP_GRACE_S

    @property
    def fqn(self) -> str:
        """Fully qualified node name, e.g. ``/demo/talker``."""
        return (self.namespace.rstrip("/") + "/" + self.name) if self.namespace != "/" else "/" + self.name

    def command(self) -> list[str]:
        """The command line that starts this node, as ``ros2 run`` would plus our remaps."""
        cmd = [str(self.path), *self.arguments, "--ros-args", "-r", f"__node:={self.name}"]
        if self.namespace != "/":
            cmd += ["-r", f"__ns:={self.namespace}"]
        for key, value in self.parameters.items():
            cmd += ["-p", f"{key}:={_param_literal(value)}"]
        for path in self.param_files:
            cmd += ["--params-file", str(path)]
        return cmd


@dataclass(frozen=True)
class LaunchFile:
    """A validated launch file."""

    file: str
    name: str
    nodes: tuple[NodeSpec, ...]
    env: dict[str, str]
    startup: str = "sequential"
    shutdown: str = "parallel"


def _param_literal(value: Any) -> str:
    """A ROS ``-p key:=value`` literal (YAML syntax) that keeps the value's type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return json.dumps(value)


def ament_prefixes() -> list[Path]:
    """The ament prefixes searched for executables: AMENT_PREFIX_PATH, else this interpreter's prefix."""
    raw = os.environ.get("AMENT_PREFIX_PATH")
    return [Path(p) for p in raw.split(os.pathsep) if p] if raw else [Path(sys.prefix)]


def resolve_executable(package: str, executable: str) -> Path:
    """Find ``<prefix>/lib/<package>/<executable>`` exactly as ``ros2 run`` does.

    Raises:
        LookupError: the package is not in the ament index, or has no such executable.
    """
    os.environ.setdefault("AMENT_PREFIX_PATH", os.pathsep.join(str(p) for p in ament_prefixes()))
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = Path(get_package_prefix(package))
    except PackageNotFoundError:
        raise LookupError(f"package {package!r} is not in the ament index ({os.environ['AMENT_PREFIX_PATH']})") from None
    path = prefix / "lib" / package / executable
    if not (path.is_file() and os.access(path, os.X_OK)):
        known = sorted(p.name for p in (prefix / "lib" / package).glob("*") if os.access(p, os.X_OK))
        raise LookupError(f"package {package!r} has no executable {executable!r} (known: {', '.join(known) or 'none'})")
    return path


def _expect(where: Where, path: tuple[Any, ...], value: Any, kind: type | tuple[type, ...], what: str) -> Any:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    # bool is an int in Python; a YAML `true` must not pass where a number is expected.
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise where.error(path, f"{what} must be {getattr(kind, '__name__', kind)}, got {type(value).__name__} {value!r}")
    return value


def parse_launch_file(path: str | Path) -> LaunchFile:
    """Load and validate a launch file; every error names the file and line."""
    data, where = load_yaml(path)
    if not isinstance(data, dict):
        raise where.error((), "a launch file must be a mapping with a 'nodes' list")
    for key in data:
        if key not in TOP_KEYS:
            raise where.error((key,), f"unknown key {key!r} (expected one of {', '.join(sorted(TOP_KEYS))})")
    nodes_raw = data.get("nodes")
    if not isinstance(nodes_raw, list) or not nodes_raw:
        raise where.error(("nodes",), "'nodes' must be a non-empty list")
    env = {str(k): str(v) for k, v in _expect(where, ("env",), data.get("env", {}) or {}, dict, "'env'").items()}
    common_params = _expect(where, ("parameters",), data.get("parameters", {}) or {}, dict, "'parameters'")
    root = repo_root()
    nodes: list[NodeSpec] = []
    seen: dict[str, int] = {}
    for index, raw in enumerate(nodes_raw):
        at = ("nodes", index)
        if not isinstance(raw, dict):
            raise where.error(at, f"node #{index + 1} must be a mapping")
        for key in raw:
            if key not in NODE_KEYS:
                raise where.error(at + (key,), f"node #{index + 1}: unknown key {key!r} (expected one of {', '.join(sorted(NODE_KEYS))})")
        for key in ("name", "package", "executable"):
            if key not in raw:
                raise where.error(at, f"node #{index + 1}: missing required key {key!r}")
            _expect(where, at + (key,), raw[key], str, f"node #{index + 1}: {key!r}")
        name = raw["name"]
        namespace = _expect(where, at + ("namespace",), raw.get("namespace", "/"), str, f"node {name!r}: 'namespace'")
        if not namespace.startswith("/"):
            namespace = "/" + namespace
        fqn = (namespace.rstrip("/") + "/" + name) if namespace != "/" else "/" + name
        if fqn in seen:
            raise where.error(at + ("name",), f"node {fqn!r} is already defined at line {seen[fqn]}")
        seen[fqn] = where.line_of(at + ("name",))
        try:
            exe_path = resolve_executable(raw["package"], raw["executable"])
        except LookupError as exc:
            raise where.error(at + ("executable",), f"node {name!r}: {exc}") from None
        params = _expect(where, at + ("parameters",), raw.get("parameters", {}) or {}, dict, f"node {name!r}: 'parameters'")
        files_raw = _expect(where, at + ("param_files",), raw.get("param_files", []) or [], list, f"node {name!r}: 'param_files'")
        param_files = []
        for i, f in enumerate(files_raw):
            p = Path(f) if Path(f).is_absolute() else root / f
            if not p.is_file():
                raise where.error(at + ("param_files", i), f"node {name!r}: parameter file {str(f)!r} not found")
            param_files.append(p)
        args = _expect(where, at + ("arguments",), raw.get("arguments", []) or [], list, f"node {name!r}: 'arguments'")
        node_env = _expect(where, at + ("env",), raw.get("env", {}) or {}, dict, f"node {name!r}: 'env'")
        required = _expect(where, at + ("required",), raw.get("required", True), bool, f"node {name!r}: 'required'")
        timeout = _expect(where, at + ("ready_timeout",), raw.get("ready_timeout", 90.0), (int, float), f"node {name!r}: 'ready_timeout'")
        on_exit = _expect(where, at + ("on_exit",), raw.get("on_exit", "error"), str, f"node {name!r}: 'on_exit'")
        if on_exit not in ON_EXIT:
            raise where.error(at + ("on_exit",), f"node {name!r}: on_exit must be one of {', '.join(sorted(ON_EXIT))}, got {on_exit!r}")
        nice = raw.get("nice")
        if nice is not None:
            _expect(where, at + ("nice",), nice, int, f"node {name!r}: 'nice'")
            if not -20 <= nice <= 19:
                raise where.error(at + ("nice",), f"node {name!r}: nice must be within -20..19, got {nice}")
        grace = _expect(where, at + ("stop_grace_s",), raw.get("stop_grace_s", DEFAULT_STOP_GRACE_S), (int, float),
                        f"node {name!r}: 'stop_grace_s'")
        if isinstance(grace, bool) or not 0 < grace <= 600:
            raise where.error(at + ("stop_grace_s",), f"node {name!r}: stop_grace_s must be within (0, 600] s, got {grace}")
        nodes.append(
            NodeSpec(
                name=name,
                package=raw["package"],
                executable=raw["executable"],
                path=exe_path,
                namespace=namespace,
                parameters={**common_params, **params},
                param_files=tuple(param_files),
                arguments=tuple(str(a) for a in args),
                env={str(k): str(v) for k, v in node_env.items()},
                required=required,
                ready_timeout=float(timeout),
                on_exit=on_exit,
                nice=nice,
                stop_grace_s=float(grace),
            )
        )
    title = data.get("name") or Path(path).stem
    startup = _expect(where, ("startup",), data.get("startup", "sequential"), str, "'startup'")
    if startup not in STARTUP:
        raise where.error(("startup",), f"startup must be one of {', '.join(sorted(STARTUP))}, got {startup!r}")
    shutdown = _expect(where, ("shutdown",), data.get("shutdown", "parallel"), str, "'shutdown'")
    if shutdown not in SHUTDOWN:
        raise where.error(("shutdown",), f"shutdown must be one of {', '.join(sorted(SHUTDOWN))}, got {shutdown!r}")
    return LaunchFile(file=str(path), name=str(title), nodes=tuple(nodes), env=env, startup=startup, shutdown=shutdown)


__all__ = ["NodeSpec", "LaunchFile", "parse_launch_file", "resolve_executable", "ConfigError"]
