"""tms_ur_experiment as its own process takes ``/sim/truth/<excavator>/hydraulics`` and the excavate leaves of
``/tms_ts/status`` and its report (written when stopped) plots one load pass's pressures.

This test is the supervisor's world: it publishes /clock, the hydraulics of zx200 (an excavator of the site), the
status of a task that excavates every 2 s of simulated time, and stands in for the one action server it waits for.
"""

from __future__ import annotations

import json
import signal
import time

from tests.rosproc import executable

LABELS = "boom_bottom,boom_rod,arm_bottom,arm_rod,bucket_bottom,bucket_rod,swing_a,swing_b,pump,relief"


def test_the_report_of_a_run_plots_the_pressures_of_a_load_pass(procs, ros_node, tmp_path):
    from action_msgs.msg import GoalStatusArray
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    from tms_msg.msg import TaskIds, TaskState, TaskStatus

    clock = ros_node.create_publisher(Clock, "/clock", 10)
    ros_node.create_publisher(GoalStatusArray, "/probe_action/_action/status", 10)  # "the server is up"
    hyd = ros_node.create_publisher(Float64MultiArray, "/sim/truth/zx200/hydraulics", 10)
    status = ros_node.create_publisher(TaskStatus, "/tms_ts/status", 10)
    starts: list = []
    ros_node.create_subscription(TaskIds, "/tms_ts/start", starts.append, 10)
    runs = tmp_path / "runs"
    proc = procs([executable("tms_ur", "tms_ur_experiment"), "--ros-args", "-p", "use_sim_time:=true",
                  "-p", f"runs_dir:={runs}", "-p", f"db_path:={tmp_path / 'db'}", "-p", "task_ids:=[2]",
                  "-p", 'wait_for_actions:=["/probe_action"]', "-p", "progress_period_s:=0.5"], name="experiment")
    sim_ns = 0
    t_start: float | None = None

    def run_for(seconds: float, until=lambda: False) -> None:
        nonlocal sim_ns
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            sim_ns += 20_000_000
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock.publish(msg)
            t = sim_ns * 1e-9
            h = Float64MultiArray()
            h.layout.dim = [MultiArrayDimension(label=LABELS, size=10, stride=10)]
            h.data = [6.0 + t % 2.0, 0.3, 8.0, 2.0, 5.0, 1.0, 0.3, 0.3, 9.0, 34.3]
            hyd.publish(h)
            if t_start is not None:  # the task: excavate 1 s, carry 1 s, again
                leaf = "LeafNodeZx200 'excavate'" if (t - t_start) % 2.0 < 1.0 else "LeafNodeZx200 'carry'"
                status.publish(TaskStatus(tasks=[TaskState(task_id=2, state=1, running_leaves=[leaf])]))
            ros_node.executor_for_test.spin_once(timeout_sec=0.02)

    run_for(60.0, until=lambda: bool(starts))
    assert starts and list(starts[0].task_ids) == [2], proc.output
    t_start = sim_ns * 1e-9
    run_for(60.0, until=lambda: sim_ns * 1e-9 > t_start + 7.0)  # three complete passes at least
    assert sim_ns * 1e-9 > t_start + 7.0, "the test's clock did not advance 7 s of simulated time in 60 s"
    proc.signal(signal.SIGINT)
    assert proc.wait(60) == 0, proc.output
    reports = sorted(runs.glob("*/metrics.json"))
    assert len(reports) == 1, proc.output
    figures = json.loads(reports[0].read_text())["hydraulics_pass"]
    assert figures is not None, proc.output
    assert figures["machine"] == "zx200" and figures["complete"] is True, figures
    assert 1.9 < figures["end_s"] - figures["start_s"] < 2.1, figures  # excavate start to the next
    assert figures["max_mpa"]["relief"] == 34.3 and 7.5 < figures["max_mpa"]["boom_bottom"] <= 8.0, figures
    assert (reports[0].parent / "hydraulics.png").stat().st_size > 5000
    assert '<img src="hydraulics.png"' in (reports[0].parent / "index.html").read_text()
