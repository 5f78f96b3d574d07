"""The whole ZX200 arm stack in separate processes, driven over ROS and COM3 CAN (fixture and helpers).

``arm_stack(ic120_pose=...)`` starts ``sim_plant`` (MuJoCo plant, CAN only), ``com3_bridge`` (machine
zx200), ``excavator_arm_controller`` and ``zx200_planner`` on this test's ROS domain and its own
udp_multicast group/port (or vcan0 with ``TMS_CAN_TEST_BACKEND=socketcan``), all with ``use_sim_time``.
The returned :class:`ArmStack` sends planning goals and reads the plant's truth (bucket tip, soil).
"""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.rosproc import executable, free_can_ports

#: Real-time factor of the plant in the integration tests (1.0: the nodes are timed against wall-clock
#: CAN/DDS transport; the controller's dead-time model assumes real-time transport delays).
SIM_SPEED = float(os.environ.get("ZX200_TEST_SIM_SPEED", "1.0"))


@contextmanager
def joint_states_held_at(node: Any, q: list[float], period_s: float = 0.01) -> Iterator[None]:
    """Publish ``/zx200/joint_states`` at pose ``q`` (at rest) every ``period_s`` from a thread: a controller
    process under test sees an arm that holds still wherever it is commanded."""
    from sensor_msgs.msg import JointState

    from tms_model.excavator.kinematics import JOINTS

    pub = node.create_publisher(JointState, "/zx200/joint_states", 10)
    stop = threading.Event()

    def feed() -> None:
        msg = JointState(name=list(JOINTS), position=[float(v) for v in q], velocity=[0.0] * len(JOINTS))
        while not stop.is_set():
            pub.publish(msg)
            time.sleep(period_s)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    try:
        yield
    finally:
        stop.set()
        feeder.join(2.0)


def _zx_bus(domain: int) -> dict[str, Any]:
    backend = os.environ.get("TMS_CAN_TEST_BACKEND", "udp_multicast")
    if backend == "socketcan":
        from com3_can.bus import socketcan_available

        channel = os.environ.get("TMS_CAN_TEST_CHANNEL", "vcan0")
        if not socketcan_available() or not Path("/sys/class/net", channel).exists():
            pytest.skip(f"SocketCAN interface {channel} is not available in this kernel")
        return {"interface": "socketcan", "channel": channel}
    rng = random.Random(os.getpid() * 7907 + domain + time.monotonic_ns())
    return {"interface": "udp_multicast", "channel": f"239.76.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
            "port": free_can_ports(domain, 1, rng)[0]}


@dataclass
class PlanningResult:
    """A planning goal's end as a client sees it: the result's ``error_code`` (tms_msg_rp/TmsRpErrorCodes) and
    the planner's ``message`` from ``/zx200/tms_rp_zx200_outcome`` (tms_msg/Zx200PlanningOutcome)."""

    error_code: Any
    message: str


