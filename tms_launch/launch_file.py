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
        container: site_server       # optional: the nodes that name one container run in one process on
                                     # one executor (the composed layout, :func:`processes`); without it a
                                     # node is its own process in every layout

Layouts (:func:`processes`): ``composed`` (the default) runs each container as one process
(``python -m tms_launch.container``), ``per-node`` runs every node as its own process from its executable,
for debugging; the same file serves both. What a node's keys mean for a container process:

* ``parameters``, ``param_files``, ``namespace``, ``use_sim_time``: per node, as before (each node gets its
  own ``--ros-args``);
* ``env``: per process; the container's environment is the union of its nodes' (a key given two values is
  an error);
* ``nice``: per process; the container runs at the lowest (most favoured) ``nice`` of its nodes;
* ``required``: the container is required when one of its nodes is; ``on_exit: shutdown``: the node's
  ``SystemExit(0)`` ends the container with 0, which ends the launch;
* ``stop_grace_s``: the container's is the sum of its nodes' (they are stopped one after another, last
  started first, each with its stop hooks run and then destroyed: the supervisor writes its report and the
  manager cancels before the servers, controllers and plant of the same process go);
* ``ready_timeout``: the container's is the longest of its nodes'; ``arguments`` are not allowed (a node
  class in a container gets ROS arguments only).

Every problem (malformed YAML, unknown key, unknown executable, duplicate name) is a
:class:`~tms_common.errors.ConfigError` naming the file and line; nothing is started.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from com3_can.bus import IN_PROCESS_ENV
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
    "container",
}
TOP_KEYS = {"name", "nodes", "env", "parameters", "startup", "shutdown"}
STARTUP = {"sequential", "parallel"}
SHUTDOWN = {"parallel", "reverse"}
ON_EXIT = {"error", "shutdown"}
LAYOUTS = ("composed", "per-node")
LAYOUT_ENV = "TMS_LAYOUT"  # the layout when tms-launch is not given --layout
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
    container: str | None = None

    @property
    def fqn(self) -> str:
        """Fully qualified node name, e.g. ``/demo/talker``."""
        return (self.namespace.rstrip("/") + "/" + self.name) if self.namespace != "/" else "/" + self.name

    def command(self) -> list[str]:
        """The command line that starts this node, as ``ros2 run`` would plus our remaps."""
        return [str(self.path), *self.arguments, *self.ros_args()]

    def ros_args(self) -> list[str]:
        """``--ros-args`` and what follows: name, namespace, parameters (a process's or one node's ``cli_args``)."""
        cmd = ["--ros-args", "-r", f"__node:={self.name}"]
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
    parameters: dict[str, Any] = field(default_factory=dict)  # the file's top-level parameters (every node's)

    @property
    def containers(self) -> tuple[str, ...]:
        """The container names of the file, in the order their first node appears."""
        return tuple(dict.fromkeys(n.container for n in self.nodes if n.container))


def with_parameters(launch: LaunchFile, overrides: list[str]) -> LaunchFile:
    """``launch`` with node parameters set from ``NODE:KEY=VALUE`` texts (tms-launch ``--param``): NODE is a
    node's name or fully qualified name (every node of that name), VALUE is YAML (``[a, b]``, ``3.0``, ``""``).
    A node or text that does not fit is a ConfigError naming it."""
    nodes = list(launch.nodes)
    for text in overrides:
        target, sep, assignment = text.partition(":")
        key, eq, value_text = assignment.partition("=")
        if not sep or not eq or not target or not key:
            raise ConfigError(f"--param {text!r}: expected NODE:KEY=VALUE (e.g. tms_sp_sensing:rate_hz=1.0)")
        try:
            value = yaml.safe_load(value_text) if value_text.strip() else ""
        except yaml.YAMLError as exc:
            raise ConfigError(f"--param {text!r}: VALUE is not YAML: {exc}") from None
        hits = [i for i, n in enumerate(nodes) if target in (n.name, n.fqn)]
        if not hits:
            raise ConfigError(f"--param {text!r}: {launch.file} has no node {target!r} "
                              f"(nodes: {', '.join(n.fqn for n in nodes)})")
        for i in hits:
            nodes[i] = dataclasses.replace(nodes[i], parameters={**nodes[i].parameters, key: value})
    return dataclasses.replace(launch, nodes=tuple(nodes))


