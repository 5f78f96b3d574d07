"""``tms-launch``: run the nodes of a YAML launch file, composed in containers or one process per node.

* Layouts (``--layout``, else ``$TMS_LAYOUT``, else ``composed``): ``composed`` runs the nodes that share a
  ``container`` key in one process with one executor (``python -m tms_launch.container``), as ROS 2
  component containers do, and every other node as its own process; ``per-node`` runs every node as its own
  process from its executable (debugging: one node's stack, CPU and log apart). ``--containers a,b`` starts
  only the nodes of those containers (one host's part of a site split over several computers).
* Starts processes in file order (a container where its first node is), each in its own process group,
  with stdout and stderr merged and every line prefixed ``[node_name]`` or ``[container_name]``.
* Waits until each process's nodes are visible on the ROS graph (name and namespace) before starting the
  next one (``startup: sequential``, the default) or starts all at once and then waits for each
  (``startup: parallel``, quicker for big launches), and prints progress lines
  ``[tms-launch] starting 2/3: listener`` / ``running 3/3``.
* Ctrl-C (SIGINT) or SIGTERM stops everything: SIGINT to every node, then SIGTERM after the node's
  ``stop_grace_s`` (default 2.5 s), then SIGKILL 1.5 s later (within 5 s for nodes with the default); with
  ``shutdown: reverse`` one node at a time, last started first, each gone before the next is signalled.
* When a required node exits (for any reason) the launcher stops the others and exits 1 naming it,
  except a node with ``on_exit: shutdown`` that exits 0: that ends the launch with 0 (a job is done).
* ``--record DIR`` adds a ``tms_ur_recorder`` node writing the site's topics into the new rosbag2 directory DIR
  (MCAP storage), stopped last but one (``launch_file.with_recorder``).
* ``--list`` prints the nodes of the file and exits; with ``--layout`` or ``--containers`` it prints the
  processes of that layout and their nodes.
* SIGUSR1 prints the stack of every thread of the launcher (to see what a launcher that does not stop waits for).
* When the launch stops it prints the CPU time (user + system, all threads) each process used and the total,
  in seconds and in cores over the launch's wall time (``/proc/<pid>/stat``, read once a second while a
  node runs, so a node that exits on its own is counted up to its last second). With a simulated-time
  report's real-time factor this gives the core-seconds the stack needs per simulated second.

Exit codes: 0 clean stop, 1 a required node died or did not come up, 2 bad launch file.
"""

from __future__ import annotations

import argparse
import ctypes
import faulthandler
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from tms_common.dds import use_platform_profiles
from tms_common.errors import ConfigError
from tms_launch.launch_file import (
    LAYOUT_ENV,
    LAYOUTS,
    LaunchFile,
    NodeSpec,
    ProcessSpec,
    parse_launch_file,
    processes,
    with_parameters,
    with_recorder,
)

SIGTERM_GRACE_S = 1.5
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """Child-side: receive SIGKILL if the launcher itself dies, so no node outlives it (SIGTERM is not
    enough: a node stuck in a callback ignores it)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        pass
    os.setpgrp()


def _child_setup(nice: int | None):  # a preexec_fn
    """Child-side setup before exec: :func:`_die_with_parent`, then the node's ``nice`` (set before exec, so
    every thread the node starts inherits it; renicing a running process changes its main thread only)."""

    def setup() -> None:
        _die_with_parent()
        if nice is None:
            return
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
        except OSError as exc:  # the node still starts; its output says why it runs at the launcher's niceness
            os.write(2, f"tms-launch: nice {nice} refused ({exc.strerror}; below the launcher's niceness needs "
                        f"root or CAP_SYS_NICE): running at nice {os.getpriority(os.PRIO_PROCESS, 0)}\n".encode())

    return setup


@dataclass
class Running:
    spec: ProcessSpec
    proc: subprocess.Popen[bytes]
    reader: threading.Thread
    ready: bool = False
    lines: list[str] = field(default_factory=list)
    cpu_s: float = 0.0  # user + system time of the process, last read


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` (all its threads) from /proc; None if it is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) ": fields[0] is the state
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_table(rows: list[tuple[str, float]], wall_s: float) -> list[str]:
    """Lines of the CPU summary: each node's seconds and share of one core, busiest first, then the total."""
    wall_s = max(wall_s, 1e-9)
    width = max((len(name) for name, _ in rows), default=0)
    lines = [f"  {name:<{width}}  {cpu:8.1f} s  {cpu / wall_s * 100:5.1f} % of a core"
             for name, cpu in sorted(rows, key=lambda r: -r[1])]
    total = sum(cpu for _, cpu in rows)
    lines.append(f"  {'total':<{width}}  {total:8.1f} s  {total / wall_s:5.2f} cores over {wall_s:.1f} s")
    return lines


