"""Cross-process: the site's /tf, /tf_static and robot_description as an RViz user receives them.

sim_plant (CAN only) <-> com3_bridge (zx200, ic120) -> ic120_localization, all -> tms_sp_tf -> this test, which
moves the ZX200's arm with a JointCmd publisher on /zx200/front_cmd and listens with a tf listener built on
tf2_msgs only (tests/tflisten.py). While the arm moves, the chain map -> bucket_end_link composed from /tf
agrees with tms_model's kinematics of the joint_states of the same stamp within 1 cm; at rest the tip and the
bases sit where the plant has them; a subscriber that joins late still receives each machine's URDF and
/tf_static.
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from tests.rosproc import executable
from tests.tflisten import TfListener
from tests.tracked_stack import can_groups
from tms_model.excavator.kinematics import JOINTS, load_kinematics
from tms_model.geometry import yaw_from_quaternion
from tms_model.transform import Transform
from tms_model.urdf import load_tree

pytestmark = pytest.mark.integration

TIP_TOL_M = 0.01
VELOCITY = 1  # JointCmd control_type "1:velocity" (com3_msgs documents it in a comment, no constant)
KIN = load_kinematics("zx200")


def _start_stack(procs: Any, domain: int) -> dict[str, Any]:
    buses = can_groups(domain)
    plant_cmd = [executable("sim_bridge", "sim_plant"), "--ros-args", "-p", "speed:=1.0"]
    for m, cfg in buses.items():
        plant_cmd += ["-p", f"{m}_can_interface:={cfg['interface']}", "-p", f"{m}_can_channel:={cfg['channel']}",
                      "-p", f"{m}_can_port:={cfg['port']}"]
    out = {"sim_plant": procs(plant_cmd, name="sim_plant")}
    for m, cfg in buses.items():
        out[f"bridge_{m}"] = procs([executable("com3_can", "com3_bridge"), "--ros-args", "-r", f"__ns:=/{m}",
                                    "-p", f"machine:={m}", "-p", f"can_interface:={cfg['interface']}",
                                    "-p", f"can_channel:={cfg['channel']}", "-p", f"can_port:={cfg['port']}"],
                                   name=f"com3_bridge_{m}")
    out["localization"] = procs([executable("tms_rp", "ic120_localization"), "--ros-args", "-r", "__ns:=/ic120"],
                                name="ic120_localization")
    out["tf"] = procs([executable("tms_sp", "tms_sp_tf")], name="tms_sp_tf")
    for name, proc in out.items():
        ready = {"sim_plant": "sim_plant: running", "localization": "EKF ready", "tf": "tms_sp_tf ready"}.get(
            name, "com3_bridge ready")
        assert proc.wait_for(ready, 90), f"{name}:\n{proc.output}"
    return out


def _seconds(header: Any) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process [s] (/proc/<pid>/stat fields 14, 15)."""
    fields = open(f"/proc/{pid}/stat").read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _front_cmd_type(node: Any, timeout: float = 30.0) -> Any:
    """The JointCmd type com3_bridge subscribes on /zx200/front_cmd (the peer's com3_msgs once it speaks it)."""
    import importlib

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for name, types in node.get_topic_names_and_types():
            if name == "/zx200/front_cmd" and types:
                pkg, _, typ = types[0].split("/")
                return getattr(importlib.import_module(f"{pkg}.msg"), typ)
        node.executor_for_test.spin_once(timeout_sec=0.1)
    raise AssertionError("nobody subscribes /zx200/front_cmd")


def _spin_until(node: Any, done: Any, timeout: float, every: tuple[float, Any] | None = None) -> bool:
    end = time.monotonic() + timeout
    next_call = 0.0
    while not done() and time.monotonic() < end:
        if every and time.monotonic() >= next_call:
            every[1]()
            next_call = time.monotonic() + every[0]
        node.executor_for_test.spin_once(timeout_sec=0.01)
    return done()


