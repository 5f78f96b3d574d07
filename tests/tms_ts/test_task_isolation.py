"""No error of one task's step ends another task or the manager's tick (issue 38), with the manager's real ROS port.

rclpy raised ``ValueError: Failed to create action client due to invalid topic name`` for a leaf named
``d37pxi_24＿``, in ``TaskRun.step``'s server check, outside the try around the tree's tick: the manager's timer died.
The loader now refuses such names; here one is forced past it (set on a loaded leaf, as a name that somehow got
through would be) to show the second line of defence: the port names it as a TreeRuntimeError and the step ends that
task FAILURE. And a ``{key}`` record_name, read only when the leaf starts, ends its task FAILURE naming it.
"""

from __future__ import annotations

import time

from tms_ts.bt.core import TreeContext
from tms_ts.loader import load_tree
from tms_ts.task import FAILED, SUCCEEDED, TaskRun


def doc(body: str) -> str:
    return f'<root main_tree_to_execute="Main"><BehaviorTree ID="Main">{body}</BehaviorTree></root>'


def leaf(record: str = "initial_pose") -> str:
    return (
        f'<Action ID="LeafNodeZx200" model_name="zx200" subtask_name="subtask_zx200_change_pose" '
        f'record_name="{record}"/>'
    )


def step_all(runs: list[TaskRun], seconds: float, spin) -> None:
    """The manager's tick loop: step every run, never letting an exception out (the test fails if one does)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end and not all(r.done for r in runs):
        for run in runs:
            if not run.done:
                run.step()
        spin()


def test_a_bad_name_past_the_loader_ends_its_task_only_and_a_run_time_record_is_checked(ros_node) -> None:
    from rclpy.action import ActionServer

    from tms_msg_ts.action import LeafNodeBase
    from tms_ts.nodes.ros_port import ManagerRosPort

    port = ManagerRosPort(ros_node)
    # a subtask server for the record case: the task must get past "starting" to read its record
    server = ActionServer(ros_node, LeafNodeBase, "/zx200/subtask_zx200_change_pose", execute_callback=lambda gh: None)

    def ctx() -> TreeContext:
        return TreeContext(ros=port, server_lost_s=3.0)

    bad_name = load_tree(doc(leaf()), ctx(), source="task 1")
    (the_leaf,) = bad_name.leaves
    the_leaf.model_name, the_leaf.action = "d37pxi_24＿", "/d37pxi_24＿/subtask_zx200_change_pose"
    bad_record = load_tree(doc(f'<Sequence><SetBlackboard output_key="rec" value="pose "/>{leaf("{rec}")}</Sequence>'),
                           ctx(), source="task 2")
    good = load_tree(doc('<Delay delay_msec="300"><AlwaysSuccess/></Delay>'), ctx(), source="task 3")
    runs = [TaskRun(1, bad_name, server_wait_s=5.0), TaskRun(2, bad_record, server_wait_s=10.0),
            TaskRun(3, good, server_wait_s=5.0)]
    step_all(runs, 20.0, lambda: ros_node.executor_for_test.spin_once(timeout_sec=0.02))
    server.destroy()

    assert [r.state for r in runs] == [FAILED, FAILED, SUCCEEDED], [(r.state, r.message) for r in runs]
    assert "TreeRuntimeError" in runs[0].message and "d37pxi_24＿" in runs[0].message, runs[0].message
    assert "LeafNodeZx200 (task 2 line 1, column" in runs[1].message, runs[1].message
    assert "'pose '" in runs[1].message and "blackboard key 'rec'" in runs[1].message


def test_a_cancel_whose_halt_raises_ends_that_task_and_returns() -> None:
    # a cancel runs in the manager's subscription callback: an error while halting must end that task, not the node
    from tms_ts.bt.core import RUNNING, Port, StatefulNode
    from tms_ts.loader import register_node

    class HaltRaises(StatefulNode):
        PORTS: dict[str, Port] = {}

        def on_start(self):
            return RUNNING

        def on_running(self):
            return RUNNING

        def on_halted(self) -> None:
            raise RuntimeError("stuck actuator")

    register_node("HaltRaisesForTest", HaltRaises)
    run = TaskRun(5, load_tree(doc("<HaltRaisesForTest/>")), server_wait_s=1.0)
    other = TaskRun(6, load_tree(doc('<Delay delay_msec="100"><AlwaysSuccess/></Delay>')), server_wait_s=1.0)
    run.step()
    other.step()
    run.cancel("canceled by /tms_ts/cancel")  # raised RuntimeError out of the callback before
    assert run.state == FAILED and "stuck actuator" in run.message and "canceled by /tms_ts/cancel" in run.message
    step_all([other], 5.0, lambda: time.sleep(0.01))
    assert other.state == SUCCEEDED
