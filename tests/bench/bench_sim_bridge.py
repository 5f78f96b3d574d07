"""sim_bridge: plant speed (real-time factor), plant-core CPU before/after, and the jitter of its 10 ms COM3 frames.

1. Core plant, both machines and soil, a scripted dig cycle on the ZX200 while the IC120 drives:
   simulated seconds per wall second (goal >= 50x).
2. Plant-core CPU per simulated second (core-s per sim-s) for the paper site (``config/sim/plant.yaml``) and the
   ten machines of ``config/launch/original_machines.yaml`` (``config/sim/original_plant.yaml``): each run is a
   child process (:mod:`tests.bench.sim_probe`) timing its stepping loop with ``time.process_time``; the ZX200
   digs the scripted cycle, the IC120 stands at P1 under the dumps, the other eight machines get simple motion
   commands (listed in the printout). Median of 3 runs per tree.
   With ``BENCH_BASE=<rev>`` the same probe also runs against a temporary ``git worktree add --detach`` of that
   revision (under /tmp, removed afterwards; the venv is shared, ``PYTHONPATH`` selects the tree and
   ``AMENT_PREFIX_PATH`` is dropped so each tree reads its own ``config/``): a base and a current probe are built
   side by side and step in turns of 1 s simulated, so both see the same outside load; it prints base, current,
   current/base of the medians and the ratio of each run pair. Only same-run ratios mean anything: the machine's
   speed varies 2-3x between days. ``BENCH_BASE=HEAD`` compares uncommitted changes against the last commit; with
   no plant-core change (HEAD c0f87d3 against itself, load average 12) the run pairs gave 0.96-1.04 (paper site)
   and 0.94-0.97 (ten machines): differences within ~5 % are not resolved.
3. The same as 1 with the COM3 CAN I/O (all state frames encoded at their DBC cycles onto virtual buses).
4. ``sim_plant`` as a separate process in real-time mode on udp_multicast: arrival period of the 10 ms
   ``Front_Angle`` frames measured in this process (p99 |period - 10 ms|; goal < 2 ms).

Run::

    .venv/bin/python -m tests.bench sim_bridge                      # current tree only
    BENCH_BASE=99c87b6 .venv/bin/python -m tests.bench sim_bridge   # before (99c87b6) and after, side by side
    make bench BENCH_ARGS=sim_bridge                                # the same in the isolated network namespace
"""

from __future__ import annotations

import json
import os
import select
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from sim_bridge.plant import Plant
from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
from tests.bench.stats import percentile, summary_ms
from tests.rosproc import Proc, executable, free_can_ports, isolated_domain, ros_env

SIM_SECONDS = 120.0
REPO = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).with_name("sim_probe.py")
#: plant-core sites: label, plant YAML under config/
SITES = (("paper site", "sim/plant.yaml"), ("original_machines.yaml", "sim/original_plant.yaml"))
CORE_SIM_S = 36.0  # [s] simulated per probe run: one dig cycle (6 poses) on today's dynamic plant
CORE_RUNS = 3  # per tree and site
#: [s] simulated per turn: base and current take turns in chunks this short, so both see the same outside load
CORE_CHUNK_S = 1.0


def _drive(plant: Plant, io=None) -> float:
    names = plant.excavator.front.names
    plant.carrier.set_centre_velocity(1.0, 0.1)
    steps = int(SIM_SECONDS / plant.dt)
    k = 0
    start = time.perf_counter()
    for _ in range(steps):
        q = dict(zip(names, plant.excavator.front.q, strict=True))
        target = DIG_CYCLE[k % len(DIG_CYCLE)]
        if pose_reached(q, target, tol=0.05):
            k += 1
        plant.excavator.set_front_velocity(servo_velocity(q, target))
        if io is not None:
            io.poll()
            io.watchdog()
        plant.step()
        if io is not None:
            io.emit()
    return time.perf_counter() - start


def _core() -> str:
    plant = Plant()
    plant.set_truth("ic120", 1.2, 6.5, 0.0, {"vessel_joint": 0.0})
    wall = _drive(plant)
    return (f"plant core (ZX200 dig cycle + IC120 driving + soil, dt {plant.dt * 1e3:.0f} ms): "
            f"{SIM_SECONDS:.0f} s simulated in {wall:.2f} s = {SIM_SECONDS / wall:.0f}x real time "
            f"({wall / (SIM_SECONDS / plant.dt) * 1e6:.0f} us/step; dug {plant.soil.dug:.2f} m^3)")


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(REPO), *args], check=True, capture_output=True, text=True).stdout.strip()