def test_tf_chain_follows_the_moving_arm_and_late_subscribers_get_the_urdfs(procs, domain, ros_node) -> None:
    from geometry_msgs.msg import PointStamped, PoseStamped
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    stack = _start_stack(procs, domain)
    tf = TfListener(ros_node)
    joints: dict[float, np.ndarray] = {}

    def on_joints(m: JointState) -> None:
        q = dict(zip(m.name, m.position, strict=True))
        joints[_seconds(m.header)] = np.array([q[j] for j in JOINTS])

    truth: dict[str, PoseStamped] = {}
    tip_truth: deque[PointStamped] = deque(maxlen=300)  # 3 s of the plant's 100 Hz truth
    ros_node.create_subscription(PointStamped, "/sim/truth/zx200/bucket_tip", lambda m: tip_truth.append(m), 10)
    ros_node.create_subscription(JointState, "/zx200/joint_states", on_joints, 200)
    for m in ("zx200", "ic120"):
        ros_node.create_subscription(
            PoseStamped, f"/sim/truth/{m}/pose", lambda msg, m=m: truth.__setitem__(m, msg), 10
        )
    joint_cmd = _front_cmd_type(ros_node)
    pub = ros_node.create_publisher(joint_cmd, "/zx200/front_cmd", 10)
    ic_base = "ic120_tf/base_link"
    assert _spin_until(ros_node, lambda: tf.lookup("map", "bucket_end_link") is not None
                       and tf.lookup("map", ic_base) is not None and len(truth) == 2, 60), (
        f"no chain: static {sorted(tf.static)}, dynamic {sorted(tf.dynamic)}\n{stack['tf'].output}")
    assert tf.lookup("world", "map") is not None

    # move every front joint at once for 6 s (a JointCmd every 50 ms: the converter's watchdog is 0.5 s)
    velocity = [0.25, -0.12, 0.3, 0.4]

    def command() -> None:
        pub.publish(joint_cmd(joint_name=list(JOINTS), control_type=VELOCITY, velocity=velocity))

    start = time.monotonic()
    first = len(joints)
    cpu0, tf0 = _cpu_seconds(stack["tf"].popen.pid), tf.messages
    _spin_until(ros_node, lambda: time.monotonic() - start > 6.0, 10.0, every=(0.05, command))
    wall = time.monotonic() - start
    print(f"tms_sp_tf: {100 * (_cpu_seconds(stack['tf'].popen.pid) - cpu0) / wall:.1f} % of a core for "
          f"{(tf.messages - tf0) / wall:.0f} /tf messages/s (both machines' joint_states, odometry, map_to_odom)")
    for _ in range(5):
        pub.publish(joint_cmd(joint_name=list(JOINTS), control_type=VELOCITY, velocity=[0.0] * 4))
    # wait for rest (the swing's dead time, lag and acceleration limit take seconds) on both sides: the /tf tip
    # and the plant's tip each unchanged over 0.5 s of their own stamps (this process may lag behind the
    # 200 /tf messages a second, so it waits on stamps, not on its clock)
    stop = time.time()

    def settled() -> bool:
        s = tf.stamps("bucket_link")
        if not s or s[-1] < stop + 1.0 or len(tip_truth) < 2 or s[-1] - s[0] < 0.5:
            return False
        now, before = (tf.lookup("base_link", "bucket_end_link", at=t) for t in (s[-1], s[-1] - 0.5))
        p = [np.array([m.point.x, m.point.y, m.point.z]) for m in tip_truth]
        old = [m for m in tip_truth if _seconds(m.header) <= _seconds(tip_truth[-1].header) - 0.5]
        return (old and np.linalg.norm(np.subtract(now.translation, before.translation)) < 1e-3
                and np.linalg.norm(p[-1] - [old[-1].point.x, old[-1].point.y, old[-1].point.z]) < 1e-3)

    assert _spin_until(ros_node, settled, 60), "the arm did not come to rest on /tf and in the plant"

    # every joint_states stamp the tf node turned into transforms: the /tf chain against the kinematics
    stamps = sorted(joints)[first:]
    errors, tips = [], []
    for t in stamps:
        if t not in tf.stamps("bucket_link"):
            continue
        base = tf.lookup("map", "base_link", at=t)
        if base is None:  # before the first odometry (as tf2, no extrapolation into the past)
            continue
        chain = tf.lookup("map", "bucket_end_link", at=t)
        assert chain is not None, (t, {c: tf.stamps(c)[:2] for c in ("odom", "base_link", "body_link", "bucket_link")})
        expected = base.apply(KIN.tip_position(joints[t]))
        errors.append(float(np.linalg.norm(np.array(chain.translation) - expected)))
        tips.append(expected)
    assert len(errors) > 50, f"only {len(errors)} of {len(stamps)} joint_states stamps found on /tf"
    travel = float(np.linalg.norm(tips[-1] - tips[0]))
    assert travel > 1.0, f"the bucket tip moved only {travel:.2f} m: the arm did not move"
    print(f"/tf chain map -> bucket_end_link vs kinematics: max {max(errors) * 1000:.3f} mm over {len(errors)} stamps, "
          f"tip travel {travel:.2f} m")
    assert max(errors) < TIP_TOL_M, (
        f"/tf chain vs kinematics: max {max(errors) * 1000:.1f} mm over {len(errors)} stamps"
    )

    # at rest, the /tf tip is where the plant has it: relative to the base within 1 cm (joints over CAN), in map
    # within the plant's RTK noise on the ZX200's position (config/sim/plant.yaml: 1 cm horizontal, 2 cm
    # vertical, 1 sigma; 5 sigma here)
    tip = tf.lookup("map", "bucket_end_link")
    plant_tip = np.array([tip_truth[-1].point.x, tip_truth[-1].point.y, tip_truth[-1].point.z])
    bp = truth["zx200"].pose
    plant_base = Transform((bp.position.x, bp.position.y, bp.position.z),
                           (bp.orientation.x, bp.orientation.y, bp.orientation.z, bp.orientation.w))
    relative = np.linalg.norm(np.array(tf.lookup("base_link", "bucket_end_link").translation)
                              - plant_base.inverse().apply(plant_tip))
    off = np.array(tip.translation) - plant_tip
    print(f"at rest: /tf tip vs the plant's: {relative * 1000:.1f} mm relative to the base, "
          f"{np.linalg.norm(off[:2]) * 1000:.1f} mm horizontal / {abs(off[2]) * 1000:.1f} mm vertical in map")
    assert relative < TIP_TOL_M, (tip.translation, plant_tip, plant_base)
    assert np.linalg.norm(off[:2]) < 0.05 and abs(off[2]) < 0.10, (tip.translation, plant_tip)

    # the bases where the plant has them (the ZX200 from RTK GNSS, the IC120 through odometry + EKF)
    for machine, frame, tol in (("zx200", "base_link", 0.05), ("ic120", ic_base, 0.3)):
        base = tf.lookup("map", frame)
        p = truth[machine].pose
        off = np.linalg.norm(np.array(base.translation[:2]) - [p.position.x, p.position.y])
        dyaw = math.remainder(yaw_from_quaternion(base.rotation) - yaw_from_quaternion(p.orientation), 2 * math.pi)
        assert off < tol and abs(dyaw) < 0.05, (machine, base, p)

    # a late subscriber: the latched URDFs (parse with urdfdom through pinocchio) and /tf_static
    latched = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    descriptions: dict[str, str] = {}
    for m in ("zx200", "ic120"):
        ros_node.create_subscription(String, f"/{m}/robot_description",
                                     lambda msg, m=m: descriptions.__setitem__(m, msg.data), latched)
    late = TfListener(ros_node)
    assert _spin_until(ros_node, lambda: len(descriptions) == 2 and "map" in late.static, 30), (
        sorted(descriptions), sorted(late.static))
    for m, description in descriptions.items():
        tree = load_tree(m)
        assert description == tree.urdf()
        model = pin.buildModelFromXML(description)
        assert {f.name for f in model.frames} >= {tree.frame(link) for link in tree.links}, m
    assert set(late.static) == {"map", "track_link", "bucket_end_link", "ic120_tf/body_link"}
    for name, proc in stack.items():
        assert proc.popen.poll() is None, f"{name} died:\n{proc.output}"
    assert "ignored" not in stack["tf"].output, stack["tf"].output
