"""The zx200_planner node: one node on the graph, start-up parameters read-only, rclpy Node kwargs taken."""

from __future__ import annotations

import time


def test_the_planner_is_one_node_that_answers_and_refuses_to_change_its_start_up_parameters(ros_node) -> None:
    from rclpy.parameter import Parameter

    from tms_if_opera.nodes.zx200_planner import ArmPlannerNode

    planner = ArmPlannerNode(namespace="/zx200", context=ros_node.context)
    try:
        assert planner.get_fully_qualified_name() == "/zx200/zx200_planner"
        # its joint_states reader used to be a second node that advertised parameter services but was never
        # spun, so `ros2 param list` hung on it: now only the planner itself is on the graph
        end = time.monotonic() + 5.0
        while "zx200_planner" not in ros_node.get_node_names() and time.monotonic() < end:
            ros_node.executor_for_test.spin_once(timeout_sec=0.05)
        names = ros_node.get_node_names()
        assert "zx200_planner" in names and not any(n.startswith("zx200_planner_") for n in names), names
        [answer] = planner.set_parameters([Parameter("machine_config", Parameter.Type.STRING, "/tmp/other.yaml")])
        assert answer.successful is False and "read-only" in answer.reason, answer
    finally:
        planner.destroy_node()