def _check_original_plant() -> None:
    """original_plant.yaml must be the plant of original_machines.yaml: its sim_plant config, the same machines."""
    launch, plant = REPO / "config/launch/original_machines.yaml", REPO / "config/sim/original_plant.yaml"
    nodes = yaml.safe_load(launch.read_text())["nodes"]
    sim = [n for n in nodes if n.get("executable") == "sim_plant"]
    if len(sim) != 1 or sim[0].get("parameters", {}).get("config") != "config/sim/original_plant.yaml":
        raise RuntimeError(f"{launch}: sim_plant does not run config/sim/original_plant.yaml")
    bridged = {n["parameters"]["machine"] for n in nodes if n.get("executable") == "com3_bridge"}
    simulated = set(yaml.safe_load(plant.read_text())["machines"])
    if bridged != simulated or len(simulated) != 10:
        raise RuntimeError(f"{plant}: machines {sorted(simulated)} are not the ten of {launch} {sorted(bridged)}")


class _Probe:
    """A ``sim_probe.py --serve`` child on one tree: built at start, then stepped chunk by chunk on request."""

    def __init__(self, tree: Path, plant: str) -> None:
        env = {k: v for k, v in os.environ.items() if k != "AMENT_PREFIX_PATH"}  # else config/ = the checkout's
        env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [os.environ.get("PYTHONPATH")])])
        self.what = f"sim_probe on {tree} ({plant})"
        self._dir = tempfile.TemporaryDirectory(prefix="bench_sim_probe_")  # MuJoCo's MUJOCO_LOG.TXT lands here
        self._err = open(Path(self._dir.name) / "stderr.txt", "w+")
        self.proc = subprocess.Popen(
            [sys.executable, str(PROBE), "--tree", str(tree), "--plant", plant, "--serve"],
            cwd=self._dir.name, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err, text=True,
        )

    def ask(self, command: str | None = None, timeout: float = 300.0) -> dict:
        if command is not None:
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        line = self.proc.stdout.readline() if ready else ""
        if not line:
            self.proc.kill()
            self._err.seek(0)
            tail = self._err.read().strip().splitlines()[-1:]
            raise RuntimeError(f"{self.what}: no answer to {command or 'start'!r} within {timeout:.0f} s "
                               f"(exit {self.proc.wait()}): {' '.join(tail)}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for f in (self.proc.stdin, self.proc.stdout, self._err):
            f.close()
        self._dir.cleanup()


def _core_cpu() -> list[str]:
    """Plant-core CPU per simulated second, current tree (and BENCH_BASE's, alternating), median of CORE_RUNS."""
    _check_original_plant()
    base_rev = os.environ.get("BENCH_BASE")
    trees: dict[str, Path] = {"current": REPO}
    lines = []
    tmp = None
    if base_rev is not None:
        try:
            sha = _git("rev-parse", "--verify", f"{base_rev or 'HEAD'}^{{commit}}")
        except subprocess.CalledProcessError:
            raise RuntimeError(f"BENCH_BASE={base_rev!r} is not a commit of {REPO}") from None
        dirty = _git("status", "--short", "--untracked-files=no", "--", "sim_bridge", "tms_model", "tms_common",
                     "config").splitlines()
        lines.append(f"base = {_git('log', '-1', '--format=%h %s', sha)}; current = working tree "
                     f"(HEAD {_git('rev-parse', '--short', 'HEAD')}, {len(dirty)} uncommitted file(s) in "
                     "sim_bridge/ tms_model/ tms_common/ config/)")
        tmp = Path(tempfile.mkdtemp(prefix="bench_sim_base_"))
    try:
        if tmp is not None:
            _git("worktree", "add", "--detach", str(tmp / "tree"), sha)
            trees = {"base": tmp / "tree", "current": REPO}
        runs: dict[tuple[str, str], list[dict]] = {}
        for _rep in range(CORE_RUNS):
            for _, plant in SITES:
                probes = {which: _Probe(tree, plant) for which, tree in trees.items()}  # they build in parallel
                try:
                    dt = [p.ask()["dt"] for p in probes.values()][0]  # every probe answers when built
                    order = list(probes)
                    for i in range(round(CORE_SIM_S / CORE_CHUNK_S)):
                        for which in order if i % 2 == 0 else reversed(order):  # alternate who goes first
                            probes[which].ask(f"step {round(CORE_CHUNK_S / dt)}")
                    for which, p in probes.items():
                        runs.setdefault((which, plant), []).append(p.ask("end"))
                finally:
                    for p in probes.values():
                        p.close()
    finally:
        if tmp is not None:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tmp / "tree")],
                           capture_output=True, check=False)
            subprocess.run(["git", "-C", str(REPO), "worktree", "prune"], capture_output=True, check=False)
            subprocess.run(["rm", "-rf", str(tmp)], check=False)
    first = runs[("current", SITES[1][1])][0]
    alt = f", base and current in turns of {CORE_CHUNK_S:.0f} s simulated" if tmp else ""
    lines.insert(0, f"plant core CPU (child process, time.process_time of {CORE_SIM_S:.0f} s simulated, "
                    f"median of {CORE_RUNS} runs per tree{alt}): "
                    f"{first['excavator']} digs DIG_CYCLE, {first['carrier']} stands at P1; others "
                    f"({', '.join(first['moving'])}) move: tracks on a 2 m circle, front/vessel/swing/blade "
                    "back and forth every 8 s")
    for label, plant in SITES:
        med, detail = {}, []
        for which in trees:
            rs = runs[(which, plant)]
            per = sorted(r["cpu_s"] / r["sim_s"] * 1e3 for r in rs)
            med[which] = statistics.median(per)
            r = rs[0]
            detail.append(f"    {which:7s} runs {' '.join(f'{x:.1f}' for x in per)} core-ms per simulated s "
                          f"({med[which] * r['sim_s'] / r['steps'] * 1e3:.0f} us/step); in {r['sim_s']:.0f} s: "
                          f"{r['poses_reached']} dig poses reached, dug {r['dug_m3']:.2f} m^3, "
                          f"vessel {r['vessel_m3']:.2f} m^3")
        n = len(runs[("current", plant)][0]["machines"])
        head = f"  {label} ({plant}, {n} machines): " + ", ".join(f"{w} {m:.1f}" for w, m in med.items())
        head += " core-ms per simulated s"
        if "base" in med:
            paired = [c["cpu_s"] / b["cpu_s"] for b, c in zip(runs[("base", plant)], runs[("current", plant)],
                                                              strict=True)]
            head += (f"; current/base = {med['current'] / med['base']:.2f} "
                     f"(per run: {' '.join(f'{x:.2f}' for x in paired)})")
        lines += [head, *detail]
    return lines


