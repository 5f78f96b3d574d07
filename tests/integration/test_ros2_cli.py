"""Good manners under the ``ros2`` command-line tool, with the whole paper launch running.

The paper launch starts as ``make demo`` starts it (``tms-launch config/launch/paper_experiment.yaml`` on a fresh
embedded DB seeded with ``paper``; see :func:`tests.integration.test_paper_cycle._start`). Then, from this test
process, what ``ros2 node list``, ``ros2 param list`` and ``ros2 param set`` do, through the same public
rclpy calls ros2cli makes (the graph, and each node's ``list_parameters`` / ``set_parameters`` services):
ros2cli itself is not among the ROS 2 wheels on PyPI that the project installs.

* the graph shows exactly the nodes of the launch file (no helper node: a helper that advertises
  parameter services but is never spun makes ``ros2 param list`` hang);
* every node answers ``list_parameters`` and the whole listing returns within 10 s;
* a parameter read only at start-up refuses ``set_parameters`` (rclpy: "parameter is read-only"), so
  ``ros2 param set`` reports a failure instead of a success that changes nothing.
"""

from __future__ import annotations

import time

import pytest
import yaml

from tests.integration.test_paper_cycle import _start

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]

LIST_BUDGET_S = 10.0
UP_TIMEOUT_S = 180.0
#: (node, parameter read only at start-up, a new value): each must be refused
READ_ONLY = [("/sim_plant", "speed", 2.0), ("/zx200/com3_bridge", "machine", "ic120"),
             ("/ic120/ic120_navigator", "pose_timeout_s", 5.0), ("/tms_sp_sensing", "rate_hz", 5.0)]


def _expected_nodes(launch_path) -> set[str]:
    launch = yaml.safe_load(launch_path.read_text())
    return {f"{n.get('namespace', '').rstrip('/')}/{n['name']}" for n in launch["nodes"]}


def _graph(node) -> set[str]:
    """``ros2 node list``: the nodes on the graph, hidden ones (a name starting with "_") left out as ros2cli does."""
    return {f"{ns.rstrip('/')}/{name}" for name, ns in node.get_node_names_and_namespaces() if not name.startswith("_")}


def _wait(futures: dict, deadline: float, executor) -> None:
    while time.monotonic() < deadline and not all(f.done() for f in futures.values()):
        executor.spin_once(timeout_sec=0.05)


def test_ros2_param_list_and_set_with_the_paper_launch_up(procs, domain, tmp_path, ros_node):
    from rcl_interfaces.srv import ListParameters, SetParameters
    from rclpy.parameter import Parameter

    launch = _start(procs, domain, tmp_path)
    expected = _expected_nodes(tmp_path / "paper_one_cycle.yaml")
    assert launch.wait_for("are up; Ctrl-C stops them", UP_TIMEOUT_S), launch.output[-4000:]
    executor = ros_node.executor_for_test
    me = ros_node.get_fully_qualified_name()

    # ros2 node list: the nodes a user started, nothing else
    end = time.monotonic() + 10.0
    while not expected <= _graph(ros_node) and time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    on_graph = _graph(ros_node) - {me}
    assert on_graph == expected, (f"ros2 node list: not started by the user: {sorted(on_graph - expected)}; "
                                  f"missing: {sorted(expected - on_graph)}")

    # ros2 param list: every node on the graph, within the budget
    start = time.monotonic()
    deadline = start + LIST_BUDGET_S
    clients = {name: ros_node.create_client(ListParameters, f"{name}/list_parameters") for name in sorted(on_graph)}
    try:
        missing = [
            n for n, c in clients.items() if not c.wait_for_service(timeout_sec=max(0.0, deadline - time.monotonic()))
        ]
        assert not missing, f"no list_parameters service: {missing}"
        futures = {n: c.call_async(ListParameters.Request(depth=ListParameters.Request.DEPTH_RECURSIVE))
                   for n, c in clients.items()}
        _wait(futures, deadline, executor)
        took = time.monotonic() - start
        silent = sorted(n for n, f in futures.items() if not f.done())
        assert not silent, f"ros2 param list: no answer within {LIST_BUDGET_S:g} s from {silent}"
        listed = {n: set(f.result().result.names) for n, f in futures.items()}
        print(f"param list of {len(listed)} nodes in {took:.2f} s")
        assert all("use_sim_time" in names for names in listed.values()), listed
        for node, param, _ in READ_ONLY:
            assert param in listed[node], (node, sorted(listed[node]))
    finally:
        for c in clients.values():
            ros_node.destroy_client(c)

    # ros2 param set on a start-up parameter: refused, naming why
    setters = {node: ros_node.create_client(SetParameters, f"{node}/set_parameters") for node, _, _ in READ_ONLY}
    try:
        futures = {node: setters[node].call_async(SetParameters.Request(
            parameters=[Parameter(param, value=value).to_parameter_msg()])) for node, param, value in READ_ONLY}
        _wait(futures, time.monotonic() + 10.0, executor)
        for node, param, _ in READ_ONLY:
            assert futures[node].done(), f"{node}: set_parameters unanswered"
            result = futures[node].result().results[0]
            assert not result.successful and "read-only" in result.reason, (node, param, result)
    finally:
        for c in setters.values():
            ros_node.destroy_client(c)
