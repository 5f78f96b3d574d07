"""The fleet experiment end to end (config/launch/fleet.yaml, composed): one ZX200 loads ic120_1, ic120_2 and
mst110cr_2 in turn at the loading point, each after reserving it through the global blackboard; every carrier
loaded once (the supervisor's ``loads: 3``; vessel target fill small, so one pass loads a carrier, as the paper's
cycle tests), simulated time. Asserts: each carrier's soil > 0, the loading point never held by two carriers (the
smallest distance between two carriers with one within 12 m of the loading point above MIN_DISTANCE_M), every
task SUCCESS.

Needs the generic tracked-machine stack by name (tms_rp.tracked, tms_rc.carrier) and the MST110CR subtask rows.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
from pathlib import Path

import pytest
import yaml

from tests.rosproc import VENV

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "fleet.yaml"
TARGET_FILL = 0.1  # one pass loads a carrier
#: two footprint half-diagonals (IC120 3.46 m, MST110CR 3.62 m): below this two carriers could touch
MIN_DISTANCE_M = 7.1
WALL_LIMIT_S = 900

pytestmark = [pytest.mark.integration, pytest.mark.timeout(WALL_LIMIT_S + 180)]


def _launch(tmp: Path) -> Path:
    launch = yaml.safe_load(LAUNCH.read_text())
    for node in launch["nodes"]:
        params = node.setdefault("parameters", {})
        if node["executable"] == "sim_plant":
            params["config"] = str(ROOT / params["config"])
        elif node["executable"] == "tms_sp_sensing":
            params["target_fill"] = TARGET_FILL
        elif node["executable"] == "tms_ur_experiment":
            params.update(loads=3, runs_dir=str(tmp / "runs"), timeout_s=3000.0)
            node["stop_grace_s"] = 180
    path = tmp / "fleet.yaml"
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def _flags_at_the_end(tmp: Path) -> str:
    """The last changes of each global-blackboard flag in the supervisor's record, if it wrote one."""
    runs = sorted((tmp / "runs").glob("*/metrics.json"))
    if not runs:
        return "(no metrics.json written)"
    timeline = json.loads(runs[-1].read_text()).get("flags_timeline", {})
    return "flags (last changes, simulated s):\n" + "\n".join(f"  {k}: {v[-4:]}" for k, v in sorted(timeline.items()))


def test_fleet_cycle_each_carrier_loaded_once(procs, tmp_path):
    db = tmp_path / "db"
    db.mkdir()
    seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "fleet"], env={**os.environ, "TMS_DB_PATH": str(db)},
                            capture_output=True, text=True, timeout=120)
    assert seeded.returncode == 0, seeded.stdout + seeded.stderr
    proc = procs([VENV / "bin" / "tms-launch", _launch(tmp_path)], name="fleet", TMS_DB_PATH=str(db))
    code = proc.wait(WALL_LIMIT_S)
    if code is None:  # stalled: stop it so the supervisor writes its record, and show where the flags stood
        proc.signal(signal.SIGINT)
        proc.wait(240)
    out = proc.output
    tail = "\n".join(out.splitlines()[-40:])
    warnings = "\n".join([line for line in out.splitlines() if "[WARN]" in line or "[ERROR]" in line][-30:])
    assert code == 0, f"exit {code}:\n{tail}\nwarnings and errors (last 30):\n{warnings}\n{_flags_at_the_end(tmp_path)}"
    m = json.loads(sorted((tmp_path / "runs").glob("*/metrics.json"))[-1].read_text())
    assert m["tasks"] and all(t["state"] == "SUCCESS" for t in m["tasks"].values()), m["tasks"]
    assert {t["machine"] for t in m["tasks"].values()} == {"zx200", "ic120_1", "ic120_2", "mst110cr_2"}
    for name, figures in m["carriers"].items():
        assert figures["soil_moved_m3"] > 0.0, (name, m["carriers"])
    assert m["min_carrier_distance_near_loading_point_m"] > MIN_DISTANCE_M, m["min_carrier_distance_at"]
    holders = [v for _, v in m["flags_timeline"]["LOADAREA_MACHINE"] if v != "-"]
    assert holders[:3] == ["ic120_1", "ic120_2", "mst110cr_2"], holders
    print(f"fleet cycle: carriers {m['carriers']}, min distance {m['min_carrier_distance_near_loading_point_m']} m, "
          f"sim {m['sim_time_s']} s, wall {m['wall_time_s']} s, RTF {m['real_time_factor']}")
