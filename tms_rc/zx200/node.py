"""``zx200_arm_controller``: the 100 Hz hierarchical arm controller as a ROS 2 node.

In the machine namespace (``/zx200``): subscribes ``joint_states`` (sensor_msgs/JointState, the four
front joints), publishes ``front_cmd`` (tms_msg/JointCmd, VELOCITY) every period (contract [A] of the
COM3 converter), and serves the internal action ``arm_controller/move`` (tms_msg/action/Zx200ChangePose)
that the planner (``zx200_planner``) uses: joint targets in ``trajectory`` (one point per target),
Cartesian targets in ``position_with_angle_sequence`` (on this internal action ``offset`` in (0, 1] is the
segment's speed scale, e.g. the planner's slow dig phases; 0 = full speed); feedback ``state`` names the segment. Cancel
decelerates within the limits and the goal ends CANCELED only when the arm is at rest.

Parameters: ``config`` (controller YAML, default config/tms_rc/zx200_arm_controller.yaml),
``machine_config`` (default config/machines/zx200.yaml).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from tms_common.node import run_node

__all__ = ["main"]


JOINT_STATES_WAIT_S = 15.0  # [s] a goal waits this long for the first joint_states


def _make_node():  # noqa: ANN202
    from rclpy.action import ActionServer, CancelResponse, GoalResponse
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from tms_msg.action import Zx200ChangePose
    from tms_msg.msg import JointCmd
    from tms_rc.zx200.controller import ArmController, CartesianTarget, JointTarget, load_controller_config
    from tms_rp.zx200 import errors as codes
    from tms_rp.zx200.kinematics import JOINTS, load_kinematics

    class ArmControllerNode(Node):
        """joint_states -> hierarchical QP -> front_cmd at ``rate_hz``; goals through ``arm_controller/move``."""

        def __init__(self) -> None:
            super().__init__("zx200_arm_controller")
            cfg_path = self.declare_parameter("config", "").value or None
            machine_path = self.declare_parameter("machine_config", "").value or None
            self.kin = load_kinematics(machine_path)
            self.cfg = load_controller_config(cfg_path)
            rate = float(self.declare_parameter("rate_hz", 0.0).value)  # 0 = rate_hz of the config file
            if rate < 0:
                raise ValueError(f"zx200_arm_controller: rate_hz must be >= 0, got {rate}")
            if rate > 0:  # e.g. 50 Hz in the two-machine launch, whose /clock comes every 20 ms
                import dataclasses

                self.cfg = dataclasses.replace(self.cfg, rate_hz=rate)
            self.ctl = ArmController(self.kin, self.cfg)
            self._lock = threading.Lock()
            self._q: np.ndarray | None = None
            self._dq = np.zeros(len(JOINTS))
            self._goal_active = False
            self._pub = self.create_publisher(JointCmd, "front_cmd", 10)
            self.create_subscription(JointState, "joint_states", self._on_state, 20)
            self.create_timer(self.cfg.dt, self._tick, callback_group=MutuallyExclusiveCallbackGroup())
            self._server = ActionServer(
                self, Zx200ChangePose, "arm_controller/move", execute_callback=self._execute,
                goal_callback=self._on_goal, cancel_callback=lambda _h: CancelResponse.ACCEPT,
                callback_group=ReentrantCallbackGroup(),
            )
            self.get_logger().info(f"zx200_arm_controller ready at {self.cfg.rate_hz} Hz")

        def _on_state(self, msg: JointState) -> None:
            idx = {n: i for i, n in enumerate(msg.name)}
            if not all(n in idx for n in JOINTS):
                return
            q = np.array([msg.position[idx[n]] for n in JOINTS])
            dq = np.array([msg.velocity[idx[n]] if len(msg.velocity) > idx[n] else 0.0 for n in JOINTS])
            with self._lock:
                self._q, self._dq = q, dq

        def _tick(self) -> None:
            with self._lock:
                q, dq = self._q, self._dq
                if q is None:
                    return
                # The ROS clock (simulated time in the launches): the controller advances its Smith
                # predictor, integrators and reference by the time that really passed, so late or
                # skipped ticks under CPU load do not corrupt the prediction (issue 9: swing stuck off).
                u = self.ctl.step(q, dq, now=self.get_clock().now().nanoseconds * 1e-9)
            msg = JointCmd()
            msg.joint_name = list(JOINTS)
            msg.control_type = JointCmd.VELOCITY
            msg.velocity = [float(v) for v in u]
            self._pub.publish(msg)

        def _on_goal(self, goal) -> GoalResponse:  # noqa: ANN001
            # Right after start-up the first joint_states may still be on its way (the plant, the CAN
            # converter and this node start together): wait a bounded time before refusing.
            deadline = time.monotonic() + JOINT_STATES_WAIT_S
            while self._q is None and time.monotonic() < deadline:
                time.sleep(0.05)
            if self._q is None:
                self.get_logger().warning(f"goal rejected: no joint_states received within {JOINT_STATES_WAIT_S:g} s")
                return GoalResponse.REJECT
            return GoalResponse.ACCEPT

        def _targets(self, goal) -> list:  # noqa: ANN001
            names = list(goal.trajectory.joint_names)
            # trajectory.header.frame_id = "<label>" or "<label>|via" (internal action): a via segment
            # (the planner's approach, carry, ...: every segment of a plan but the last, sent one goal
            # each) is reached within via_tolerance_* without waiting for rest.
            label, _, flags = goal.trajectory.header.frame_id.partition("|")
            via = "via" in flags.split(",")
            out = []
            for k, pt in enumerate(goal.trajectory.points):
                q = self._q.copy()
                for n, v in zip(names, pt.positions, strict=False):
                    if n in JOINTS:
                        q[JOINTS.index(n)] = v
                out.append(JointTarget(q, label or f"joint {k + 1}", via=via))
            for k, pwa in enumerate(goal.position_with_angle_sequence):
                p = np.array([pwa.position.x, pwa.position.y, pwa.position.z])
                scale = pwa.offset if 0.0 < pwa.offset <= 1.0 else 1.0
                out.append(CartesianTarget(p, pwa.theta_w, label or f"position {k + 1}", speed_scale=scale, via=via))
            return out

        def _execute(self, handle):  # noqa: ANN001, ANN202
            result = Zx200ChangePose.Result()
            with self._lock:
                targets = self._targets(handle.request)
                if not targets:
                    handle.abort()
                    result.error_code.val = codes.INVALID_GOAL
                    result.message = "empty goal"
                    return result
                self.ctl.start(targets)
            canceling = False
            while True:
                time.sleep(0.05)
                with self._lock:
                    st = self.ctl.status
                    if handle.is_cancel_requested and not canceling:
                        self.ctl.stop("canceled")
                        canceling = True
                        st = self.ctl.status
                    if st.result is not None:
                        break
                fb = Zx200ChangePose.Feedback()
                fb.state = "stopping" if st.mode == "stopping" else f"{st.label or 'moving'} ({st.segment}/{st.segments})"
                fb.distance_remaining = float(st.distance_remaining)
                handle.publish_feedback(fb)
            result.error_code.val = int(st.result)
            result.message = st.message
            if st.result == codes.SUCCESS:
                handle.succeed()
            elif st.result == codes.CANCELED and handle.is_cancel_requested:
                handle.canceled()
            else:
                handle.abort()
            return result

    return ArmControllerNode()


def main() -> int:
    """Console script ``zx200_arm_controller``."""
    return run_node(_make_node, executor="multi")
