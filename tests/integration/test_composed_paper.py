"""The paper launch in the composed layout: 13 nodes in 5 container processes, the plant and both converters
linked by in-process python-can virtual buses.

* ``test_composed_paper_cycle``: one load-haul-dump cycle (vessel target fill small, as
  ``test_paper_cycle.py``), both tasks SUCCESS, the launch ended by the supervisor through its container. Recorded
  as ``make demo`` records (``tms-launch --record``): an independent reader (mcap + mcap_ros2, not the rosbags code
  that wrote it) finds every machine pose this test's own subscriber received, stamp for stamp, in the bag.
* ``test_composed_stop_mid_task``: Ctrl-C while both tasks run: the containers stop last-started first and
  inside ``site_server`` the nodes stop last-listed first, so the supervisor writes its report of a stopped
  run and the manager cancels the running tasks and locks their machines while the converters and plant still run
  (the plant engages a hydraulic lock); the launch exits 0, nothing killed.

Everything is real: tms-launch, the container processes, DDS between them on the test's own domain, MuJoCo.
No CAN parameters are given: the in-process link needs no isolation (a virtual channel exists only inside its
process), and the plant container's log shows it was chosen.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import threading
import time
from collections import Counter
from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import PoseStamped
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import QoSProfile, ReliabilityPolicy

from tests.rosproc import VENV

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "paper_experiment.yaml"
SENSING = ROOT / "config" / "tms_sp" / "sensing.yaml"
TARGET_FILL = 0.1  # as test_paper_cycle.py: one pass loads the IC120
WALL_LIMIT_S = 900

pytestmark = [pytest.mark.integration, pytest.mark.timeout(WALL_LIMIT_S + 180)]


def _launch(tmp: Path) -> Path:
    text = SENSING.read_text()
    text, n = re.subn(r"(?m)^(\s*target_fill:\s*)[0-9.]+", rf"\g<1>{TARGET_FILL}", text)
    assert n == 1, "config/tms_sp/sensing.yaml: vessel.target_fill not found"
    sensing = tmp / "sensing_small_fill.yaml"
    sensing.write_text(text)
    launch = yaml.safe_load(LAUNCH.read_text())
    for node in launch["nodes"]:
        params = node.setdefault("parameters", {})
        if node["executable"] == "sim_plant":
            params["config"] = str(ROOT / params["config"])
        elif node["executable"] == "tms_sp_sensing":
            params["config"] = str(sensing)
        elif node["executable"] == "tms_ur_experiment":
            params.update(cycles=1, runs_dir=str(tmp / "runs"), timeout_s=3000.0)
            # the report of a stopped run (matplotlib) took over 40 s on a 2-core machine under other tests' load
            node["stop_grace_s"] = 180
    path = tmp / "paper_composed.yaml"
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


def _start(procs, tmp_path, *extra):
    db = tmp_path / "db"
    db.mkdir()
    import os

    seeded = subprocess.run([str(VENV / "bin" / "tms-db"), "seed", "paper"], env={**os.environ, "TMS_DB_PATH": str(db)},
                            capture_output=True, text=True, timeout=120)
    assert seeded.returncode == 0, seeded.stdout + seeded.stderr
    return procs([VENV / "bin" / "tms-launch", "--layout", "composed", _launch(tmp_path), *extra], name="paper",
                 TMS_DB_PATH=str(db))


def _check_composed(out: str, recorded: bool = False) -> None:
    nodes, processes = (15, 6) if recorded else (14, 5)  # the recorder is a process of its own
    assert f"all {nodes} node(s) of 'paper_experiment' are up; Ctrl-C stops them ({processes} process(es), composed " \
        "layout)" in out, out[-3000:]
    for container in ("plant", "zx200_pc", "ic120_pc", "sensing_pc", "site_server"):
        assert re.search(rf"^\[{container}\] container of \d+ node\(s\) in process \d+", out, re.M), container
    # both CAN links chosen in-process by com3_can.bus.link_config, at both ends
    for machine in ("zx200", "ic120"):
        assert f"{machine}: CAN {{'interface': 'virtual', 'channel': 'com3_{machine}'}}" in out, machine
        assert f"{machine}: CAN {{'interface': 'virtual', 'channel': 'com3_{machine}'}} watchdog" in out, machine


POSES = ("/sim/truth/zx200/pose", "/sim/truth/ic120/pose")


def _probe(ros_node):
    """This test's own subscriber of the machine poses, spun in a thread: the stamps it received, per topic."""
    got: dict[str, list[int]] = {t: [] for t in POSES}
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    for topic in POSES:
        ros_node.create_subscription(
            PoseStamped, topic, lambda m, t=topic: got[t].append(m.header.stamp.sec * 10**9 + m.header.stamp.nanosec),
            qos)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            ros_node.executor_for_test.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    return got, stop, thread


