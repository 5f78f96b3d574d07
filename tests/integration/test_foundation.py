"""Foundation: real processes over DDS, a tms_msg action across processes, the launcher."""

from __future__ import annotations

import os
import re
import signal
import time
from pathlib import Path

import pytest

from tests.rosproc import ROOT, VENV, executable

pytestmark = pytest.mark.integration


def test_ros2_run_resolution_finds_and_runs_a_registered_node():
    """Resolve like `ros2 run`: ament prefix + lib/<pkg>/<exe>, executable, and it runs."""
    import subprocess

    path = executable("tms_launch", "demo_subtask_client")
    assert path.parent == VENV / "lib" / "tms_launch"
    assert (VENV / "share" / "ament_index" / "resource_index" / "packages" / "tms_launch").exists()
    assert (VENV / "share" / "tms_launch" / "package.xml").exists()
    out = subprocess.run([str(path), "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "--cancel-after" in out.stdout


def test_publisher_and_subscriber_processes_exchange_messages(procs):
    talker = procs([executable("tms_launch", "demo_talker"), "--ros-args", "-p", "rate_hz:=50.0"])
    listener = procs([executable("tms_launch", "demo_listener"), "--ros-args", "-p", "log_every:=25"])
    assert listener.wait_for("total=26", timeout=30), f"listener heard too little:\n{listener.output}\n{talker.output}"


def test_tms_msg_action_goal_feedback_result_across_processes(procs):
    procs([executable("tms_launch", "demo_subtask_server"), "--ros-args", "-p", "duration_s:=0.5"])
    client = procs([executable("tms_launch", "demo_subtask_client"), "--record", "initial_pose"])
    assert client.wait(40) == 0, client.output
    assert "goal accepted" in client.output
    assert "feedback step 0" in client.output
    assert "feedback demo/initial_pose done" in client.output
    assert "status SUCCEEDED result=True" in client.output


def test_tms_msg_action_cancel_is_acknowledged_by_the_server(procs):
    procs([executable("tms_launch", "demo_subtask_server"), "--ros-args", "-p", "duration_s:=10.0"])
    client = procs([executable("tms_launch", "demo_subtask_client"), "--cancel-after", "0.5"])
    assert client.wait(40) == 0, client.output
    assert "cancel acknowledged=True" in client.output
    assert "status CANCELED result=False" in client.output


def test_tms_msg_action_rejects_a_goal_without_record(procs):
    procs([executable("tms_launch", "demo_subtask_server")])
    client = procs([executable("tms_launch", "demo_subtask_client"), "--record", ""])
    assert client.wait(40) == 3, client.output
    assert "goal rejected" in client.output


def _launcher(procs, launch_file: Path):
    return procs([VENV / "bin" / "tms-launch", str(launch_file)], name="tms-launch")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "launch.yaml"
    path.write_text(text)
    return path


THREE_NODES = """
name: three
nodes:
  - {name: talker, package: tms_launch, executable: demo_talker, namespace: /t3, parameters: {rate_hz: 20.0}}
  - {name: listener, package: tms_launch, executable: demo_listener, namespace: /t3}
  - {name: subtask_server, package: tms_launch, executable: demo_subtask_server, namespace: /t3}
"""


def _node_pids(launcher_pid: int) -> list[int]:
    """Pids of the launcher's direct children (the node processes)."""
    children = Path(f"/proc/{launcher_pid}/task/{launcher_pid}/children")
    return [int(p) for p in children.read_text().split()] if children.exists() else []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie is dead for our purpose.
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except FileNotFoundError:
        return False


def test_launcher_starts_three_nodes_visible_to_a_client_and_ctrl_c_stops_them(procs, ros_node, tmp_path):
    launcher = _launcher(procs, _write(tmp_path, THREE_NODES))
    assert launcher.wait_for("all 3 node(s) of 'three' are up", timeout=90), launcher.output
    assert "[tms-launch] running 3/3: talker, listener, subtask_server" in launcher.output
    deadline = time.monotonic() + 20
    want = {("talker", "/t3"), ("listener", "/t3"), ("subtask_server", "/t3")}
    seen: set = set()
    while time.monotonic() < deadline and not want <= seen:
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)
        seen = set(ros_node.get_node_names_and_namespaces())
    assert want <= seen, f"client sees {seen}"
    pids = _node_pids(launcher.popen.pid)
    assert len(pids) == 3
    # Output of the nodes is prefixed with their name.
    assert launcher.wait_for("[listener] heard seq=", timeout=20), launcher.output
    started = time.monotonic()
    os.kill(launcher.popen.pid, signal.SIGINT)
    if launcher.wait(10) is None:  # stuck: its threads' stacks say where
        os.kill(launcher.popen.pid, signal.SIGUSR1)
        launcher.wait_for("most recent call first", 5.0)
        time.sleep(0.5)
        pytest.fail(f"tms-launch still running 10 s after SIGINT; its stacks (SIGUSR1) and output:\n{launcher.output}")
    assert launcher.popen.returncode == 0, launcher.output
    assert time.monotonic() - started < 5.0
    assert not [p for p in pids if _alive(p)], "node processes outlived the launcher"
    # The stop prints each node's CPU time: every one of them spent some (rclpy import and init alone do).
    table = launcher.output.split("CPU time per process", 1)[-1]
    for fqn in ("/t3/talker", "/t3/listener", "/t3/subtask_server"):
        match = re.search(rf"^\s+{re.escape(fqn)}\s+([0-9.]+) s\s+([0-9.]+) % of a core$", table, re.M)
        assert match and float(match[1]) > 0.05, f"{fqn} missing or 0 s in the CPU table:\n{launcher.output}"
    assert re.search(r"^\s+total\s+[0-9.]+ s\s+[0-9.]+ cores over [0-9.]+ s$", table, re.M), launcher.output


def test_launcher_prints_its_threads_stacks_on_sigusr1_and_keeps_running(procs, tmp_path):
    launch = "name: one\nnodes:\n  - {name: talker, package: tms_launch, executable: demo_talker, namespace: /u1}\n"
    launcher = _launcher(procs, _write(tmp_path, launch))
    assert launcher.wait_for("are up", timeout=90), launcher.output
    os.kill(launcher.popen.pid, signal.SIGUSR1)
    assert launcher.wait_for("most recent call first", 10.0), launcher.output
    time.sleep(0.5)  # the rest of the dump
    assert re.search(r'File ".*tms_launch/launcher\.py", line \d+ in run$', launcher.output, re.M), launcher.output
    assert launcher.popen.poll() is None, "SIGUSR1 stopped the launcher"
    os.kill(launcher.popen.pid, signal.SIGINT)
    assert launcher.wait(10) == 0, launcher.output


def test_launcher_exits_nonzero_naming_a_required_node_that_dies(procs, tmp_path):
    launcher = _launcher(procs, _write(tmp_path, THREE_NODES))
    assert launcher.wait_for("are up", timeout=90), launcher.output
    pids = _node_pids(launcher.popen.pid)
    os.kill(pids[1], signal.SIGKILL)  # the listener
    assert launcher.wait(15) == 1, launcher.output
    assert "ERROR: required node 'listener' exited with code -9" in launcher.output
    assert not [p for p in pids if _alive(p)]


def test_launcher_list_prints_nodes(procs):
    out = procs([VENV / "bin" / "tms-launch", "--list", str(ROOT / "config/launch/demo_three.yaml")])
    assert out.wait(60) == 0, out.output
    assert "/demo/talker\ttms_launch/demo_talker\trequired" in out.output


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "nodes:\n  - name: a\n    package: tms_launch\n    executable: no_such_exe\n",
            "launch.yaml:4: node 'a': package 'tms_launch' has no executable 'no_such_exe'",
        ),
        (
            "nodes:\n  - name: a\n    package: no_such_pkg\n    executable: x\n",
            "launch.yaml:4: node 'a': package 'no_such_pkg' is not in the ament index",
        ),
        ("nodes:\n  - name: a\n    package: [unclosed\n", "launch.yaml:4: malformed YAML"),
        (
            "nodes:\n  - name: a\n    package: tms_launch\n    executable: demo_talker\n    colour: red\n",
            "launch.yaml:5: node #1: unknown key 'colour'",
        ),
        (
            "nodes:\n  - name: a\n    package: tms_launch\n    executable: demo_talker\n    nice: 25\n",
            "launch.yaml:5: node 'a': nice must be within -20..19, got 25",
        ),
        (
            "nodes:\n  - name: a\n    package: tms_launch\n    executable: demo_talker\n    stop_grace_s: 0\n",
            "launch.yaml:5: node 'a': stop_grace_s must be within (0, 600] s, got 0",
        ),
        (
            "shutdown: backwards\nnodes:\n  - name: a\n    package: tms_launch\n    executable: demo_talker\n",
            "launch.yaml:1: shutdown must be one of parallel, reverse, got 'backwards'",
        ),
    ],
    ids=["unknown-executable", "unknown-package", "malformed-yaml", "unknown-key", "nice-out-of-range",
         "stop-grace-out-of-range", "unknown-shutdown"],
)
def test_bad_launch_file_names_file_and_line_and_starts_nothing(procs, tmp_path, text, expected):
    launcher = _launcher(procs, _write(tmp_path, text))
    assert launcher.wait(60) == 2, launcher.output
    assert expected in launcher.output
    assert "starting" not in launcher.output


