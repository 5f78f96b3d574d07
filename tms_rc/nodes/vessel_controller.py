"""``vessel_controller``: a crawler carrier's vessel (and vessel swing) servers (thin rclpy wrapper of
VesselController).

Run in the machine's namespace: ``vessel_controller --ros-args -r __ns:=/ic120_1`` (the machine is the
``machine`` parameter, else the namespace's last segment; ``ic120_vessel`` is this node under its former
name). What it serves follows the machine's description (``tms_model.fleet.load_named``):

* every carrier (a description with a ``vessel``): action ``set_dump_angle`` (com3_msgs/action/SetDumpAngle,
  OPERA's): goal ``target_angle`` [rad] (0 = lowered, + = raised, up to the description's
  ``vessel.max_angle``); feedback ``current_error`` [rad]; result ``success`` (the reason of a failure is
  logged: the peer's result has no text field); and service ``vessel_target_pos`` (com3_msgs/srv/DumpUp, what
  the original's MST release_soil subtasks call): request ``vessel_angle`` [rad, as ``target_angle``], the
  reply ``result`` once the vessel is there (true) or failed (false);
* a carrier whose vessel swings (its description has a joint about the z axis,
  :func:`tms_model.fleet.vessel_swing_joint`): action ``set_swing_angle`` (com3_msgs/action/SetSwingAngle):
  goal ``target_angle`` [rad] within the swing joint's limits (a continuous joint: any angle, the short way
  round).

Publishes ``rot_dump_cmd`` (com3_msgs/JointCmd, POSITION: ``dump_joint`` = vessel angle and, on a swinging
vessel, ``rotate_joint`` = swing angle, com3_ros's names) at ``rate_hz`` (10) while a goal runs and keeps
holding the last targets afterwards (com3_bridge's watchdog would otherwise neutralise the channel); once one
axis was commanded the other is held where it was. Reads ``joint_states`` (``vessel_joint``, the swing joint's
name). A new goal or request on an axis preempts the running one (which fails). Cancel holds the axis where it
is, waits for it to stop, then reports CANCELED (a DumpUp call cannot be canceled).

Parameters: ``machine``, ``machine_config`` (the kind's description file instead of config/machines/<kind>.yaml),
``nav_config`` (the ``vessel`` tuning: tolerance, settle_time, timeout_margin; default the kind's nav file,
config/nav/<kind>_nav.yaml over tracked_nav.yaml, :mod:`tms_model.nav_files`), ``rate_hz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from com3_msgs.action import SetDumpAngle, SetSwingAngle
from com3_msgs.msg import JointCmd
from com3_msgs.srv import DumpUp
from tms_common.errors import ConfigError
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_common.rclpy_compat import create_deferred_service
from tms_model.com3 import CARRIER_DUMP_JOINT, CARRIER_ROTATE_JOINT, POSITION
from tms_model.fleet import load_named, machine_name, vessel_swing_joint
from tms_model.nav_files import load_nav_files
from tms_rc.carrier.vessel import VesselController, VesselError, VesselParams, VesselTuning

__all__ = ["main", "VesselControllerNode", "VESSEL_JOINT"]

VESSEL_JOINT = "vessel_joint"  # the vessel's joint_states name (com3_can crawler-carrier profile)


@dataclass
class _Axis:
    """One positioned axis: its controller, the rot_dump_cmd joint, the joint_states name and its goal."""

    name: str  # action name, for messages
    ctl: VesselController
    cmd_joint: str
    state_joint: str
    angle: float | None = None
    vel: float = 0.0
    hold: float | None = None
    #: the running goal: (action goal handle or None for a service call, future, result factory)
    active: tuple[Any, Future, Any] | None = None


class VesselControllerNode(Node):
    def __init__(self, node_name: str = "vessel_controller", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.machine = machine_name(str(declare_startup(self, "machine", "").value), self.get_namespace())
        machine_yaml = str(declare_startup(self, "machine_config", "").value)
        nav_yaml = str(declare_startup(self, "nav_config", "").value)
        rate = float(declare_startup(self, "rate_hz", 10.0).value)
        # a name resolves to its kind through the site only (machine_config replaces that kind's file)
        desc = load_named(self.machine, machine_yaml or None)
        if desc.vessel is None:
            raise ConfigError(f"{desc.source}: {self.machine} ({desc.kind}, a {desc.type}) has no vessel: "
                              "vessel_controller serves crawler carriers")
        tuning = load_nav_files(desc.kind, nav_yaml or None).section(VesselTuning, "vessel")
        self.axes: dict[str, _Axis] = {"vessel": _Axis(
            "set_dump_angle",
            VesselController(VesselParams.from_config(desc.vessel, tuning, f"{desc.source} vessel.max_angle")),
            CARRIER_DUMP_JOINT, VESSEL_JOINT)}
        swing = vessel_swing_joint(desc)
        if swing is not None:
            self.axes["swing"] = _Axis(
                "set_swing_angle",
                VesselController(VesselParams.for_swing(swing, tuning, f"{desc.source} joints.{swing.name}")),
                CARRIER_ROTATE_JOINT,
                swing.name,
            )
        self.pub = self.create_publisher(JointCmd, "rot_dump_cmd", 10)
        self.create_subscription(JointState, "joint_states", self._on_joints, 20)
        self._servers = [self._action(SetDumpAngle, "set_dump_angle", "vessel")]
        # replies when the vessel is there (tms_common.rclpy_compat: the EventsExecutor awaits no async service)
        self._dump_up = create_deferred_service(self, DumpUp, "vessel_target_pos", self._on_dump_up)
        if swing is not None:
            self._servers.append(self._action(SetSwingAngle, "set_swing_angle", "swing"))
        self.create_timer(1.0 / rate, self._tick)
        served = ["set_dump_angle", "vessel_target_pos"] + (["set_swing_angle"] if swing is not None else [])
        self.get_logger().info(f"{self.machine} ({desc.kind}): {', '.join(served)} ready "
                               f"(vessel max {self.axes['vessel'].ctl.params.max_angle:.3f} rad"
                               + (f", swing joint {swing.name}" if swing is not None else "") + ")")

    def _action(self, action_type: Any, name: str, axis: str) -> ActionServer:
        async def execute(handle):  # rclpy awaits a coroutine function
            return await self._execute(handle, action_type, axis)

        return ActionServer(self, action_type, name, execute_callback=execute,
                            goal_callback=lambda _g: GoalResponse.ACCEPT,
                            cancel_callback=lambda _h: CancelResponse.ACCEPT,
                            result_timeout=ACTION_RESULT_TIMEOUT_S)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_joints(self, msg: JointState) -> None:
        names = list(msg.name)
        for ax in self.axes.values():
            if ax.state_joint in names:
                i = names.index(ax.state_joint)
                ax.angle = float(msg.position[i])
                ax.vel = float(msg.velocity[i]) if len(msg.velocity) > i else 0.0

    def _publish_holds(self) -> None:
        held = [ax for ax in self.axes.values() if ax.hold is not None]
        if held:
            self.pub.publish(JointCmd(joint_name=[ax.cmd_joint for ax in held], control_type=POSITION,
                                      position=[float(ax.hold) for ax in held]))

    def _preempt(self, ax: _Axis) -> None:
        if ax.active is None:
            return
        old, fut, result = ax.active
        if old is not None and old.is_active:
            old.abort()
        self.get_logger().warning(f"{ax.name}: FAILED: preempted by a new goal")
        if not fut.done():
            fut.set_result(result(False))
        ax.active = None

    def _start(self, ax: _Axis, handle: Any, target: float, result: Any) -> tuple[Future | None, str]:
        """Start a target on ``ax``; (future of its result, "") or (None, why it cannot run)."""
        self._preempt(ax)
        if ax.angle is None:
            return None, f"no {ax.state_joint} on joint_states yet: is com3_bridge running?"
        try:
            ax.ctl.start(float(target), ax.angle, self._now())
        except VesselError as exc:
            return None, str(exc)
        for other in self.axes.values():  # hold every other axis where it is from now on
            if other is not ax and other.hold is None and other.angle is not None:
                other.hold = other.angle
        fut = Future()
        ax.active = (handle, fut, result)
        return fut, ""

    async def _execute(self, handle, action_type: Any, axis: str):
        ax = self.axes[axis]
        fut, why = self._start(ax, handle, handle.request.target_angle, lambda ok: action_type.Result(success=ok))
        if fut is None:
            handle.abort()
            self.get_logger().warning(f"{ax.name}: FAILED: {why}")
            return action_type.Result(success=False)
        return await fut

    def _on_dump_up(self, request: DumpUp.Request, reply) -> None:  # reply(response), once
        ax = self.axes["vessel"]
        fut, why = self._start(ax, None, request.vessel_angle, lambda ok: ok)
        if fut is None:
            self.get_logger().warning(f"vessel_target_pos: FAILED: {why}")
            reply(DumpUp.Response(result=False))
            return
        fut.add_done_callback(lambda f: reply(DumpUp.Response(result=bool(f.result()))))

    def _tick(self) -> None:
        for ax in self.axes.values():
            if ax.active is None or ax.angle is None:
                continue
            handle, fut, result = ax.active
            if handle is not None and handle.is_cancel_requested and not ax.ctl._canceling:
                ax.ctl.cancel(ax.angle)
            step = ax.ctl.step(ax.angle, ax.vel, self._now())
            ax.hold = step.command
            if handle is not None:
                feedback = (SetSwingAngle if ax.name == "set_swing_angle" else SetDumpAngle).Feedback()
                feedback.current_error = float(step.error)
                handle.publish_feedback(feedback)
            if step.status in ("SUCCEEDED", "FAILED", "CANCELED"):
                if handle is not None:
                    {"SUCCEEDED": handle.succeed, "FAILED": handle.abort, "CANCELED": handle.canceled}[step.status]()
                ax.active = None
                where = ax.name if handle is not None else "vessel_target_pos"
                self.get_logger().info(f"{where}: {step.status}: {step.message}")
                fut.set_result(result(step.status == "SUCCEEDED"))
        self._publish_holds()


def main() -> int:
    return run_node(VesselControllerNode)
