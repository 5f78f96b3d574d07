"""``excavator_arm_controller``: the 100 Hz hierarchical arm controller of any excavator kind as a ROS 2 node.

In the machine namespace (``/zx200``, ``/zx120``): subscribes ``joint_states`` (sensor_msgs/JointState, the four
front joints), publishes ``front_cmd`` (com3_msgs/JointCmd, VELOCITY: OPERA com3_ros's type and topic) every period
to the COM3 converter, and serves the internal action ``arm_controller/move`` (tms_msg/action/Zx200ArmMove)
that the planner (``zx200_planner``) uses: the segments of one planned action (tms_msg/msg/Zx200ArmSegment:
joint or Cartesian, label, speed scale, via), run as one motion; feedback names the running segment. A
malformed segment rejects the whole goal before motion, naming the segment (:mod:`tms_rc.excavator.segments`). Cancel
decelerates within the
limits and the goal ends CANCELED only when the arm is at rest. One goal drives the arm at a time: a new goal
preempts the running one, which ends ABORTED with FAILURE "preempted by a newer goal" (a result, never rclpy's
empty one); a goal to the pose the arm already holds ends SUCCESS once it is confirmed there.

One thread: the goal's execute callback is a coroutine that the control tick wakes (feedback at most
every ``FEEDBACK_PERIOD_S``), so the node spins on a SingleThreadedExecutor. On the MultiThreadedExecutor
it had, the control step was 3.7 % of the node's py-spy samples and rclpy's dispatch most of the rest; the
node took about a third more CPU in the paper demo than on one thread.

Parameters: ``config`` (the control choices, default config/tms_rc/excavator_arm_controller.yaml), ``machine`` (the
excavator on the site it drives, e.g. zx120; default the namespace's last segment), ``machine_config`` (default
the machine kind's config/machines/<kind>.yaml: joint limits, pump flow, flow per joint, hydraulic delays),
``rate_hz`` (0 = the config file's).
"""

from __future__ import annotations

import dataclasses
import time
import traceback
from dataclasses import dataclass
from typing import Any

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState

from com3_msgs.msg import JointCmd
from tms_common.errors import ConfigError
from tms_common.node import ACTION_RESULT_TIMEOUT_S, run_node
from tms_common.params import declare_startup
from tms_model.com3 import VELOCITY
from tms_model.excavator import codes
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.fleet import load_named, machine_name
from tms_model.machines import EXCAVATOR
from tms_msg.action import Zx200ArmMove
from tms_rc.excavator.controller import ArmController, load_controller_config
from tms_rc.excavator.segments import targets_from_segments
from tms_rc.excavator.tick_stats import SegmentSpans, TickStats

__all__ = ["ArmControllerNode", "main"]


JOINT_STATES_WAIT_S = 15.0  # [s] a goal waits this long for the first joint_states (wall clock)
FEEDBACK_PERIOD_S = 0.05  # [s wall] feedback at most this often (the result is checked on every tick)


@dataclass(eq=False)
class _Run:
    """One goal's run of the controller: its tick timing and, once the controller ends it, (code, message)."""

    stats: TickStats
    result: tuple[int, str] | None = None