SLOW_STOP = """
nodes:
  - {name: patient, package: tms_launch, executable: demo_talker, namespace: /slow, stop_grace_s: 10,
     parameters: {rate_hz: 5.0, shutdown_delay_s: 6.0}}
  - {name: hasty, package: tms_launch, executable: demo_talker, namespace: /slow,
     parameters: {rate_hz: 5.0, shutdown_delay_s: 6.0}}
"""


def test_launcher_gives_a_node_its_stop_grace_before_sigterm(procs, tmp_path):
    """A node with stop_grace_s 10 finishes its 6 s shutdown; one with the default 2.5 s gets SIGTERM, then SIGKILL
    at 4 s."""
    launcher = _launcher(procs, _write(tmp_path, SLOW_STOP))
    assert launcher.wait_for("all 2 node(s)", timeout=90), launcher.output
    # On the graph is not yet spinning: a SIGINT inside a node's __init__ ends it before it has a destroy_node.
    time.sleep(3.0)
    started = time.monotonic()
    os.kill(launcher.popen.pid, signal.SIGINT)
    assert launcher.wait(20) == 0, launcher.output
    assert 5.5 < time.monotonic() - started < 10.0, launcher.output
    assert "[patient] talker: shut down" in launcher.output, launcher.output
    assert "[hasty] talker: shut down" not in launcher.output, launcher.output
    assert re.search(r"hasty still running 2\.[5-9] s after SIGINT; sending SIGTERM", launcher.output), launcher.output
    assert "patient still running" not in launcher.output, launcher.output


