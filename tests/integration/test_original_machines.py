"""``config/launch/original_machines.yaml``: every machine the original's task trees name, in one site, serving
every subtask the original defines for its kind under ``/<model_name>/<subtask_name>``.

The expected pairs are written out here from the original's subtask servers (irvs/ros2_tms_for_construction,
``tms_ts/tms_ts_subtask``: the ``st_<prefix>_*`` / ``subtask_zx200_*`` servers it builds, started in the namespace of
each machine of that kind) and the one cross pair its trees send (``/mst2200/st_ic120_release_soil``), not derived
from our own table. The launch runs composed on the test's domain; a probe lists the action servers on the graph.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from tests.rosproc import VENV

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "original_machines.yaml"
UP_LIMIT_S = 420

pytestmark = [pytest.mark.integration, pytest.mark.timeout(UP_LIMIT_S + 240)]

_TRAVEL = ("follow_waypoints", "navigate_anywhere", "navigate_through_poses")
_SAMPLES = ("swing", "boom", "arm", "bucket")


def _travel(prefix: str) -> list[str]:
    return [f"st_{prefix}_{verb}{deg}" for verb in _TRAVEL for deg in ("", "_deg")]


def _carrier_mst(prefix: str) -> list[str]:
    return [*_travel(prefix), f"st_{prefix}_release_soil", f"st_{prefix}_swing", f"st_{prefix}_swing_align_to_heading"]


ZX200 = ["subtask_zx200_change_pose", "subtask_zx200_change_pose_plan", "subtask_zx200_excavate_simple",
         "subtask_zx200_excavate_simple_plan", "subtask_zx200_release_simple", *_travel("zx200"),
         *(f"st_zx200_sample_{j}" for j in _SAMPLES)]
IC120 = [*_travel("ic120"), "st_ic120_release_soil"]
#: model_name -> the subtask names the original serves (or its trees send) in that namespace
ORIGINAL: dict[str, list[str]] = {
    "zx200": ZX200,
    "zx120": [f"st_zx120_sample_{j}" for j in _SAMPLES],
    "ic120": IC120,
    "ic120_1": IC120,
    "ic120_2": IC120,
    "mst110cr": _carrier_mst("mst110cr"),
    "mst110cr_2": _carrier_mst("mst110cr"),
    "mst2200vd": _carrier_mst("mst2200"),
    "mst2200": [*_carrier_mst("mst2200"), "st_ic120_release_soil"],
    "d37pxi_24": _travel("d37pxi"),
}
LEAF = "tms_msg_ts/action/LeafNodeBase"


def test_every_original_machine_serves_every_subtask_of_its_kind(procs, ros_node, tmp_path):
    from rclpy.action import get_action_names_and_types

    launch = yaml.safe_load(LAUNCH.read_text())
    for node in launch["nodes"]:
        if node["executable"] == "sim_plant":
            node["parameters"]["config"] = str(ROOT / node["parameters"]["config"])
    path = tmp_path / "original_machines.yaml"
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    db = tmp_path / "db"
    db.mkdir()
    seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env={**os.environ, "TMS_DB_PATH": str(db)},
                            capture_output=True, text=True, timeout=120)
    assert seeded.returncode == 0, seeded.stdout + seeded.stderr
    proc = procs([VENV / "bin" / "tms-launch", "--layout", "composed", path], name="original", TMS_DB_PATH=str(db))

    wanted = {f"/{m}/{s}" for m, subs in ORIGINAL.items() for s in subs}
    assert len(wanted) == sum(len(set(v)) for v in ORIGINAL.values())
    deadline = time.monotonic() + UP_LIMIT_S
    served: dict[str, list[str]] = {}
    while time.monotonic() < deadline:
        assert proc.popen.poll() is None, proc.output[-4000:]
        served = dict(get_action_names_and_types(ros_node))
        if wanted <= set(served):
            break
        time.sleep(2.0)
    missing = sorted(wanted - set(served))
    assert not missing, f"{len(missing)} of {len(wanted)} not served: {missing[:20]}\n" + proc.output[-3000:]
    assert all(served[a] == [LEAF] for a in wanted), {a: served[a] for a in wanted if served[a] != [LEAF]}
    # the downstream servers the rows call are up too: planning, navigation, vessel
    for action in ("/zx200/tms_rp_zx200_change_pose_plan", "/zx200/arm_controller/move", "/zx120/arm_controller/move",
                   "/ic120_2/navigate_to_pose", "/mst110cr_2/set_swing_angle", "/mst2200/set_dump_angle",
                   "/d37pxi_24/follow_waypoints"):
        assert action in served, action
    out = proc.output
    print(f"{len(wanted)} (model_name, subtask_name) pairs served by {len(ORIGINAL)} machines")
    proc.signal(signal.SIGINT)
    assert proc.wait(180) == 0, proc.output[-4000:]
    assert "Traceback" not in proc.output, proc.output[-4000:]
    assert "[FATAL]" not in out
