"""The panel's 3-D view in headless Chromium during a paper cycle (the whole paper stack, the dynamic terrain
writer and the panel; tms-launch on the test's own ROS domain and CAN groups).

The scene holds the terrain and every machine; each machine's base_link in the view agrees with /tf (heard by this
test over DDS) within 1 cm at the stamp the page says it drew; the view's terrain changes where the bucket dug; a
screenshot goes to runs/screenshots/site3d.png (docs/img/site3d.png is one of them, copied by hand).
"""

from __future__ import annotations

import math
import os
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from tests.integration.test_paper_cycle import ROOT, _write_configs
from tests.rosproc import VENV
from tests.tms_ur.conftest import free_port
from tf2_msgs.msg import TFMessage
from tms_model.transform import Transform
from tms_sp.nodes.tms_sp_tf import TF_QOS

pytestmark = [pytest.mark.integration, pytest.mark.timeout(900)]

SCREENSHOT = ROOT / "runs" / "screenshots" / "site3d.png"
MACHINES = ("zx200", "ic120")  # the paper launch's machines (its experiment's ``machines`` parameter)


def launch_with_view(tmp_path: Path, domain: int, port: int, supervisor: bool = True) -> Path:
    """The paper launch (one cycle) plus the dynamic terrain writer and the panel, each in a process of its own."""
    path = _write_configs(tmp_path, domain, supervisor=supervisor)
    launch = yaml.safe_load(path.read_text())
    machines = next((n["parameters"]["machines"] for n in launch["nodes"] if n["executable"] == "tms_ur_experiment"),
                    list(MACHINES))
    launch["nodes"] += [
        # every 2 s of simulated time, not on every 0.5 s scan: each write is a PNG into the embedded DB
        {"name": "tms_sd_terrain_dynamic", "package": "tms_sp", "executable": "tms_sd_terrain_dynamic",
         "container": "terrain", "parameters": {"period_s": 2.0}},
        {"name": "tms_ur_panel", "package": "tms_ur", "executable": "tms_ur_panel", "container": "panel",
         "parameters": {"port": port, "machines": machines, "use_sim_time": False}},
    ]
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def start_stack(procs, domain: int, tmp_path: Path, port: int, supervisor: bool = True):
    db = tmp_path / "db"
    db.mkdir()
    env = {"TMS_DB_PATH": str(db)}
    seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env={**os.environ, **env},
                            capture_output=True, text=True, timeout=120)
    assert seeded.returncode == 0, seeded.stdout + seeded.stderr
    launcher = procs([VENV / "bin" / "tms-launch", launch_with_view(tmp_path, domain, port, supervisor)],
                     name="paper+view", **env)
    assert launcher.wait_for(f"serving http://127.0.0.1:{port}/", timeout=300), "\n".join(launcher.lines[-60:])
    return launcher


class TfLog:
    """Every /tf edge heard, by child frame: [(stamp, parent, translation)] in arrival order."""

    def __init__(self, node) -> None:
        self.edges: dict[str, list[tuple[float, str, tuple[float, float, float], tuple[float, ...]]]] = {}
        node.create_subscription(TFMessage, "/tf", self._on, TF_QOS)

    def _on(self, msg) -> None:
        for t in msg.transforms:
            tr, r = t.transform.translation, t.transform.rotation
            stamp = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9
            self.edges.setdefault(t.child_frame_id, []).append(
                (stamp, t.header.frame_id, (tr.x, tr.y, tr.z), (r.x, r.y, r.z, r.w)))

    def base_in_map(self, base: str, chain: dict[str, float]) -> tuple[float, float, float] | None:
        """``map -> ... -> base`` composed from the edges of the stamps the page says it drew (``chain``: child
        frame -> stamp); None while one of them has not been heard here."""
        tr, frame = Transform(), base
        while frame != "map":
            stamp = chain.get(frame)
            edge = next((e for e in self.edges.get(frame, []) if stamp is not None and abs(e[0] - stamp) < 1e-6),
                        None)
            if edge is None:
                return None
            tr = Transform(edge[2], edge[3]) * tr
            frame = edge[1]
        return tr.translation