RECORDER_NAME = "tms_ur_recorder"
RECORDER_STOP_GRACE_S = 15.0  # closing the MCAP file (its index and summary) of a long run on busy cores


def with_recorder(launch: LaunchFile, output: str | Path) -> LaunchFile:
    """``launch`` plus a ``tms_ur_recorder`` node recording the site's topics into the new directory ``output``
    (tms-launch ``--record``): a process of its own, placed right after the file's first process (the plant in
    the simulation launches), so ``shutdown: reverse`` stops it last but one, after every node it records and
    before the clock's source; it takes the file's top-level parameters (``use_sim_time``: log time on the
    simulated clock). An existing ``output`` or a node already named so is a ConfigError, nothing started."""
    out = Path(output)
    out = out if out.is_absolute() else Path.cwd() / out
    if out.exists():
        raise ConfigError(f"--record {output}: {out} exists already; a recording needs a new directory")
    if not out.parent.is_dir():
        raise ConfigError(f"--record {output}: the parent directory {out.parent} does not exist")
    if any(n.name == RECORDER_NAME for n in launch.nodes):
        raise ConfigError(f"--record: {launch.file} has a node named {RECORDER_NAME!r} already")
    try:
        path = resolve_executable("tms_ur", RECORDER_NAME)
    except LookupError as exc:
        raise ConfigError(f"--record: {exc}") from None
    spec = NodeSpec(name=RECORDER_NAME, package="tms_ur", executable=RECORDER_NAME, path=path,
                    parameters={**launch.parameters, "output": str(out)}, stop_grace_s=RECORDER_STOP_GRACE_S)
    nodes = list(launch.nodes)
    first = nodes[0].container if nodes else None
    # after the first process: after every node of the first node's container (or after the first node alone)
    at = 1 + max((i for i, n in enumerate(nodes) if first is not None and n.container == first), default=0)
    nodes.insert(min(at, len(nodes)), spec)
    return dataclasses.replace(launch, nodes=tuple(nodes))


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a launch in a layout: a node run from its executable, or a container of nodes.

    ``name`` is the node's name or the container's; the other fields are what the launcher needs per process
    (the rules for a container are in the module docstring).
    """

    name: str
    nodes: tuple[NodeSpec, ...]
    command: tuple[str, ...]
    container: str | None = None
    env: dict[str, str] = field(default_factory=dict)
    nice: int | None = None
    required: bool = True
    on_exit: str = "error"
    stop_grace_s: float = DEFAULT_STOP_GRACE_S
    ready_timeout: float = 90.0

    @property
    def what(self) -> str:
        """What the progress lines show: ``package/executable``, or ``container of n1, n2``."""
        if self.container is None:
            return f"{self.nodes[0].package}/{self.nodes[0].executable}"
        return "container of " + ", ".join(n.name for n in self.nodes)


def _single(spec: NodeSpec) -> ProcessSpec:
    return ProcessSpec(name=spec.name, nodes=(spec,), command=tuple(spec.command()), env=dict(spec.env),
                       nice=spec.nice, required=spec.required, on_exit=spec.on_exit,
                       stop_grace_s=spec.stop_grace_s, ready_timeout=spec.ready_timeout)


def in_process_can_links(nodes: tuple[NodeSpec, ...]) -> list[str]:
    """The machines whose plant (``sim_plant``) and COM3 converter (``com3_bridge`` with ``machine`` set) are among
    ``nodes``: in one process their CAN link is in-process (:func:`com3_can.bus.link_config`)."""
    if not any((n.package, n.executable) == ("sim_bridge", "sim_plant") for n in nodes):
        return []
    return sorted({str(n.parameters["machine"]) for n in nodes
                   if (n.package, n.executable) == ("com3_can", "com3_bridge") and "machine" in n.parameters})


def _container(launch: LaunchFile, name: str, nodes: tuple[NodeSpec, ...]) -> ProcessSpec:
    env: dict[str, str] = {}
    for node in nodes:
        for key, value in node.env.items():
            if key in env and env[key] != value:
                owner = next(n.name for n in nodes if n.env.get(key) == env[key])
                raise ConfigError(f"{launch.file}: container {name!r}: env {key!r} is {env[key]!r} for node "
                                  f"{owner!r} and {value!r} for node {node.name!r} (one process, one environment)")
            env[key] = value
    for node in nodes:
        if node.arguments:
            raise ConfigError(f"{launch.file}: node {node.name!r} of container {name!r} has 'arguments': a node in a "
                              "container gets ROS arguments only (remove them or the container key)")
    machines = in_process_can_links(nodes)
    if machines:
        env[IN_PROCESS_ENV] = ",".join(machines)
    nices = [n.nice for n in nodes if n.nice is not None]
    payload = json.dumps([{"name": n.name, "package": n.package, "executable": n.executable,
                           "on_exit": n.on_exit, "ros_args": n.ros_args()} for n in nodes])
    return ProcessSpec(
        name=name, nodes=nodes, container=name,
        command=(sys.executable, "-m", "tms_launch.container", name, payload),
        env=env, nice=min(nices) if nices else None, required=any(n.required for n in nodes),
        on_exit="shutdown" if any(n.on_exit == "shutdown" for n in nodes) else "error",
        stop_grace_s=sum(n.stop_grace_s for n in nodes), ready_timeout=max(n.ready_timeout for n in nodes),
    )


def processes(
    launch: LaunchFile, layout: str = "composed", containers: list[str] | None = None
) -> tuple[ProcessSpec, ...]:
    """The processes that run ``launch`` in ``layout``, in start order.

    ``layout``: ``composed`` (each container one process, other nodes one each) or ``per-node`` (every node
    its own process). ``containers``: only the nodes of these containers (a host's part of a site).

    Raises:
        ConfigError: unknown layout or container name, or a container whose nodes cannot share a process.
    """
    if layout not in LAYOUTS:
        raise ConfigError(f"unknown layout {layout!r}: expected one of {', '.join(LAYOUTS)}")
    nodes = launch.nodes
    if containers is not None:
        unknown = [c for c in containers if c not in launch.containers]
        if unknown or not containers:
            raise ConfigError(f"{launch.file}: no container(s) {unknown or containers!r}; the file has "
                              f"{', '.join(launch.containers) or 'none'}")
        nodes = tuple(n for n in nodes if n.container in containers)
    if layout == "per-node":
        return tuple(_single(n) for n in nodes)
    out: list[ProcessSpec] = []
    done: set[str] = set()
    for node in nodes:
        if node.container is None:
            out.append(_single(node))
        elif node.container not in done:
            done.add(node.container)
            out.append(_container(launch, node.container, tuple(n for n in nodes if n.container == node.container)))
    return tuple(out)


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
        raise LookupError(
            f"package {package!r} is not in the ament index ({os.environ['AMENT_PREFIX_PATH']})"
        ) from None
    path = prefix / "lib" / package / executable
    if not (path.is_file() and os.access(path, os.X_OK)):
        known = sorted(p.name for p in (prefix / "lib" / package).glob("*") if os.access(p, os.X_OK))
        raise LookupError(f"package {package!r} has no executable {executable!r} (known: {', '.join(known) or 'none'})")
    return path


def _expect(where: Where, path: tuple[Any, ...], value: Any, kind: type | tuple[type, ...], what: str) -> Any:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    # bool is an int in Python; a YAML `true` must not pass where a number is expected.
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise where.error(
            path, f"{what} must be {getattr(kind, '__name__', kind)}, got {type(value).__name__} {value!r}"
        )
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
                raise where.error(
                    at + (key,),
                    f"node #{index + 1}: unknown key {key!r} (expected one of {', '.join(sorted(NODE_KEYS))})",
                )
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
        params = _expect(
            where, at + ("parameters",), raw.get("parameters", {}) or {}, dict, f"node {name!r}: 'parameters'"
        )
        files_raw = _expect(
            where, at + ("param_files",), raw.get("param_files", []) or [], list, f"node {name!r}: 'param_files'"
        )
        param_files = []
        for i, f in enumerate(files_raw):
            p = Path(f) if Path(f).is_absolute() else root / f
            if not p.is_file():
                raise where.error(at + ("param_files", i), f"node {name!r}: parameter file {str(f)!r} not found")
            param_files.append(p)
        args = _expect(where, at + ("arguments",), raw.get("arguments", []) or [], list, f"node {name!r}: 'arguments'")
        node_env = _expect(where, at + ("env",), raw.get("env", {}) or {}, dict, f"node {name!r}: 'env'")
        required = _expect(where, at + ("required",), raw.get("required", True), bool, f"node {name!r}: 'required'")
        timeout = _expect(
            where,
            at + ("ready_timeout",),
            raw.get("ready_timeout", 90.0),
            (int, float),
            f"node {name!r}: 'ready_timeout'",
        )
        on_exit = _expect(where, at + ("on_exit",), raw.get("on_exit", "error"), str, f"node {name!r}: 'on_exit'")
        if on_exit not in ON_EXIT:
            raise where.error(
                at + ("on_exit",),
                f"node {name!r}: on_exit must be one of {', '.join(sorted(ON_EXIT))}, got {on_exit!r}",
            )
        nice = raw.get("nice")
        if nice is not None:
            _expect(where, at + ("nice",), nice, int, f"node {name!r}: 'nice'")
            if not -20 <= nice <= 19:
                raise where.error(at + ("nice",), f"node {name!r}: nice must be within -20..19, got {nice}")
        grace = _expect(where, at + ("stop_grace_s",), raw.get("stop_grace_s", DEFAULT_STOP_GRACE_S), (int, float),
                        f"node {name!r}: 'stop_grace_s'")
        if isinstance(grace, bool) or not 0 < grace <= 600:
            raise where.error(
                at + ("stop_grace_s",), f"node {name!r}: stop_grace_s must be within (0, 600] s, got {grace}"
            )
        container = raw.get("container")
        if container is not None:
            _expect(where, at + ("container",), container, str, f"node {name!r}: 'container'")
            if not container.isidentifier():
                raise where.error(
                    at + ("container",), f"node {name!r}: container name {container!r} must be an identifier"
                )
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
                container=container,
            )
        )
    title = data.get("name") or Path(path).stem
    startup = _expect(where, ("startup",), data.get("startup", "sequential"), str, "'startup'")
    if startup not in STARTUP:
        raise where.error(("startup",), f"startup must be one of {', '.join(sorted(STARTUP))}, got {startup!r}")
    shutdown = _expect(where, ("shutdown",), data.get("shutdown", "parallel"), str, "'shutdown'")
    if shutdown not in SHUTDOWN:
        raise where.error(("shutdown",), f"shutdown must be one of {', '.join(sorted(SHUTDOWN))}, got {shutdown!r}")
    return LaunchFile(file=str(path), name=str(title), nodes=tuple(nodes), env=env, startup=startup, shutdown=shutdown,
                      parameters=dict(common_params))


__all__ = ["NodeSpec", "LaunchFile", "ProcessSpec", "LAYOUTS", "LAYOUT_ENV", "processes", "parse_launch_file",
           "resolve_executable", "ConfigError"]
