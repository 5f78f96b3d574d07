"""Cross-process: ``tms_sp_tf`` started with the ``machines`` of ``config/launch/original_machines.yaml`` keeps one
/tf tree per machine *name*.

That launch file names three machines of one kind (ic120, ic120_1, ic120_2). The node runs in its own process with
the launch file's parameters (read from the file here); this test publishes a different vessel angle and odometry
pose for each IC120 on ``/<name>/joint_states`` and ``/<name>/odom_pose`` over DDS and listens to /tf with a tf
listener built on tf2_msgs (tests/tflisten.py). Each IC120's frames carry its own prefix and follow its own topics
only; every machine of the launch file has its latched ``/<name>/robot_description``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from tests.rosproc import executable
from tests.tflisten import TfListener
from tms_model.fleet import machine_kind
from tms_model.geometry import quaternion_from_yaw
from tms_model.urdf import load_tree

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "config" / "launch" / "original_machines.yaml"

pytestmark = [pytest.mark.integration, pytest.mark.timeout(240)]

#: per IC120 name: (vessel angle [rad], map x, map y) published for it
IC120S = {"ic120": (0.15, 10.0, 1.0), "ic120_1": (0.45, 20.0, 2.0), "ic120_2": (0.75, 30.0, 3.0)}


def _tf_node_parameters() -> dict[str, Any]:
    nodes = [n for n in yaml.safe_load(LAUNCH.read_text())["nodes"] if n["executable"] == "tms_sp_tf"]
    assert len(nodes) == 1, f"{LAUNCH}: expected one tms_sp_tf node, found {len(nodes)}"
    return dict(nodes[0].get("parameters", {}))


def _ros_args(parameters: dict[str, Any]) -> list[str]:
    out = ["--ros-args"]
    for key, value in parameters.items():
        out += ["-p", f"{key}:={yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()}"]
    return out


def _spin_until(node: Any, done: Any, timeout: float, every: tuple[float, Any] | None = None) -> bool:
    end = time.monotonic() + timeout
    next_call = 0.0
    while not done() and time.monotonic() < end:
        if every and time.monotonic() >= next_call:
            every[1]()
            next_call = time.monotonic() + every[0]
        node.executor_for_test.spin_once(timeout_sec=0.02)
    return done()


def test_three_ic120s_of_the_original_launch_are_three_trees(procs, ros_node) -> None:
    from nav_msgs.msg import Odometry
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    parameters = _tf_node_parameters()
    machines = [str(m) for m in parameters["machines"]]
    assert set(IC120S) <= set(machines), machines
    assert {machine_kind(n) for n in IC120S} == {"ic120"}, "the three names are of one kind"
    tf_node = procs([executable("tms_sp", "tms_sp_tf"), *_ros_args(parameters)], name="tms_sp_tf")
    assert tf_node.wait_for("tms_sp_tf ready", 90), tf_node.output

    tf = TfListener(ros_node)
    latched = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    descriptions: dict[str, str] = {}
    for name in machines:
        ros_node.create_subscription(String, f"/{name}/robot_description",
                                     lambda m, n=name: descriptions.__setitem__(n, m.data), latched)
    joints = {n: ros_node.create_publisher(JointState, f"/{n}/joint_states", 10) for n in IC120S}
    odoms = {n: ros_node.create_publisher(Odometry, f"/{n}/odom_pose", 10) for n in IC120S}

    def publish() -> None:
        stamp = ros_node.get_clock().now().to_msg()
        for name, (angle, x, y) in IC120S.items():
            js = JointState(name=["vessel_joint"], position=[angle])
            js.header.stamp = stamp
            joints[name].publish(js)
            od = Odometry()
            od.header.stamp, od.header.frame_id = stamp, "map"  # a pose in map: map -> odom is the identity
            od.pose.pose.position.x, od.pose.pose.position.y = x, y
            q = od.pose.pose.orientation
            q.x, q.y, q.z, q.w = quaternion_from_yaw(0.0)
            odoms[name].publish(od)

    trees = {n: load_tree(n) for n in IC120S}
    pins = {n: trees[n].frame("vessel_pin_link") for n in IC120S}
    assert len(set(pins.values())) == 3, pins  # each name its own frames

    def complete() -> bool:
        return (all(tf.lookup("map", pin) is not None for pin in pins.values())
                and set(descriptions) == set(machines))

    assert _spin_until(ros_node, complete, 60, every=(0.1, publish)), (
        f"static {sorted(tf.static)}\ndynamic {sorted(tf.dynamic)}\ndescriptions {sorted(descriptions)}\n"
        f"{tf_node.output}")

    for name, (angle, x, y) in IC120S.items():
        tree = trees[name]
        base = tree.frame("base_link")
        # its own pose: map -> <name>_tf/odom -> <name>_tf/base_link
        at = tf.lookup("map", base)
        assert np.allclose(at.translation, (x, y, 0.0), atol=1e-9), (name, at)
        # its own vessel angle, in its own tree: the pin's rotation about the hinge is this machine's angle
        pin = tf.lookup(base, pins[name])
        dump = next(j for j in tree.moving if j.state == "vessel_joint")
        want = dump.transform(angle)
        assert np.allclose(pin.matrix(), want.matrix(), atol=1e-9), (name, pin, want)
        others = [a for n, (a, _, _) in IC120S.items() if n != name]
        assert not any(np.allclose(pin.matrix(), dump.transform(a).matrix(), atol=1e-6) for a in others), name
        # the pin's parent chain stays inside this machine's frames
        assert tf.dynamic[pins[name]][-1][1] == tree.frame(dump.parent)
        assert math.isclose(tf.lookup("map", tree.frame("odom")).translation[0], 0.0, abs_tol=1e-12)

    # one URDF per machine name of the launch file; each IC120's names its links with its own prefix
    assert set(descriptions) == set(machines)
    for name, tree in trees.items():
        others = [trees[n].frame("base_link") for n in IC120S if n != name]
        assert f'"{tree.frame("base_link")}"' in descriptions[name], name
        assert not any(f'"{o}"' in descriptions[name] for o in others), name