def spin(node, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        node.executor_for_test.spin_once(timeout_sec=0.02)


def wait_page(page, node, predicate_js: str, timeout: float, what: str, launcher) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        spin(node, 0.25)
        if page.evaluate(predicate_js):
            return
        if launcher.popen.poll() is not None:
            pytest.fail(f"the stack ended while waiting for {what}:\n" + "\n".join(launcher.lines[-60:]))
    pytest.fail(f"timed out waiting for {what}:\n" + "\n".join(launcher.lines[-60:]))


def base_frame(links: dict) -> str:
    return next(f for f in links if f == "base_link" or f.endswith("/base_link"))


def test_the_3d_view_shows_the_site_as_tf_has_it_and_the_dig(procs, domain, ros_node, browser_page, tmp_path):
    port = free_port()
    tf = TfLog(ros_node)
    launcher = start_stack(procs, domain, tmp_path, port)
    page = browser_page
    page.goto(f"http://127.0.0.1:{port}/3d")
    wait_page(page, ros_node, "document.querySelector('#conn.ok') !== null", 30, "the websocket", launcher)
    # every machine of the site is in the scene, from its URDF, placed from /tf
    names_js = f"{list(MACHINES)}.every(n => window.site3d.loaded(n) && window.site3d.stamp(n) !== null)"
    wait_page(page, ros_node, names_js, 120, "every machine placed", launcher)
    assert sorted(page.evaluate("window.site3d.machineNames()")) == sorted(MACHINES)
    # the terrain: the dynamic layer from the mound scans
    wait_page(page, ros_node, "window.site3d.terrainLayers().some(l => l.kind === 'dynamic')", 120,
              "the dynamic terrain in the view", launcher)
    layer = page.evaluate("window.site3d.terrainLayers().find(l => l.kind === 'dynamic')")
    assert layer["rows"] > 10 and layer["cols"] > 10, layer

    # poses: the view against /tf at the stamp the page drew, for every machine, several times
    compared = 0
    for _ in range(20):  # a loaded machine misses some stamps (the page drew one /tf the test has not heard): retry
        if compared >= len(MACHINES) * 3:
            break
        spin(ros_node, 1.0)
        for name in MACHINES:
            shown = page.evaluate(f"[window.site3d.stamp({name!r}), window.site3d.chain({name!r}), "
                                  f"window.site3d.links({name!r})]")
            stamp, chain, links = shown
            base = base_frame(links)
            m = links[base]  # column-major 4x4: translation in 12..14
            assert chain[base] == stamp, (name, chain, stamp)
            expected = tf.base_in_map(base, chain)
            if expected is None:
                continue
            err = math.dist((m[12], m[13], m[14]), expected)
            assert err < 0.01, f"{name} at /tf stamp {stamp}: view {m[12:15]} vs /tf {expected}: {err:.4f} m"
            compared += 1
    assert compared >= len(MACHINES) * 3, f"only {compared} view/tf comparisons found the page's stamp on /tf"

    # the dig: heights over the dynamic layer before, the bucket tip when the bucket first holds soil, and the
    # view's terrain lowered there afterwards
    before = page.evaluate("""(() => { const l = window.site3d.terrainLayers().find(l => l.kind === 'dynamic');
        return window.site3d.terrainVersion(); })()""")
    grid_js = """(() => { const out = []; const b = window.site3d.terrainBounds('dynamic');
        for (let x = b.x_min + 0.25; x < b.x_max; x += 0.5) for (let y = b.y_min + 0.25; y < b.y_max; y += 0.5)
          out.push([x, y, window.site3d.heightAt(x, y)]); return out; })()"""
    heights0 = page.evaluate(grid_js)
    excavator = "zx200"
    wait_page(page, ros_node, f"window.site3d.heap({excavator!r}) > 0", 400, "soil in the bucket", launcher)
    links = page.evaluate(f"window.site3d.links({excavator!r})")
    tip = links[next(f for f in links if f.endswith("bucket_end_link"))]
    dig = (tip[12], tip[13])
    near = [h for x, y, h in heights0 if math.hypot(x - dig[0], y - dig[1]) < 1.5]
    assert near, f"the dig point {dig} is outside the dynamic terrain"

    def lowered() -> float:
        now = page.evaluate(f"""(() => {{ const out = []; for (const [x, y] of {[[x, y] for x, y, _ in heights0
                            if math.hypot(x - dig[0], y - dig[1]) < 1.5]})
                            out.push(window.site3d.heightAt(x, y)); return out; }})()""")
        return sum(near) / len(near) - sum(now) / len(now)

    deadline = time.monotonic() + 120
    while lowered() < 0.05 and time.monotonic() < deadline:
        spin(ros_node, 1.0)
    drop = lowered()
    assert page.evaluate("window.site3d.terrainVersion()") != before, "the terrain in the view never changed"
    assert drop >= 0.05, f"the view's terrain near the dig point {dig} dropped only {drop:.3f} m"
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOT))
    assert SCREENSHOT.stat().st_size > 10_000
