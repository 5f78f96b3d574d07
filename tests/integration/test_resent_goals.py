"""Re-sent change_pose goals to the pose the arm already holds, across processes (issue 39).

The original's ZX200 tree re-sends ``subtask_zx200_change_pose`` to ``initial_pose`` every time its loop turns
while it waits (13 goals in 5.5 s in the paper launch, all to the pose the arm held). One of them ended before
the controller's first tick, the controller's end-of-goal log line raised, rclpy aborted the goal with an empty
result, and the subtask server reported ``PLANNING_FAILED ... error_code 0``.

Here a tree of that shape (a counted loop around the original's leaf) re-sends the goal 20 times on the real
stack, every node its own process (``tests/integration/safety_stack.py``): manager, ZX200 subtask server, planner,
arm controller, COM3 converter and the MuJoCo plant over CAN. Shown: 20 results, each a success at every level
(subtask, planning, controller), the task SUCCESS as the tree defines it (every round of the loop succeeded), and
no exception in any process's log.
"""

from __future__ import annotations

import threading
import time

import pytest

from tests.integration.safety_stack import Probe, start_stack, wait_servers

pytestmark = pytest.mark.integration

TASK = 93
RESENDS = 20
#: the plant faster than the paper launch's 3x: a goal to the held pose takes >= 0.8 s simulated (the
#: controller's 0.5 s shortest segment and 0.3 s settle), so 20 of them fit in about 5 s of wall time only so
SPEED = 5.0
#: the original's tree shape: its leaf, its record and subtask, re-sent by a loop that stops after RESENDS rounds
XML = f"""<root main_tree_to_execute="BehaviorTree"><BehaviorTree ID="BehaviorTree">
<Repeat name="wait_for_dump" num_cycles="{RESENDS}">
  <Action ID="LeafNodeZx200" name="initial_pose" model_name="zx200" record_name="initial_pose"
          subtask_name="subtask_zx200_change_pose"/>
</Repeat></BehaviorTree></root>"""
#: the nodes this needs of the paper launch (the IC120's are not started: fewer processes on 2 cores)
SKIP = {"ic120/com3_bridge", "ic120/ic120_localization", "ic120/ic120_navigator", "subtasks_ic120", "tms_sp_tf"}
SERVERS = {
    "/zx200/subtask_zx200_change_pose": "tms_msg_ts.action:LeafNodeBase",
    "/zx200/tms_rp_zx200_change_pose": "tms_msg_rp.action:TmsRpZx200ChangePose",
    "/zx200/arm_controller/move": "tms_msg.action:Zx200ArmMove",
}
#: what an exception leaves in a process's log (rclpy's own lines for a raising execute callback included)
RAISED = ("Traceback", "Error raised in execute callback", "Goal state not set", "ValueError")
IDLE, RUNNING, SUCCESS = 0, 1, 2  # tms_msg/TaskState


@pytest.mark.timeout(300)
def test_twenty_resent_change_pose_goals_to_the_held_pose_all_end_with_a_result(procs, domain, ros_node, tmp_path):
    from tms_common.goals import OUTCOME_QOS
    from tms_msg.msg import SubtaskOutcome, Zx200PlanningOutcome

    stack = start_stack(procs, domain, tmp_path, SPEED, skip=SKIP,
                        tasks={TASK: (XML, "issue 39: change_pose re-sent to the held pose")})
    tail = lambda: "\n".join(f"--- {k}\n" + "\n".join(p.output.splitlines()[-12:]) for k, p in stack.items())  # noqa: E731
    missing = wait_servers(ros_node, 150.0, SERVERS)
    assert not missing, f"action servers not up: {missing}\n{tail()}"
    lock = threading.Lock()
    subtask: list[tuple[float, int, str]] = []  # (wall, error_code, error_msg) per subtask goal
    planning: list[tuple[int, str]] = []  # (error_code, message) per planning goal

    def on_subtask(msg) -> None:
        if msg.action == "/zx200/subtask_zx200_change_pose":
            with lock:
                subtask.append((time.monotonic(), int(msg.error_code), msg.error_msg))

    def on_planning(msg) -> None:
        with lock:
            planning.append((int(msg.error_code), msg.message))

    # subscribed before the probe's thread spins the node (rclpy: adding entities while it spins can kill it)
    ros_node.create_subscription(SubtaskOutcome, "/zx200/subtask_outcome", on_subtask, OUTCOME_QOS)
    ros_node.create_subscription(Zx200PlanningOutcome, "/zx200/tms_rp_zx200_outcome", on_planning, OUTCOME_QOS)
    probe = Probe(ros_node)
    try:
        # the start is a topic: sent once the manager's subscription has matched the probe's publisher
        assert probe.wait(lambda: probe.start_pub.get_subscription_count() > 0, 60.0), f"no manager\n{tail()}"
        started = time.monotonic()
        probe.start(TASK)
        assert probe.wait(lambda: probe.task(TASK) is not None, 10.0), f"task {TASK} not started\n{tail()}"
        done = lambda: probe.task(TASK)[0] not in (IDLE, RUNNING)  # noqa: E731
        assert probe.wait(done, 120.0), f"task {TASK} still {probe.task(TASK)} after 120 s\n{tail()}"
        ended = time.monotonic()
        state = probe.task(TASK)
        # the outcomes are topics of their own: give the last ones a moment after the task's end
        probe.wait(lambda: len(subtask) >= RESENDS and len(planning) >= RESENDS, 5.0)
        with lock:
            results, plans = list(subtask), list(planning)
        goals = [ln for ln in stack["zx200/excavator_arm_controller"].output.splitlines() if "goal ended" in ln]
        span = results[-1][0] - results[0][0] if results else 0.0
        print(f"\n{len(results)} change_pose results re-sent to the held pose in {ended - started:.1f} s of wall time "
              f"from the start (first to last result {span:.1f} s; plant at {SPEED:g}x); task {state}; "
              f"controller goals ended {len(goals)}, of them before a tick recorded a phase ('at once', the "
              f"goals whose log line once raised) {sum('at once' in g for g in goals)}")
        failed = [r[1:] for r in results if r[1] != SubtaskOutcome.NONE]
        # the task as the tree defines it: the loop ran its RESENDS rounds, each leaf succeeded
        assert state[0] == SUCCESS, f"task {state}; failed subtask goals {failed}\n{tail()}"
        assert len(results) == RESENDS and not failed, results
        assert len(plans) == RESENDS and all(code == 1 for code, _ in plans), plans  # TmsRpErrorCodes SUCCESS
        assert len(goals) == RESENDS and all("goal ended 1 (reached)" in g for g in goals), "\n".join(goals)
        raised = {k: [ln for ln in p.output.splitlines() if any(w in ln for w in RAISED)] for k, p in stack.items()}
        raised = {k: v for k, v in raised.items() if v}
        assert not raised, raised
    finally:
        probe.close()
