"""tms-launch containers with real processes: composed and per-node layouts of one file, --containers, a
node that fails inside a container, Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import pytest

from tests.integration.test_foundation import _alive, _node_pids
from tests.rosproc import VENV

pytestmark = pytest.mark.integration

PAIR = """
name: pair
nodes:
  - {name: talker, package: tms_launch, executable: demo_talker, namespace: /c, parameters: {rate_hz: 20.0}, \
container: pair}
  - {name: listener, package: tms_launch, executable: demo_listener, namespace: /c, parameters: {log_every: 10}, \
container: pair}
  - {name: subtask_server, package: tms_launch, executable: demo_subtask_server, namespace: /c, container: server}
"""


def _launch(procs, tmp_path: Path, text: str, *args: str):
    path = tmp_path / "launch.yaml"
    path.write_text(text)
    return procs([VENV / "bin" / "tms-launch", *args, str(path)], name="tms-launch")


def _stop(launcher) -> None:
    os.kill(launcher.popen.pid, signal.SIGINT)
    assert launcher.wait(20) == 0, launcher.output


def test_composed_nodes_share_a_process_and_talk_inside_it(procs, tmp_path):
    launcher = _launch(procs, tmp_path, PAIR)
    assert launcher.wait_for("are up; Ctrl-C stops them (2 process(es), composed layout)", timeout=120), launcher.output
    assert "starting 1/2: pair (container of talker, listener)" in launcher.output
    pids = _node_pids(launcher.popen.pid)
    assert len(pids) == 2, pids
    # the listener hears the talker of its own process, through the one executor
    assert launcher.wait_for("[pair] heard seq=", timeout=30), launcher.output
    assert re.search(
        r"^\[pair\] container of 2 node\(s\) in process \d+: /c/talker, /c/listener$", launcher.output, re.M
    )
    started = time.monotonic()
    _stop(launcher)
    assert time.monotonic() - started < 10.0
    assert not [p for p in pids if _alive(p)]
    unclean = [
        ln for ln in launcher.output.splitlines() if any(w in ln for w in ("[FATAL]", "while stopping", "Destroyable"))
    ]
    assert not unclean, unclean
    assert re.search(r"^\s+pair \(2 nodes\)\s+[0-9.]+ s\s+[0-9.]+ % of a core$", launcher.output, re.M), launcher.output


def test_per_node_layout_runs_the_same_file_one_process_per_node(procs, tmp_path):
    launcher = _launch(procs, tmp_path, PAIR, "--layout", "per-node")
    assert launcher.wait_for("are up; Ctrl-C stops them (3 process(es), per-node layout)", timeout=120), launcher.output
    assert len(_node_pids(launcher.popen.pid)) == 3
    assert launcher.wait_for("[listener] heard seq=", timeout=30), launcher.output
    _stop(launcher)


def test_containers_switch_starts_only_those_containers(procs, tmp_path):
    launcher = _launch(procs, tmp_path, PAIR, "--containers", "server")
    assert launcher.wait_for("are up; Ctrl-C stops them (1 process(es), composed layout)", timeout=120), launcher.output
    assert "all 1 node(s) of 'pair'" in launcher.output and "talker" not in launcher.output
    _stop(launcher)


def test_a_node_failing_in_a_container_stops_the_launch_naming_it(procs, tmp_path):
    bad = PAIR.replace("executable: demo_subtask_server, namespace: /c,",
                       "executable: demo_subtask_server, namespace: /c, parameters: {duration_s: soon},")
    launcher = _launch(procs, tmp_path, bad)
    assert launcher.wait(120) == 1, launcher.output
    # the container names the node and why (a parameter of the wrong type: one line, exit 2), the launcher the container
    assert re.search(r"^\[server\] \[subtask_server\] \w+: .*duration_s", launcher.output, re.M), launcher.output
    assert "container 'server' exited with code 2" in launcher.output, launcher.output
