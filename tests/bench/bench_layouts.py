"""One cycle of the paper experiment per layout, back to back: one process per node, then composed.

``config/launch/paper_experiment.yaml`` runs through ``tms-launch --layout per-node`` (13 processes, COM3 CAN
over udp_multicast between the plant and the converters) and then ``tms-launch --layout composed`` (the
containers plant, zx200_pc, ic120_pc, sensing_pc, site_server: 5 processes, the plant and both converters linked by
in-process python-can virtual buses), each on a fresh embedded DB seeded with ``config/seeds/paper.yaml``, its
own ROS domain, one haul cycle (``cycles: 1``), the plant at ``LAYOUTS_SPEED`` x real time (default: the paper
launch's own speed parameter). Nothing else differs.

Printed per layout: the CPU of all its processes (tms-launch's CPU table: user + system, all threads, from
start-up to the end), the simulated seconds of the run (the supervisor's report), their quotient in
core-seconds per simulated second, the real-time factor and both tasks' end states. Then
``cpu_ratio`` = composed / per-node core-seconds per simulated second (goal <= 0.5) and ``composed_rtf``
(goal >= 3 on the 2-core machine). Each run's full output goes to ``runs/bench_layouts/<layout>.log``.

``LAYOUTS_ONLY=composed`` (or ``per-node``) runs one layout; ``LAYOUTS_WALL_S`` bounds each run (default 1500 s).
"""

from __future__ import annotations

import json
import os
import random
import re
import subprocess
import sys
import time
from pathlib import Path

import yaml

from tests.rosproc import VENV, free_can_ports, isolated_domain, ros_env

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "paper_experiment.yaml"
LAYOUTS = ("per-node", "composed")
WALL_S = float(os.environ.get("LAYOUTS_WALL_S", "1500"))
SPEED = os.environ.get("LAYOUTS_SPEED")
OUT = ROOT / "runs" / "bench_layouts"


def _launch_file(tmp: Path, layout: str, domain: int) -> Path:
    """The paper launch with one cycle and this run's report directory; per-node: this run's own CAN groups."""
    launch = yaml.safe_load(LAUNCH.read_text())
    rng = random.Random(domain)
    ports = dict(zip(("zx200", "ic120"), free_can_ports(domain, 2, rng), strict=True))
    groups = {m: f"239.75.{rng.randrange(1, 250)}.{rng.randrange(1, 250)}" for m in ports}
    for node in launch["nodes"]:
        # 13 processes importing at once on 2 shared cores took over the default 90 s to come up
        node["ready_timeout"] = 300
        params = node.setdefault("parameters", {})
        exe = node["executable"]
        if exe == "sim_plant":
            params["config"] = str(ROOT / params["config"])
            if SPEED:
                params["speed"] = float(SPEED)
            if layout == "per-node":  # the composed plant container links its converters in-process instead
                for m in ports:
                    params.update({f"{m}_can_interface": "udp_multicast", f"{m}_can_channel": groups[m],
                                   f"{m}_can_port": ports[m]})
        elif exe == "com3_bridge" and layout == "per-node":
            m = params["machine"]
            params.update(can_interface="udp_multicast", can_channel=groups[m], can_port=ports[m])
        elif exe == "tms_ur_experiment":
            params.update(cycles=1, runs_dir=str(tmp / "runs"), timeout_s=WALL_S * 3)
    path = tmp / f"paper_{layout}.yaml"
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def _run(layout: str) -> dict:
    import tempfile

    OUT.mkdir(parents=True, exist_ok=True)
    log_path = OUT / f"{layout}.log"
    with isolated_domain() as domain, tempfile.TemporaryDirectory(prefix=f"bench_layouts_{layout}_") as tmpdir:
        tmp = Path(tmpdir)
        env = ros_env(domain, TMS_DB_PATH=str(tmp / "db"))
        env.pop("TMS_LAYOUT", None)
        (tmp / "db").mkdir()
        seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env=env, capture_output=True,
                                text=True, timeout=300)
        if seeded.returncode != 0:
            raise RuntimeError(f"seeding the DB failed: {seeded.stdout}{seeded.stderr}")
        launch = _launch_file(tmp, layout, domain)
        began = time.monotonic()
        with log_path.open("w") as log:
            proc = subprocess.Popen([str(VENV / "bin" / "tms-launch"), "--layout", layout, str(launch)], env=env,
                                    stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
            try:
                code = proc.wait(WALL_S)
            except subprocess.TimeoutExpired:
                proc.send_signal(2)
                code = proc.wait(120)
                print(f"  {layout}: not done within {WALL_S:g} s wall; stopped", flush=True)
        wall = time.monotonic() - began
        out = log_path.read_text()
        total = re.search(r"^\s+total\s+([0-9.]+) s\s+([0-9.]+) cores over ([0-9.]+) s", out, re.M)
        if total is None:
            raise RuntimeError(f"{layout}: no CPU table in {log_path} (exit {code})")
        reports = sorted((tmp / "runs").glob("*/metrics.json"))
        if not reports:
            raise RuntimeError(f"{layout}: no report written (exit {code}); see {log_path}")
        m = json.loads(reports[-1].read_text())
        cpu = float(total.group(1))
        rows = re.findall(r"^\s{2}(\S.*?)\s+([0-9.]+) s\s+([0-9.]+) % of a core", out, re.M)
        states = {t: v[-1][1] for t, v in m.get("task_states", {}).items()}
        return {"layout": layout, "exit": code, "cpu_s": cpu, "sim_s": float(m["sim_time_s"]),
                "rtf": float(m["real_time_factor"]), "wall_s": wall, "processes": len(rows),
                "tasks": states, "cycles": m.get("cycles"), "rows": rows}


def main() -> None:
    only = os.environ.get("LAYOUTS_ONLY")
    chosen = [only] if only else list(LAYOUTS)
    results = {}
    for layout in chosen:
        print(f"  running one paper cycle, {layout} layout (log: {OUT / (layout + '.log')}) ...", flush=True)
        r = _run(layout)
        results[layout] = r
        per_sim = r["cpu_s"] / r["sim_s"]
        print(f"  {layout}: {r['processes']} processes, CPU {r['cpu_s']:.1f} s over {r['sim_s']:.1f} simulated s "
              f"= {per_sim:.3f} core-s per simulated s; real-time factor {r['rtf']:.2f}; wall {r['wall_s']:.0f} s; "
              f"cycles {r['cycles']}; tasks {r['tasks']}; exit {r['exit']}", flush=True)
        for name, cpu_s, share in r["rows"]:
            if name != "total":
                print(f"      {name:<40} {float(cpu_s):8.1f} s  {float(share):5.1f} % of a core", flush=True)
    if "composed" in results:
        print(f"composed_rtf = {results['composed']['rtf']:.2f}  (goal >= 3)", flush=True)
    if len(results) == 2:
        ratio = (results["composed"]["cpu_s"] / results["composed"]["sim_s"]) / (
            results["per-node"]["cpu_s"] / results["per-node"]["sim_s"])
        print(f"cpu_ratio = {ratio:.2f}  (composed / per-node core-s per simulated s; goal <= 0.5)", flush=True)
    failed = [k for k, r in results.items() if r["exit"] != 0 or set(r["tasks"].values()) != {"SUCCESS"}]
    if failed:
        raise RuntimeError(f"layout(s) {failed} did not end with both tasks SUCCESS (see {OUT})")


if __name__ == "__main__":
    main()
    sys.exit(0)
