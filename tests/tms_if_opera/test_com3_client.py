"""An OPERA-style client drives the plant's arm: com3_msgs/JointCmd on ``/zx200/front_cmd``, nothing of ours.

sim_plant (MuJoCo, CAN only) <-> com3_bridge (zx200) <- this test, whose client uses only OPERA com3_ros's
type and topic (``com3_msgs/msg/JointCmd``, control_type 1 = velocity) and reads ``sensor_msgs/JointState``
and the plant's truth. The boom moves the commanded way over CAN and stops when the commands stop (the
converter's watchdog neutralises the channel).
"""

from __future__ import annotations

import time
from typing import Any

import pytest

from tests.arm_stack import _zx_bus
from tests.rosproc import executable

pytestmark = [pytest.mark.integration]

BOOM_RATE = 0.08  # [rad/s] well inside the boom's limits


def _spin_until(node: Any, pred: Any, timeout: float, every: tuple[float, Any] | None = None) -> bool:
    end = time.monotonic() + timeout
    next_call = time.monotonic()
    while time.monotonic() < end and not pred():
        if every and time.monotonic() >= next_call:
            every[1]()
            next_call = time.monotonic() + every[0]
        node.executor_for_test.spin_once(timeout_sec=0.01)
    return pred()


def test_com3_msgs_joint_cmd_on_front_cmd_moves_the_plant_arm(procs, domain, ros_node, tmp_path) -> None:
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import JointState

    from com3_msgs.msg import JointCmd
    from tms_common.config import config_path

    cfg_file = tmp_path / "plant.yaml"
    cfg_file.write_text(config_path("sim", "plant.yaml").read_text())
    bus = _zx_bus(domain)
    sim_args = [str(executable("sim_bridge", "sim_plant")), "--ros-args", "-p", f"config:={cfg_file}",
                "-p", f"zx200_can_interface:={bus['interface']}", "-p", f"zx200_can_channel:={bus['channel']}"]
    bridge_args = [str(executable("com3_can", "com3_bridge")), "--ros-args", "-r", "__ns:=/zx200",
                   "-p", "machine:=zx200", "-p", f"can_interface:={bus['interface']}",
                   "-p", f"can_channel:={bus['channel']}"]
    if "port" in bus:
        sim_args += ["-p", f"zx200_can_port:={bus['port']}"]
        bridge_args += ["-p", f"can_port:={bus['port']}"]
    sim = procs(sim_args, name="sim_plant")
    assert sim.wait_for("sim_plant: running", 90), sim.output
    bridge = procs(bridge_args, name="com3_bridge")
    assert bridge.wait_for("com3_bridge ready", 60), bridge.output

    boom: list[tuple[float, float]] = []  # (monotonic, boom angle) from the converter's joint_states
    tip: list[float] = []

    def on_js(msg: JointState) -> None:
        if "boom_joint" in msg.name:
            boom.append((time.monotonic(), msg.position[list(msg.name).index("boom_joint")]))

    ros_node.create_subscription(JointState, "/zx200/joint_states", on_js, 50)
    ros_node.create_subscription(PointStamped, "/sim/truth/zx200/bucket_tip", lambda m: tip.__setitem__(
        slice(None), [m.point.x, m.point.y, m.point.z]), 10)
    pub = ros_node.create_publisher(JointCmd, "/zx200/front_cmd", 10)
    assert _spin_until(ros_node, lambda: boom and tip and pub.get_subscription_count() > 0, 60), \
        f"no joint_states / truth / front_cmd subscriber\n{bridge.output}"
    q0, z0 = boom[-1][1], tip[2]

    cmd = JointCmd(joint_name=["boom_joint"], control_type=1, velocity=[BOOM_RATE])  # 1: com3_ros's velocity
    t_start = time.monotonic()
    assert _spin_until(ros_node, lambda: boom[-1][1] - q0 > 0.15, 30, (0.05, lambda: pub.publish(cmd))), (
        f"boom moved {boom[-1][1] - q0:+.3f} rad in {time.monotonic() - t_start:.1f} s of +{BOOM_RATE} rad/s "
        f"commands\n{bridge.output}")
    # the plant's own truth (not the converter's report) shows the arm moved: a positive boom angle lowers the
    # boom (the COM3 boom pair is down/up), so the tip goes down
    assert tip[2] < z0 - 0.1, f"bucket tip z {z0:.3f} -> {tip[2]:.3f} m: +boom_joint lowers the boom and the tip"

    # commands stop: the converter's watchdog (0.5 s) neutralises the front, the plant brings the boom to rest
    t_stop = time.monotonic()
    _spin_until(ros_node, lambda: False, 3.0)
    settled = [q for t, q in boom if t > t_stop + 2.0]
    assert settled and max(settled) - min(settled) < 0.01, (
        f"boom still moving after the commands stopped: {settled[:5]}"
    )
