"""Small real planning action servers for tms_ts integration tests (stand-in for tms_rp, contract D).

``python -m tests.tms_ts.planning_stub --ros-args -p model_names:=zx200,ic120 -p duration_s:=0.5``
serves every ZX200 and IC120 planning action under each ``/<model_name>/``. Each goal runs ``duration_s`` then
succeeds; a cancel stops it at once and ends CANCELED (the "machine at rest" confirmation), unless
``ignore_cancel`` is true. Prints ``GOAL <action>``, ``DONE <action>``, ``CANCELED <action>`` lines.
"""

from __future__ import annotations

import sys
import threading
import time

from rclpy.action import ActionServer, CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from com3_msgs.action import SetDumpAngle
from nav2_msgs.action import FollowWaypoints, NavigateThroughPoses, NavigateToPose
from tms_if_opera.interface import CHANGE_POSE, CHANGE_POSE_OPTIONS, EXCAVATE_SIMPLE, RELEASE_SIMPLE
from tms_msg.msg import Zx200PlanningOutcome
from tms_msg.srv import Zx200ChangePoseOptions
from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple
from tms_msg_rp.msg import TmsRpErrorCodes

ACTIONS = {
    CHANGE_POSE: TmsRpZx200ChangePose,
    EXCAVATE_SIMPLE: TmsRpZx200ExcavateSimple,
    RELEASE_SIMPLE: TmsRpZx200ReleaseSimple,
    "navigate_to_pose": NavigateToPose,
    "navigate_through_poses": NavigateThroughPoses,
    "follow_waypoints": FollowWaypoints,
    "set_dump_angle": SetDumpAngle,
}


_PRINT_LOCK = threading.Lock()


def _say(line: str) -> None:
    """One whole line per write: ``print`` from two executor threads can interleave two lines into one."""
    with _PRINT_LOCK:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def _result(action_type, ok: bool):
    res = action_type.Result()
    if hasattr(res, "error_code") and hasattr(res.error_code, "val"):
        res.error_code.val = TmsRpErrorCodes.SUCCESS if ok else Zx200PlanningOutcome.CANCELED
    elif hasattr(res, "error_code"):
        res.error_code = 0 if ok else 9006
    else:
        res.success = ok
    return res


class PlanningStub(Node):
    def __init__(self) -> None:
        super().__init__("planning_stub")
        models = [m.strip() for m in str(self.declare_parameter("model_names", "zx200,ic120").value).split(",")]
        self.duration = float(self.declare_parameter("duration_s", 0.5).value)
        self.ignore_cancel = bool(self.declare_parameter("ignore_cancel", False).value)
        group = ReentrantCallbackGroup()
        self.action_servers = [
            ActionServer(
                self,
                t,
                f"/{m}/{name}",
                execute_callback=lambda gh, n=f"/{m}/{name}", t=t: self._run(gh, n, t),
                cancel_callback=lambda _gh: CancelResponse.ACCEPT,
                callback_group=group,
            )
            for m in models
            for name, t in ACTIONS.items()
        ]
        # a change_pose's pass_through / theta_w_tolerance come by goal id before the goal: accepted, printed
        self.option_services = [
            self.create_service(
                Zx200ChangePoseOptions, f"/{m}/{CHANGE_POSE_OPTIONS}", self._on_options, callback_group=group
            )
            for m in models
        ]
        _say(f"planning stub ready {models}")

    def _on_options(self, request, response):
        _say(f"OPTIONS pass_through={request.pass_through} theta_w_tolerance={request.theta_w_tolerance:g}")
        response.accepted = True
        return response

    def _run(self, gh, name: str, action_type):
        _say(f"GOAL {name}")
        end = time.monotonic() + self.duration
        while time.monotonic() < end:
            if gh.is_cancel_requested and not self.ignore_cancel:
                time.sleep(0.05)  # "bring the machine to rest"
                gh.canceled()
                _say(f"CANCELED {name}")
                return _result(action_type, False)
            time.sleep(0.01)
        if gh.is_cancel_requested:
            gh.canceled()
            _say(f"CANCELED {name}")
            return _result(action_type, False)
        gh.succeed()
        _say(f"DONE {name}")
        return _result(action_type, True)


if __name__ == "__main__":
    from tms_common.node import run_node

    # one thread per goal: each goal's execute sleeps until it ends (a stand-in, not a model of a node)
    raise SystemExit(run_node(PlanningStub, executor="multi", threads=32))