REVERSE_STOP = """
shutdown: reverse
nodes:
  - {name: first, package: tms_launch, executable: demo_talker, namespace: /rev, parameters: {rate_hz: 5.0, \
shutdown_delay_s: 1.0}}
  - {name: second, package: tms_launch, executable: demo_talker, namespace: /rev, parameters: {rate_hz: 5.0, \
shutdown_delay_s: 1.0}}
"""


def test_launcher_reverse_shutdown_stops_the_last_started_node_first_and_alone(procs, tmp_path):
    launcher = _launcher(procs, _write(tmp_path, REVERSE_STOP))
    assert launcher.wait_for("all 2 node(s)", timeout=90), launcher.output
    time.sleep(3.0)  # both spinning (see test_launcher_gives_a_node_its_stop_grace_before_sigterm)
    started = time.monotonic()
    os.kill(launcher.popen.pid, signal.SIGINT)
    assert launcher.wait(20) == 0, launcher.output
    assert time.monotonic() - started > 1.9, "one node at a time: 1 s each"
    lines = launcher.output.splitlines()
    assert "stopping 2 process(es) (last started first, one at a time): second, first" in launcher.output
    assert lines.index("[second] talker: shut down") < lines.index("[first] talker: shut down"), launcher.output


JOB = """
parameters: {use_sim_time: false}
nodes:
  - {name: server, package: tms_launch, executable: demo_subtask_server, namespace: /job, parameters: {duration_s: 0.3}}
  - name: client
    package: tms_launch
    executable: demo_subtask_client
    namespace: /job
    arguments: [--action, /job/demo_subtask]
    on_exit: shutdown
"""


def test_launcher_ends_cleanly_when_a_job_node_finishes(procs, tmp_path):
    launcher = _launcher(procs, _write(tmp_path, JOB))
    assert launcher.wait(90) == 0, launcher.output
    assert "[client] status SUCCEEDED" in launcher.output
    assert "client finished; stopping the launch" in launcher.output


def test_launcher_parallel_startup_brings_all_nodes_up(procs, tmp_path):
    launcher = _launcher(procs, _write(tmp_path, "startup: parallel\n" + THREE_NODES))
    assert launcher.wait_for("all 3 node(s) of 'three' are up", timeout=90), launcher.output
    starts = [i for i, line in enumerate(launcher.lines) if "[tms-launch] starting" in line]
    first_running = next(i for i, line in enumerate(launcher.lines) if "[tms-launch] running" in line)
    assert len(starts) == 3 and max(starts) < first_running  # all started before any was waited for
    launcher.signal(2)
    assert launcher.wait(10) == 0


def _thread_nices(pid: int) -> set[int]:
    """The niceness of every thread of ``pid`` (field 19 of /proc/<pid>/task/<tid>/stat)."""
    nices = set()
    for stat in Path(f"/proc/{pid}/task").glob("*/stat"):
        nices.add(int(stat.read_text().rsplit(")", 1)[1].split()[16]))
    return nices


def test_launcher_nice_applies_to_every_thread_of_the_node(procs, tmp_path):
    base = os.getpriority(os.PRIO_PROCESS, 0)
    text = f"""
nodes:
  - {{name: talker, package: tms_launch, executable: demo_talker, namespace: /nice, nice: {base + 5}}}
  - {{name: listener, package: tms_launch, executable: demo_listener, namespace: /nice}}
"""
    launcher = _launcher(procs, _write(tmp_path, text))
    assert launcher.wait_for("all 2 node(s)", timeout=90), launcher.output
    talker, listener = _node_pids(launcher.popen.pid)
    assert _thread_nices(talker) == {base + 5}  # DDS and executor threads too, not only the main thread
    assert _thread_nices(listener) == {base}
    launcher.signal(2)
    assert launcher.wait(10) == 0