class ArmStack:
    """The test process's view of the running stack: action clients and truth subscribers."""

    def __init__(self, node: Any) -> None:
        from geometry_msgs.msg import PointStamped
        from rclpy.action import ActionClient
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from tms_common.goals import OUTCOME_QOS
        from tms_msg.msg import Zx200PlanningOutcome
        from tms_msg.srv import Zx200ChangePoseOptions
        from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple

        self.node = node
        self.tip: list[float] | None = None
        self.soil: list[float] | None = None
        self.q: list[float] | None = None
        self.dq_log: list[tuple[float, list[float], list[float]]] = []
        self.feedback: list[str] = []
        node.create_subscription(PointStamped, "/sim/truth/zx200/bucket_tip",
                                 lambda m: setattr(self, "tip", [m.point.x, m.point.y, m.point.z]), 10)
        node.create_subscription(
            Float64MultiArray, "/sim/truth/soil", lambda m: setattr(self, "soil", list(m.data)), 10
        )
        node.create_subscription(JointState, "/zx200/joint_states", self._on_js, 50)
        self.outcomes: dict[bytes, Any] = {}
        node.create_subscription(Zx200PlanningOutcome, "/zx200/tms_rp_zx200_outcome",
                                 lambda m: self.outcomes.__setitem__(bytes(m.goal_id.uuid), m), OUTCOME_QOS)
        self.options = node.create_client(Zx200ChangePoseOptions, "/zx200/tms_rp_zx200_change_pose/options")
        self.clients = {
            "change_pose": ActionClient(node, TmsRpZx200ChangePose, "/zx200/tms_rp_zx200_change_pose"),
            "excavate": ActionClient(node, TmsRpZx200ExcavateSimple, "/zx200/tms_rp_zx200_excavate_simple"),
            "release": ActionClient(node, TmsRpZx200ReleaseSimple, "/zx200/tms_rp_zx200_release_simple"),
        }
        self.types = {"change_pose": TmsRpZx200ChangePose, "excavate": TmsRpZx200ExcavateSimple,
                      "release": TmsRpZx200ReleaseSimple}
        self._lock = threading.Lock()

    def _on_js(self, msg: Any) -> None:
        self.q = list(msg.position[:4])
        self.dq_log.append((time.monotonic(), list(msg.position[:4]), list(msg.velocity[:4])))

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.node.executor_for_test.spin_once(timeout_sec=0.01)

    def spin_until(self, pred: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred():
                return True
            self.node.executor_for_test.spin_once(timeout_sec=0.02)
        return pred()

    def send(self, kind: str, goal: Any, timeout: float = 10.0, **options: Any) -> Any:
        """Send ``goal``; returns the goal handle (accepted or not). ``options`` (pass_through,
        theta_w_tolerance) go first to the change_pose options service under the goal's id."""
        import uuid

        from unique_identifier_msgs.msg import UUID

        from tms_msg.srv import Zx200ChangePoseOptions

        client = self.clients[kind]
        assert client.wait_for_server(timeout_sec=timeout), f"{kind} action server not available"
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        if options:
            assert self.spin_until(self.options.service_is_ready, timeout), "change_pose options service not available"
            reply = self.options.call_async(Zx200ChangePoseOptions.Request(goal_id=goal_id, **options))
            assert self.spin_until(reply.done, timeout) and reply.result().accepted, f"options {options} refused"

        def on_fb(fb: Any) -> None:
            self.feedback.append(fb.feedback.state)

        fut = client.send_goal_async(goal, feedback_callback=on_fb, goal_uuid=goal_id)
        assert self.spin_until(fut.done, timeout), f"{kind}: no goal response"
        return fut.result()

    def result(self, handle: Any, timeout: float) -> tuple[int, PlanningResult]:
        """(GoalStatus, result with the planner's message) of an accepted goal, spinning until it ends."""
        fut = handle.get_result_async()
        assert self.spin_until(fut.done, timeout), (
            f"goal did not end within {timeout} s (feedback {self.feedback[-3:]})"
        )
        res = fut.result()
        key = bytes(handle.goal_id.uuid)
        assert self.spin_until(lambda: key in self.outcomes, 5.0), "no Zx200PlanningOutcome for the goal"
        outcome = self.outcomes.pop(key)
        assert outcome.error_code == res.result.error_code.val, (outcome, res.result)
        return res.status, PlanningResult(res.result.error_code, outcome.message)

    def run(self, kind: str, goal: Any, timeout: float = 90.0, **options: Any) -> tuple[int, PlanningResult]:
        handle = self.send(kind, goal, **options)
        assert handle.accepted, f"{kind} goal not accepted"
        return self.result(handle, timeout)


@pytest.fixture
def arm_stack(procs, domain: int, ros_node, tmp_path: Path) -> Iterator[Callable[..., ArmStack]]:
    """``arm_stack(ic120_pose="ic120_start")`` -> :class:`ArmStack` once every node is ready."""

    def start(*, ic120_pose: str = "ic120_start", speed: float = SIM_SPEED, plant: str = "plant.yaml",
              clock_period_s: float = 0.0, rate_hz: float = 0.0, joint_states_period_s: float = 0.0,
              planner_args: tuple[str, ...] = ()) -> ArmStack:
        """Start the stack; the keyword arguments after ``speed`` reproduce the paper launch's choices
        (config/launch/paper_experiment.yaml: paper_plant.yaml, /clock every 20 ms, 50 Hz controller).
        ``planner_args``: more ``--ros-args`` of the planner (``-p name:=value`` ...)."""
        from tms_common.config import config_path

        text = config_path("sim", plant).read_text().replace("ic120: ic120_start", f"ic120: {ic120_pose}")
        cfg_file = tmp_path / "plant.yaml"
        cfg_file.write_text(text)
        bus = _zx_bus(domain)
        sim_args = [str(executable("sim_bridge", "sim_plant")), "--ros-args", "-p", f"speed:={speed}",
                    "-p", f"config:={cfg_file}", "-p", f"zx200_can_interface:={bus['interface']}",
                    "-p", f"zx200_can_channel:={bus['channel']}", "-p", f"clock_period_s:={clock_period_s}"]
        bridge_args = [str(executable("com3_can", "com3_bridge")), "--ros-args", "-r", "__ns:=/zx200",
                       "-p", "machine:=zx200", "-p", f"can_interface:={bus['interface']}",
                       "-p", f"can_channel:={bus['channel']}", "-p", "use_sim_time:=true",
                       "-p", f"joint_states_period_s:={joint_states_period_s}"]
        if "port" in bus:
            sim_args += ["-p", f"zx200_can_port:={bus['port']}"]
            bridge_args += ["-p", f"can_port:={bus['port']}"]
        sim = procs(sim_args, name="sim_plant")
        assert sim.wait_for("sim_plant: running", 90), sim.output
        bridge = procs(bridge_args, name="com3_bridge")
        assert bridge.wait_for("com3_bridge ready", 60), bridge.output
        ctl = procs([str(executable("tms_rc", "excavator_arm_controller")), "--ros-args", "-r", "__ns:=/zx200",
                     "-p", "use_sim_time:=true", "-p", f"rate_hz:={rate_hz}"], name="excavator_arm_controller")
        planner = procs([str(executable("tms_if_opera", "zx200_planner")), "--ros-args", "-r", "__ns:=/zx200",
                         "-p", "use_sim_time:=true", *planner_args], name="zx200_planner")
        assert ctl.wait_for("excavator_arm_controller ready", 60), ctl.output
        assert planner.wait_for("zx200_planner ready", 60), planner.output
        stack = ArmStack(ros_node)
        stack.procs = {"sim": sim, "bridge": bridge, "controller": ctl, "planner": planner}
        stack.plant_config = cfg_file
        assert stack.spin_until(lambda: stack.q is not None and stack.tip is not None and stack.soil is not None, 30), \
            "no joint_states / truth from the plant"
        return stack

    yield start
