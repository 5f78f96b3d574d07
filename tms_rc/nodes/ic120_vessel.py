"""``ic120_vessel``: the ``set_dump_angle`` action server (thin rclpy wrapper of VesselController).

Run in the machine namespace: ``ic120_vessel --ros-args -r __ns:=/ic120``. Action ``set_dump_angle``
(com3_msgs/action/SetDumpAngle, OPERA's): goal ``target_angle`` [rad] (0 = lowered, + = raised, up to
config/machines/ic120.yaml ``vessel.max_angle``); feedback ``current_error`` [rad]; result ``success`` (the
reason of a failure is logged: the peer's result has no text field). Publishes ``rot_dump_cmd``
(com3_msgs/JointCmd, ``dump_joint`` POSITION = target angle) at ``rate_hz`` (10) while a goal runs and keeps
holding the last target afterwards (com3_bridge's watchdog would otherwise neutralise the vessel channel);
reads ``joint_states`` (``vessel_joint``). Cancel holds the vessel where it is, waits for it to stop, then
reports CANCELED.
"""

from __future__ import annotations

from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from com3_msgs.action import SetDumpAngle
from com3_msgs.msg import JointCmd
from tms_common.config import config_path, load_yaml
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_model.com3 import CARRIER_DUMP_JOINT, POSITION
from tms_model.machines import CRAWLER_DUMP, load_machine
from tms_rc.ic120.vessel import VesselController, VesselError, VesselParams

__all__ = ["main", "Ic120Vessel"]


class Ic120Vessel(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__("ic120_vessel", **kwargs)
        machine_yaml = str(declare_startup(self, "machine_config", "").value)
        nav_yaml = str(declare_startup(self, "nav_config", "").value)
        rate = float(declare_startup(self, "rate_hz", 10.0).value)
        machine = load_machine("ic120", machine_yaml or None).require(CRAWLER_DUMP)
        ndata, _ = load_yaml(nav_yaml or config_path("nav", "ic120_nav.yaml"))
        self.ctl = VesselController(VesselParams.from_config(machine.vessel, ndata["vessel"]))
        self._angle: float | None = None
        self._vel = 0.0
        self._hold: float | None = None
        self._active: tuple[Any, Future] | None = None
        self.pub = self.create_publisher(JointCmd, "rot_dump_cmd", 10)
        self.create_subscription(JointState, "joint_states", self._on_joints, 20)
        self._server = ActionServer(self, SetDumpAngle, "set_dump_angle", execute_callback=self._execute,
                                    goal_callback=lambda _g: GoalResponse.ACCEPT,
                                    cancel_callback=lambda _h: CancelResponse.ACCEPT,
                                    result_timeout=ACTION_RESULT_TIMEOUT_S)
        self.create_timer(1.0 / rate, self._tick)
        self.get_logger().info(f"set_dump_angle ready (max {self.ctl.params.max_angle:.3f} rad)")

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_joints(self, msg: JointState) -> None:
        if "vessel_joint" in msg.name:
            i = list(msg.name).index("vessel_joint")
            self._angle = float(msg.position[i])
            self._vel = float(msg.velocity[i]) if len(msg.velocity) > i else 0.0

    def _command(self, angle: float) -> None:
        self.pub.publish(JointCmd(joint_name=[CARRIER_DUMP_JOINT], control_type=POSITION, position=[angle]))

    def _fail(self, handle, why: str) -> SetDumpAngle.Result:  # noqa: ANN001
        handle.abort()
        self.get_logger().warning(f"set_dump_angle: FAILED: {why}")
        return SetDumpAngle.Result(success=False)

    async def _execute(self, handle):  # noqa: ANN001, ANN202
        if self._active is not None:
            old, fut = self._active
            if old.is_active:
                old.abort()
            self.get_logger().warning("set_dump_angle: FAILED: preempted by a new goal")
            fut.set_result(SetDumpAngle.Result(success=False))
            self._active = None
        if self._angle is None:
            return self._fail(handle, "no vessel_joint on joint_states yet: is com3_bridge running?")
        try:
            self.ctl.start(float(handle.request.target_angle), self._angle, self._now())
        except VesselError as exc:
            return self._fail(handle, str(exc))
        fut = Future()
        self._active = (handle, fut)
        return await fut

    def _tick(self) -> None:
        if self._active is None:
            if self._hold is not None:
                self._command(self._hold)
            return
        handle, fut = self._active
        if self._angle is None:
            return
        if handle.is_cancel_requested and not self.ctl._canceling:
            self.ctl.cancel(self._angle)
        step = self.ctl.step(self._angle, self._vel, self._now())
        self._hold = step.command
        self._command(step.command)
        fb = SetDumpAngle.Feedback()
        fb.current_error = float(step.error)
        handle.publish_feedback(fb)
        if step.status in ("SUCCEEDED", "FAILED", "CANCELED"):
            res = SetDumpAngle.Result(success=step.status == "SUCCEEDED")
            {"SUCCEEDED": handle.succeed, "FAILED": handle.abort, "CANCELED": handle.canceled}[step.status]()
            self._active = None
            self.get_logger().info(f"set_dump_angle: {step.status}: {step.message}")
            fut.set_result(res)


def main() -> int:
    return run_node(Ic120Vessel)