class Launcher:
    """Starts, watches and stops the processes of one launch file."""

    def __init__(self, launch: LaunchFile, *, out=None, layout: str = "composed",
                 containers: list[str] | None = None) -> None:
        self.launch = launch
        self.processes = processes(launch, layout, containers)
        self.layout = layout
        self.out = out or sys.stdout
        self.running: list[Running] = []
        self._stop = threading.Event()
        self._print_lock = threading.Lock()
        self._graph_node = None
        self._began = time.monotonic()
        self._next_cpu_read = 0.0

    # -- output ---------------------------------------------------------------------------------
    def log(self, text: str) -> None:
        with self._print_lock:
            print(f"[tms-launch] {text}", file=self.out, flush=True)

    def _pump(self, run: Running) -> None:
        assert run.proc.stdout is not None
        for raw in iter(run.proc.stdout.readline, b""):
            line = raw.decode(errors="replace").rstrip("\n")
            with self._print_lock:
                print(f"[{run.spec.name}] {line}", file=self.out, flush=True)

    # -- graph ----------------------------------------------------------------------------------
    def _graph(self):
        if self._graph_node is None:
            import rclpy
            from rclpy.signals import SignalHandlerOptions

            use_platform_profiles()
            # The launcher owns SIGINT/SIGTERM (to stop its children in order), not rclpy.
            rclpy.init(
                args=["tms-launch", "--ros-args", "--disable-rosout-logs"],
                signal_handler_options=SignalHandlerOptions.NO,
            )
            # a hidden name (leading "_"): `ros2 node list` shows the nodes of the launch, not the launcher's probe
            self._graph_node = rclpy.create_node("_tms_launch_monitor", start_parameter_services=False,
                                                 enable_rosout=False)
        return self._graph_node

    def visible(self, spec: NodeSpec | ProcessSpec) -> bool:
        """True when the node (every node of the process) is on the ROS graph under its name and namespace."""
        graph = set(self._graph().get_node_names_and_namespaces())
        nodes = spec.nodes if isinstance(spec, ProcessSpec) else (spec,)
        return all((n.name, n.namespace) in graph for n in nodes)

    # -- lifecycle ------------------------------------------------------------------------------
    def start(self, spec: ProcessSpec) -> Running:
        env = {**os.environ, **self.launch.env, **spec.env, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen(
            list(spec.command),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            preexec_fn=_child_setup(spec.nice),  # needed for PDEATHSIG, a process group, nice
        )
        run = Running(spec=spec, proc=proc, reader=threading.Thread(target=lambda: None))
        run.reader = threading.Thread(target=self._pump, args=(run,), daemon=True, name=f"pump-{spec.name}")
        run.reader.start()
        self.running.append(run)
        return run

    def _dead_required(self) -> Running | None:
        for run in self.running:
            if run.spec.required and run.proc.poll() is not None and not self._finished_job(run):
                return run
        return None

    @staticmethod
    def _finished_job(run: Running) -> bool:
        return run.spec.on_exit == "shutdown" and run.proc.returncode == 0

    def _wait_ready(self, run: Running, started: float | None = None) -> str | None:
        """Wait until ``run`` is visible; returns an error text when it died or timed out."""
        deadline = (started or time.monotonic()) + run.spec.ready_timeout
        while time.monotonic() < deadline and not self._stop.is_set():
            if run.proc.poll() is not None:
                if self._finished_job(run):
                    return None
                return f"{self._kind(run)} {run.spec.name!r} exited with code {run.proc.returncode} before it came up"
            dead = self._dead_required()
            if dead is not None:
                return f"required {self._kind(dead)} {dead.spec.name!r} exited with code {dead.proc.returncode}"
            if self.visible(run.spec):
                run.ready = True
                return None
            time.sleep(0.05)
        if self._stop.is_set():
            return None
        missing = [n.name for n in run.spec.nodes if not self.visible(n)] if run.spec.container else []
        what = f" (missing: {', '.join(missing)})" if missing else ""
        return (f"{self._kind(run)} {run.spec.name!r} did not appear on the ROS graph within "
                f"{run.spec.ready_timeout:g} s{what}")

    @staticmethod
    def _kind(run: Running) -> str:
        return "container" if run.spec.container else "node"

    def read_cpu(self) -> None:
        """Record each live node's CPU time so far (a node that exits keeps its last reading)."""
        for run in self.running:
            cpu = process_cpu_seconds(run.proc.pid)
            if cpu is not None:
                run.cpu_s = cpu

    def report_cpu(self) -> None:
        if not self.running:
            return
        rows: dict[str, float] = {}
        for run in self.running:
            key = f"{run.spec.name} ({len(run.spec.nodes)} nodes)" if run.spec.container else run.spec.nodes[0].fqn
            rows[key] = rows.get(key, 0.0) + run.cpu_s
        wall = time.monotonic() - self._began
        self.log(f"CPU time per process ({self.layout} layout; user + system, all threads):\n"
                 + "\n".join(cpu_table(list(rows.items()), wall)))

    def _stop_group(self, alive: list[Running]) -> None:
        """Stop these nodes together: SIGINT, SIGTERM after each one's stop_grace_s, SIGKILL 1.5 s later."""
        escalation = {id(r): [(signal.SIGINT, 0.0), (signal.SIGTERM, r.spec.stop_grace_s),
                              (signal.SIGKILL, r.spec.stop_grace_s + SIGTERM_GRACE_S)] for r in alive}
        began = time.monotonic()
        while alive:
            elapsed = time.monotonic() - began
            for r in alive:
                steps = escalation[id(r)]
                while steps and elapsed >= steps[0][1]:
                    sig, _ = steps.pop(0)
                    if sig != signal.SIGINT:
                        self.log(f"{r.spec.name} still running {elapsed:.1f} s after SIGINT; sending {sig.name}")
                    try:
                        os.killpg(r.proc.pid, sig)
                    except ProcessLookupError:
                        pass
            time.sleep(0.02)
            # after its SIGKILL a process is given 0.5 s to be reaped (one stuck in the kernel is left behind)
            alive = [r for r in alive if r.proc.poll() is None
                     and (escalation[id(r)] or elapsed < r.spec.stop_grace_s + SIGTERM_GRACE_S + 0.5)]

    def stop_all(self) -> None:
        """SIGINT, then SIGTERM after each node's ``stop_grace_s``, then SIGKILL 1.5 s later."""
        self.read_cpu()
        self.report_cpu()
        alive = [r for r in self.running if r.proc.poll() is None]
        one_at_a_time = self.launch.shutdown == "reverse"
        if one_at_a_time:
            alive.reverse()
        if alive:
            order = " (last started first, one at a time)" if one_at_a_time else ""
            self.log(f"stopping {len(alive)} process(es){order}: {', '.join(r.spec.name for r in alive)}")
        for group in ([r] for r in alive) if one_at_a_time else [alive]:
            self._stop_group(group)
        for r in self.running:
            r.reader.join(timeout=0.5)

    def run(self) -> int:
        """Start every node, then supervise until a stop signal or a required node dies."""
        nodes = self.processes
        error: str | None = None
        try:
            if self.launch.startup == "parallel":
                began = time.monotonic()
                for index, spec in enumerate(nodes, 1):
                    self.log(f"starting {index}/{len(nodes)}: {spec.name} ({spec.what})")
                    self.start(spec)
                for run in list(self.running):
                    if self._stop.is_set():
                        break
                    error = self._wait_ready(run, began)
                    if error:
                        break
                    up = [r.spec.name for r in self.running if r.ready]
                    self.log(f"running {len(up)}/{len(nodes)}: {', '.join(up)}")
            for index, spec in enumerate(nodes if self.launch.startup == "sequential" else (), 1):
                if self._stop.is_set():
                    break
                self.log(f"starting {index}/{len(nodes)}: {spec.name} ({spec.what})")
                run = self.start(spec)
                error = self._wait_ready(run)
                if error:
                    break
                up = [r.spec.name for r in self.running if r.ready]
                self.log(f"running {len(up)}/{len(nodes)}: {', '.join(up)}")
            if not error and not self._stop.is_set():
                count = sum(len(p.nodes) for p in nodes)
                self.log(f"all {count} node(s) of {self.launch.name!r} are up; Ctrl-C stops them "
                         f"({len(nodes)} process(es), {self.layout} layout)")
            while not error and not self._stop.is_set():
                done = next((r for r in self.running if r.proc.poll() is not None and self._finished_job(r)), None)
                if done is not None:
                    self.log(f"{done.spec.name} finished; stopping the launch")
                    break
                dead = self._dead_required()
                if dead is not None:
                    error = f"required {self._kind(dead)} {dead.spec.name!r} exited with code {dead.proc.returncode}"
                    break
                for r in self.running:
                    if not r.spec.required and r.proc.poll() is not None and r.ready:
                        self.log(f"optional {self._kind(r)} {r.spec.name!r} exited with code {r.proc.returncode}")
                        r.ready = False
                if time.monotonic() >= self._next_cpu_read:
                    self._next_cpu_read = time.monotonic() + 1.0
                    self.read_cpu()
                self._stop.wait(0.1)
        finally:
            self.stop_all()
            if self._graph_node is not None:
                import rclpy

                self._graph_node.destroy_node()
                rclpy.try_shutdown()
        if error:
            self.log(f"ERROR: {error}")
            return 1
        self.log("stopped")
        return 0

    def request_stop(self, *_args: object) -> None:
        self._stop.set()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="tms-launch", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("launch_file", help="YAML launch file, e.g. config/launch/demo_three.yaml")
    parser.add_argument("--list", action="store_true", help="print the nodes of the file and exit")
    parser.add_argument("--layout", choices=LAYOUTS, default=None,
                        help=f"composed: a container's nodes in one process; per-node: every node its own process "
                             f"(default: ${LAYOUT_ENV}, else composed)")
    parser.add_argument("--containers", default=None, metavar="A,B",
                        help="start only the nodes of these containers (comma-separated)")
    parser.add_argument("--param", action="append", default=[], metavar="NODE:KEY=VALUE",
                        help="set a node's parameter (VALUE as YAML); repeatable, e.g. "
                             "--param tms_sp_sensing:blackboard_records=[SAMPLE_BLACKBOARD_SHIMIZU]")
    parser.add_argument("--record", default=None, metavar="DIR",
                        help="record the site's topics into the new rosbag2 directory DIR (MCAP; tms_ur_recorder)")
    opts = parser.parse_args(argv)
    path = Path(opts.launch_file)
    layout = opts.layout or os.environ.get(LAYOUT_ENV) or "composed"
    containers = [c.strip() for c in opts.containers.split(",") if c.strip()] if opts.containers is not None else None
    try:
        launch = with_parameters(parse_launch_file(path), opts.param)
        if opts.record is not None:
            if containers is not None:
                raise ConfigError("--record with --containers: the recorder belongs to no container; start it on "
                                  "one host with ros2 run tms_ur tms_ur_recorder --ros-args -p output:=DIR")
            launch = with_recorder(launch, opts.record)
        launcher = Launcher(launch, layout=layout, containers=containers)
    except ConfigError as exc:
        print(f"tms-launch: {exc}", file=sys.stderr, flush=True)
        return 2
    if opts.list:
        if opts.layout is None and containers is None:
            for spec in launch.nodes:
                flag = "required" if spec.required else "optional"
                print(f"{spec.fqn}\t{spec.package}/{spec.executable}\t{flag}\t{spec.container or '-'}")
            return 0
        for proc in launcher.processes:
            print(f"{proc.name}\t{'container' if proc.container else 'node'}\t"
                  + " ".join(n.fqn for n in proc.nodes))
        return 0
    # `kill -USR1 <pid>` prints every thread's stack: what a launcher that does not stop is waiting for
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    signal.signal(signal.SIGINT, launcher.request_stop)
    signal.signal(signal.SIGTERM, launcher.request_stop)
    return launcher.run()


if __name__ == "__main__":
    sys.exit(main())