def _check_recording(bag: Path, got: dict[str, list[int]]) -> None:
    assert (bag / "metadata.yaml").is_file(), sorted(bag.parent.iterdir())
    counts: Counter = Counter()
    recorded: dict[str, list[int]] = {t: [] for t in POSES}
    for path in sorted(bag.glob("*.mcap")):
        with path.open("rb") as f:
            for _schema, channel, _message, msg in make_reader(f, decoder_factories=[DecoderFactory()]) \
                    .iter_decoded_messages():
                counts[channel.topic] += 1
                if channel.topic in recorded:
                    recorded[channel.topic].append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    print("recorded messages per topic:", dict(sorted(counts.items())))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["storage_identifier"] == "mcap"
    # a topic subscribed but never published on (/emergency_signal in a run without a stop) is listed with 0
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]
            if t["message_count"]} == dict(counts), "metadata.yaml's counts differ from the messages in the file"
    for topic in ("/tf", "/tms_ts/status", "/sim/truth/soil", "/zx200/joint_states", "/sim/sensors/mound/points"):
        assert counts[topic] > 0, (topic, dict(counts))
    for topic in POSES:
        # while both listened (the recorder starts before the test's subscriber matches, and stops after the
        # supervisor ended the launch), every pose the test received is in the bag, none twice
        heard, kept = got[topic], recorded[topic]
        assert len(heard) > 100, (topic, len(heard))
        window = [s for s in heard if min(kept) <= s <= max(kept)]
        assert len(window) > 0.9 * len(heard), (topic, len(window), len(heard))
        missing = sorted(set(window) - set(kept))
        assert not missing, f"{topic}: {len(missing)} of {len(window)} poses the test received are not recorded"
        assert len(kept) == len(set(kept)), f"{topic}: a pose recorded twice"


def test_composed_paper_cycle(procs, ros_node, tmp_path):
    bag = tmp_path / "bag"
    got, stop, thread = _probe(ros_node)
    proc = _start(procs, tmp_path, "--record", bag)
    code = proc.wait(WALL_LIMIT_S)
    stop.set()
    thread.join(5)
    out = proc.output
    tail = "\n".join(out.splitlines()[-60:])
    assert code == 0, f"exit {code}:\n{tail}"
    _check_composed(out, recorded=True)
    assert re.search(r"task 1: SUCCESS", out) and re.search(r"task 2: SUCCESS", out), tail
    m = json.loads(sorted((tmp_path / "runs").glob("*/metrics.json"))[-1].read_text())
    assert m["cycles"] == 1 and m["soil_moved_m3"] > 0.04, m
    assert m["real_time_factor"] > 0, m
    # the CPU table has one row per container
    assert re.search(r"^\s+site_server \(4 nodes\)\s+[0-9.]+ s", out, re.M), tail
    # the supervisor's end and every node's stop are clean (on the events executor: no FATAL callback log,
    # no timer of a destroyed node)
    unclean = [ln for ln in out.splitlines() if any(w in ln for w in ("[FATAL]", "while stopping", "Destroyable"))]
    assert not unclean, "\n".join(unclean[:20])
    _check_recording(bag, got)


def test_composed_stop_mid_task(procs, tmp_path):
    proc = _start(procs, tmp_path)
    # the supervisor prints a progress line once the tasks run; stop a few of them later
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.popen.poll() is None:
        if len(re.findall(r"^\[site_server\] \[experiment\] cycle", proc.output, re.M)) >= 3:
            break
        time.sleep(0.5)
    out = proc.output
    assert proc.popen.poll() is None, out[-3000:]
    assert re.search(r"^\[site_server\] \[experiment\] cycle", out, re.M), out[-3000:]
    proc.signal(signal.SIGINT)
    code = proc.wait(120)
    out = proc.output
    tail = "\n".join(out.splitlines()[-60:])
    assert code == 0, tail
    _check_composed(out)
    stopping = out.index("stopping 5 process(es) (last started first, one at a time): sensing_pc, site_server, "
                         "ic120_pc, zx200_pc, plant")
    assert "[experiment] STOPPED before the end" in out[stopping:], tail
    m = json.loads(sorted((tmp_path / "runs").glob("*/metrics.json"))[-1].read_text())
    assert m["ended"] == "stopped", m
    # the manager cancelled the running tasks and locked their machines (its destroy_node) while the converters
    # and the plant were still up: the plant engaged a hydraulic lock; nothing had to be killed
    assert "SIGKILL" not in out[stopping:] and "SIGTERM" not in out[stopping:], tail
    assert re.search(r"^\[plant\] .*(zx200|ic120): pilot cut-off engaged", out[stopping:], re.M), tail