def _with_can() -> str:
    import can

    from sim_bridge.can_io import PlantCanIO

    plant = Plant()
    buses = {m: can.Bus(interface="virtual", channel=f"bench_{m}", ignore_config=True) for m in ("zx200", "ic120")}
    io = PlantCanIO(plant, buses)
    try:
        wall = _drive(plant, io)
    finally:
        for b in buses.values():
            b.shutdown()
    sent = sum(c.get("sent", 0) for c in io.counters().values())
    return (f"plant + COM3 CAN I/O (virtual bus, {sent / SIM_SECONDS:.0f} state frames per simulated s): "
            f"{SIM_SECONDS / wall:.1f}x real time")


def _jitter(seconds: float = 20.0) -> str:
    from com3_can.bus import open_bus
    from com3_can.codec import load_codec

    codec = load_codec("zx200")
    fid = codec.frame_id("Front_Angle")
    with isolated_domain() as domain:
        port = free_can_ports(domain, 1)[0]
        cfg = {"interface": "udp_multicast", "channel": f"239.76.1.{domain}", "port": port}
        bus = open_bus(cfg)
        proc = Proc(
            [
                str(executable("sim_bridge", "sim_plant")),
                "--ros-args",
                "-p",
                "speed:=1.0",
                "-p",
                "realtime_priority:=20",
                "-p",
                f"zx200_can_channel:={cfg['channel']}",
                "-p",
                f"zx200_can_port:={port}",
                "-p",
                f"ic120_can_channel:=239.76.2.{domain}",
                "-p",
                f"ic120_can_port:={port + 1}",
            ],
            ros_env(domain),
        )
        stamps: list[float] = []
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(20))  # the receiver is measured too
        except OSError:
            pass
        try:
            if not proc.wait_for("sim_plant: running", 60):
                raise RuntimeError(f"sim_plant did not start: {proc.output}")
            warm = time.monotonic() + 2.0
            end = warm + seconds
            while time.monotonic() < end:
                msg = bus.recv(0.1)
                if msg is not None and msg.arbitration_id == fid and time.monotonic() >= warm:
                    stamps.append(time.monotonic())
        finally:
            proc.kill()
            bus.shutdown()
    periods = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
    dev = [abs(p - 0.010) for p in periods]
    return (f"real-time mode, Front_Angle (10 ms) arrival period over {seconds:.0f} s: {summary_ms(periods)}; "
            f"|period - 10 ms| p99 {percentile(dev, 99) * 1e3:.3f} ms, max {max(dev) * 1e3:.3f} ms; "
            f"rate {len(stamps) / seconds:.1f} Hz")


def main() -> None:
    print(_core(), flush=True)
    for line in _core_cpu():
        print(line, flush=True)
    print(_with_can(), flush=True)
    print(_jitter(), flush=True)


if __name__ == "__main__":
    main()
