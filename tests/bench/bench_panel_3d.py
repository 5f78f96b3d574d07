"""The panel's 3-D view with the ten machines of ``config/launch/original_machines.yaml``: frames per second of the
view in headless Chromium and the panel's CPU per simulated second.

The launch runs as it is (composed, the plant at its own speed, machines idle: no task started) on its own ROS domain
and a fresh embedded DB seeded with the paper seeds, plus ``tms_ur_panel`` (all ten machines) in a container of its
own. Headless Debian chromium (software WebGL) opens ``/3d``; once every machine is placed from /tf, for
``PANEL3D_WINDOW_S`` wall seconds (default 30) it counts the frames the page drew, the panel process's CPU (user +
system, all threads, /proc) and the simulated seconds (the page's /tf stamps). Output of the launch:
``runs/bench_panel_3d/launch.log``.
"""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import yaml

from tests.rosproc import VENV, isolated_domain, ros_env
from tests.tms_ur.conftest import CHROMIUM, CHROMIUM_ARGS

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "original_machines.yaml"
WINDOW_S = float(os.environ.get("PANEL3D_WINDOW_S", "30"))
OUT = ROOT / "runs" / "bench_panel_3d"


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _launch_file(tmp: Path, port: int) -> tuple[Path, list[str]]:
    launch = yaml.safe_load(LAUNCH.read_text())
    machines = []
    for node in launch["nodes"]:
        params = node.setdefault("parameters", {})
        node["ready_timeout"] = 300
        if "config" in params and not Path(params["config"]).is_absolute():
            params["config"] = str(ROOT / params["config"])
        if node["executable"] == "com3_bridge":
            machines.append(params["machine"])
    launch["nodes"].append({"name": "tms_ur_panel", "package": "tms_ur", "executable": "tms_ur_panel",
                            "container": "panel", "parameters": {"port": port, "machines": machines,
                                                                 "use_sim_time": False}})
    path = tmp / "original_machines_panel.yaml"
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path, machines


def _panel_pid(launcher_pid: int) -> int | None:
    """The ``panel`` container's process (``python -m tms_launch.container panel ...``) under the launcher."""
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if ppid == launcher_pid and b"tms_launch.container" in argv and b"panel" in argv:
            return int(proc.name)
    return None


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    from playwright.sync_api import sync_playwright

    OUT.mkdir(parents=True, exist_ok=True)
    port = _port()
    with isolated_domain() as domain, tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        env = ros_env(domain, TMS_DB_PATH=str(tmp / "db"))
        seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env=env, capture_output=True,
                                text=True, timeout=120)
        if seeded.returncode:
            raise RuntimeError(f"tms-db seed paper failed: {seeded.stderr[-400:]}")
        launch, machines = _launch_file(tmp, port)
        log = (OUT / "launch.log").open("w")
        launcher = subprocess.Popen([str(VENV / "bin" / "tms-launch"), str(launch)], env=env, stdout=log,
                                    stderr=subprocess.STDOUT)
        try:
            deadline = time.monotonic() + 400
            while f"serving http://127.0.0.1:{port}/" not in (OUT / "launch.log").read_text():
                if launcher.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"the launch did not serve the panel; see {OUT / 'launch.log'}")
                time.sleep(1.0)
            pid = _panel_pid(launcher.pid)
            if pid is None:
                raise RuntimeError("no panel container process found under tms-launch")
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
                page = browser.new_page(viewport={"width": 1200, "height": 800})
                page.goto(f"http://127.0.0.1:{port}/3d")
                page.wait_for_function(
                    f"{machines}.every(n => window.site3d.loaded(n) && window.site3d.stamp(n) !== null)",
                    timeout=180_000)
                stamp = f"Math.max(...{machines}.map(n => window.site3d.stamp(n)))"
                f0, s0, c0, w0 = page.evaluate("window.site3d.frames()"), page.evaluate(stamp), _cpu_s(pid), \
                    time.monotonic()
                time.sleep(WINDOW_S)
                f1, s1, c1, w1 = page.evaluate("window.site3d.frames()"), page.evaluate(stamp), _cpu_s(pid), \
                    time.monotonic()
                browser.close()
        finally:
            launcher.terminate()
            try:
                launcher.wait(60)
            except subprocess.TimeoutExpired:
                launcher.kill()
            log.close()
    wall, sim, cpu = w1 - w0, s1 - s0, c1 - c0
    print(f"machines: {len(machines)} ({', '.join(machines)}), idle; window {wall:.1f} s wall, {sim:.1f} s simulated")
    print(f"view fps (headless chromium, software WebGL, 1200x800): {(f1 - f0) / wall:.1f}")
    print(f"panel CPU: {cpu:.2f} core-s = {cpu / wall:.3f} cores; per simulated second: "
          f"{cpu / sim if sim > 0 else float('nan'):.3f} core-s")