class ArmControllerNode(Node):
    """joint_states -> hierarchical QP -> front_cmd at ``rate_hz``; goals through ``arm_controller/move``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("excavator_arm_controller", **kwargs)
        cfg_path = declare_startup(self, "config", "").value or None
        machine_path = declare_startup(self, "machine_config", "").value or None
        # any excavator of the site: the machine parameter, else the namespace; its kind's description gives the
        # geometry, limits, pump flow and hydraulic delays, the config file the control choices
        self.machine = machine_name(str(declare_startup(self, "machine", "").value), self.get_namespace())
        description = load_named(self.machine, machine_path).require(EXCAVATOR)
        self.kin = ExcavatorKinematics(description)
        self.cfg = load_controller_config(description, cfg_path)
        rate = float(declare_startup(self, "rate_hz", 0.0).value)  # 0 = rate_hz of the config file
        if rate < 0:
            raise ConfigError(f"excavator_arm_controller: parameter rate_hz must be >= 0, got {rate}")
        if rate > 0:  # e.g. 50 Hz in the two-machine launch, whose /clock comes every 20 ms
            self.cfg = dataclasses.replace(self.cfg, rate_hz=rate)
        self.ctl = ArmController(self.kin, self.cfg)
        self._q: np.ndarray | None = None
        self._dq: np.ndarray | None = None
        self._q_stamp: float | None = None  # header stamp of the last joint_states [s]
        self._run: _Run | None = None  # the goal that drives the arm now
        self._pub = self.create_publisher(JointCmd, "front_cmd", 10)
        self.create_subscription(JointState, "joint_states", self._on_state, 20)
        # futures completed by the next control tick / the first joint_states (coroutines await them)
        self._tick_waiters: list[Future] = []
        self._state_waiters: list[Future] = []
        self.create_timer(self.cfg.dt, self._tick, callback_group=MutuallyExclusiveCallbackGroup())
        # Reentrant: a goal callback awaiting the first joint_states holds the server's group, and in the
        # node's default group it would block the joint_states subscription it waits for.
        self._server = ActionServer(
            self, Zx200ArmMove, "arm_controller/move", execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=lambda _h: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(), result_timeout=ACTION_RESULT_TIMEOUT_S,
        )
        self.get_logger().info(f"excavator_arm_controller ready at {self.cfg.rate_hz} Hz")

    def _on_state(self, msg: JointState) -> None:
        idx = {n: i for i, n in enumerate(msg.name)}
        if not all(n in idx for n in JOINTS):
            return
        q = np.array([msg.position[idx[n]] for n in JOINTS])
        # no velocities (a driver that reports positions only): the controller predicts without them
        dq = np.array([msg.velocity[idx[n]] for n in JOINTS]) if len(msg.velocity) == len(msg.name) else None
        self._q, self._dq = q, dq
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        self._q_stamp = stamp if stamp > 0 else None
        self._wake(self._state_waiters)

    @staticmethod
    def _wake(waiters: list) -> None:
        pending = list(waiters)
        waiters.clear()
        for future in pending:
            if not future.done():
                future.set_result(True)

    def _next_tick(self) -> Future:
        future = Future()
        self._tick_waiters.append(future)
        return future

    def _tick(self) -> None:
        q, dq = self._q, self._dq
        if q is None:
            return
        # The ROS clock (simulated time in the launches): the controller advances its Smith
        # predictor, integrators and reference by the time that really passed, so late or
        # skipped ticks under CPU load do not corrupt the prediction (issue 9: swing stuck off).
        now = self.get_clock().now().nanoseconds * 1e-9
        run = self._run
        if run is not None:
            run.stats.tick(now, self._q_stamp)
        u = self.ctl.step(q, dq, now=now)
        if run is not None:
            self._note_end(run)  # recorded here, so the run's result survives a goal that starts before it wakes
        msg = JointCmd()
        msg.joint_name = list(JOINTS)
        msg.control_type = VELOCITY
        msg.velocity = [float(v) for v in u]
        self._pub.publish(msg)
        self._wake(self._tick_waiters)

    async def _on_goal(self, goal) -> GoalResponse:
        # Right after start-up the first joint_states may still be on its way (the plant, the CAN
        # converter and this node start together): wait a bounded time (wall clock) before refusing.
        if self._q is None:
            waiter = Future()
            self._state_waiters.append(waiter)
            timer = self.create_timer(JOINT_STATES_WAIT_S, lambda: waiter.done() or waiter.set_result(False),
                                      clock=Clock(clock_type=ClockType.STEADY_TIME))
            await waiter
            timer.cancel()
            self.destroy_timer(timer)
        if self._q is None:
            self.get_logger().warning(f"goal rejected: no joint_states received within {JOINT_STATES_WAIT_S:g} s")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def _execute(self, handle):
        result = Zx200ArmMove.Result()
        try:
            targets = targets_from_segments(handle.request.segments)
        except ValueError as exc:
            self.get_logger().warning(f"goal rejected before motion: {exc}")
            handle.abort()
            result.error_code.val = codes.INVALID_GOAL
            result.message = str(exc)
            return result
        # One arm, one run: a new goal preempts the running one (whose coroutine then ends it FAILURE),
        # as a trajectory controller does; the tree's halt-and-resend pattern relies on the newer goal winning.
        run = _Run(TickStats(self.cfg.dt))
        preempts = self._run is not None
        self._run = run
        self.ctl.start(targets)
        spans = SegmentSpans()
        try:
            code, message = await self._follow(handle, run, spans)
        except Exception as exc:  # noqa: BLE001 - every goal ends with a result, never rclpy's empty one
            self.get_logger().error(f"goal failed inside the controller: {traceback.format_exc()}")
            if self._run is run:
                self.ctl.stop(f"controller error: {exc!r}")  # the arm comes to rest; no goal drives it any more
            code, message = codes.FAILURE, f"arm controller error: {exc!r}"
        finally:
            if self._run is run:
                self._run = None
        code, message = codes.reported(code == codes.SUCCESS, code, message, "ended")
        result.error_code.val = int(code)
        result.message = message
        self.get_logger().info(
            f"goal ended {code} ({message}) {spans.summary(self.get_clock().now().nanoseconds * 1e-9)}"
            + (" (it preempted a running goal)" if preempts else "")
            + f"; control loop: {run.stats.summary()}"
        )
        if code == codes.SUCCESS:
            handle.succeed()
        elif code == codes.CANCELED and handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result

    def _note_end(self, run: _Run) -> None:
        """The controller's result, if its run (``run``, still the current one) has just ended."""
        st = self.ctl.status
        if self._run is run and run.result is None and st.result is not None:
            run.result = (int(st.result), st.message)

    async def _follow(self, handle, run: _Run, spans: SegmentSpans) -> tuple[int, str]:
        """Wait on the control ticks until ``run`` ends (its result), is preempted, or is canceled and at rest."""
        canceling = False
        last_feedback = -1e9
        while True:
            await self._next_tick()
            # the result the tick recorded for this run comes first: a run that ended at the tick before a
            # newer goal started keeps its own result
            if run.result is not None:
                return run.result
            if self._run is not run:
                return codes.FAILURE, "preempted by a newer goal before it ended"
            st = self.ctl.status
            spans.enter("stopping" if st.mode == "stopping" else (st.label or f"segment {st.segment}"),
                        self.get_clock().now().nanoseconds * 1e-9)
            if handle.is_cancel_requested and not canceling:
                self.ctl.stop("canceled")
                canceling = True
                self._note_end(run)  # stopping an arm already at rest ends the run at once
                if run.result is not None:
                    return run.result
                st = self.ctl.status
            if time.monotonic() - last_feedback < FEEDBACK_PERIOD_S:
                continue
            last_feedback = time.monotonic()
            fb = Zx200ArmMove.Feedback()
            stopping = st.mode == "stopping"
            fb.segment = 0 if stopping else int(st.segment)
            fb.label = "" if stopping else st.label
            fb.state = "stopping" if stopping else f"{st.label or 'moving'} ({st.segment}/{st.segments})"
            fb.distance_remaining = float(st.distance_remaining)
            handle.publish_feedback(fb)


def main() -> int:
    """Console script ``excavator_arm_controller``."""
    return run_node(ArmControllerNode, executor="single")
