"""tms_ur_experiment stopped (SIGINT) in the middle of a run still writes the report of what it recorded; without
``wait_for_actions`` it waits for the action servers its tasks' trees call.

The supervisor runs as its own process on simulated time; this test is its world: it publishes /clock,
listens on /tms_ts/start and stands in for the one action server it is told to wait for.
"""

from __future__ import annotations

import json
import signal
import time
from pathlib import Path

from tests.rosproc import executable

TREES = Path(__file__).parent / "trees"


def test_a_run_stopped_by_sigint_writes_its_report_marked_stopped(procs, ros_node, tmp_path):
    from action_msgs.msg import GoalStatusArray
    from rosgraph_msgs.msg import Clock

    from tms_msg.msg import TaskIds

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    ros_node.create_publisher(GoalStatusArray, "/probe_action/_action/status", 10)  # "the server is up"
    starts: list = []
    ros_node.create_subscription(TaskIds, "/tms_ts/start", starts.append, 10)
    runs = tmp_path / "runs"
    proc = procs([executable("tms_ur", "tms_ur_experiment"), "--ros-args", "-p", "use_sim_time:=true",
                  "-p", f"runs_dir:={runs}", "-p", f"db_path:={tmp_path / 'db'}", "-p", "task_ids:=[1, 2]",
                  "-p", 'wait_for_actions:=["/probe_action"]', "-p", "progress_period_s:=0.5"], name="experiment")
    sim_ns = 0

    def run_for(seconds: float, until=lambda: False) -> None:
        nonlocal sim_ns
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            sim_ns += 20_000_000
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock.publish(msg)
            ros_node.executor_for_test.spin_once(timeout_sec=0.02)

    run_for(60.0, until=lambda: bool(starts))
    assert starts and list(starts[0].task_ids) == [1, 2], proc.output
    run_for(1.5)  # the run goes on for a while, then Ctrl-C
    proc.signal(signal.SIGINT)
    assert proc.wait(60) == 0, proc.output
    assert "[experiment] STOPPED before the end" in proc.output, proc.output
    reports = sorted(runs.glob("*/metrics.json"))
    assert len(reports) == 1, proc.output
    metrics = json.loads(reports[0].read_text())
    assert metrics["ended"] == "stopped" and metrics["sim_time_s"] > 0.5, metrics
    assert (reports[0].parent / "index.html").read_text().count("stopped before the end") == 2  # title and h1


def test_without_wait_for_actions_it_waits_for_the_servers_the_tasks_trees_call(procs, ros_node, tmp_path):
    """No hand list: the tasks' trees in tms_db name the action servers (leaf subtasks and their planning actions);
    the tasks start only once each of them is on the graph."""
    from action_msgs.msg import GoalStatusArray
    from rosgraph_msgs.msg import Clock

    from tms_db import open_store
    from tms_msg.msg import TaskIds

    store = open_store(path=str(tmp_path / "db"))
    try:
        store.add_task((TREES / "panel_ic120_drive.xml").read_text(), task_id=1, description="drive")
    finally:
        store.close()
    expected = ["/ic120/st_ic120_navigate_anywhere", "/ic120/navigate_to_pose"]
    clock = ros_node.create_publisher(Clock, "/clock", 10)
    starts: list = []
    ros_node.create_subscription(TaskIds, "/tms_ts/start", starts.append, 10)
    proc = procs([executable("tms_ur", "tms_ur_experiment"), "--ros-args", "-p", "use_sim_time:=true",
                  "-p", f"runs_dir:={tmp_path / 'runs'}", "-p", f"db_path:={tmp_path / 'db'}", "-p", "task_ids:=[1]",
                  "-p", "progress_period_s:=0.5"], name="experiment")
    sim_ns = 0

    def run_for(seconds: float, until=lambda: False) -> None:
        nonlocal sim_ns
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            sim_ns += 20_000_000
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock.publish(msg)
            ros_node.executor_for_test.spin_once(timeout_sec=0.02)

    waiting = f"waiting for action server(s): {', '.join(expected)}"
    run_for(60.0, until=lambda: waiting in proc.output)
    assert waiting in proc.output, proc.output
    ros_node.create_publisher(GoalStatusArray, f"{expected[0]}/_action/status", 10)
    run_for(3.0)
    assert not starts, "started before every server of the tree was up"
    ros_node.create_publisher(GoalStatusArray, f"{expected[1]}/_action/status", 10)
    run_for(60.0, until=lambda: bool(starts))
    assert starts and list(starts[0].task_ids) == [1], proc.output
