"""The ZX200 arm stack in the MuJoCo plant over COM3 CAN, every node its own process.

sim_plant (CAN only) <-> com3_bridge (zx200) <-> excavator_arm_controller <-> zx200_planner <- this test.
Accuracy is checked against the plant's ground truth (``/sim/truth/zx200/bucket_tip``, ZX200 base at
the map origin, see config/site.yaml ``points.zx200_base``) and soil against ``/sim/truth/soil``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tms_common.config import config_path, load_yaml
from tms_model.excavator import codes
from tms_model.excavator.kinematics import JOINTS, load_kinematics
from tms_model.site import load_site

pytestmark = pytest.mark.integration

SUCCEEDED, CANCELED, ABORTED = 4, 5, 6
TOL_M, TOL_RAD = 0.03, math.radians(2.0)
KIN = load_kinematics()


def joint_goal(q):
    from trajectory_msgs.msg import JointTrajectoryPoint

    from tms_msg_rp.action import TmsRpZx200ChangePose

    g = TmsRpZx200ChangePose.Goal()
    g.trajectory.joint_names = list(JOINTS)
    g.trajectory.points = [JointTrajectoryPoint(positions=[float(v) for v in q])]
    return g


def pwa_goal(p, theta_w):
    from tms_msg_rp.action import TmsRpZx200ChangePose
    from tms_msg_rp.msg import TmsRpZx200PositionWithAngle

    g = TmsRpZx200ChangePose.Goal()
    pwa = TmsRpZx200PositionWithAngle()
    pwa.position.x, pwa.position.y, pwa.position.z = (float(v) for v in p)
    pwa.theta_w = float(theta_w)
    g.position_with_angle_sequence = [pwa]
    return g


def pose_goal(q):
    from geometry_msgs.msg import Pose

    from tms_msg_rp.action import TmsRpZx200ChangePose

    m = KIN.tip_pose(np.asarray(q, dtype=float))
    x, y, z, w = (float(v) for v in __import__("pinocchio").Quaternion(m.rotation).coeffs())
    g = TmsRpZx200ChangePose.Goal()
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in m.translation)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = x, y, z, w
    g.pose_sequence = [pose]
    return g


def settled_tip(stack) -> np.ndarray:
    stack.spin(0.5)
    return np.array(stack.tip)


def test_change_pose_reaches_rejects_and_cancels_in_the_plant(arm_stack) -> None:
    stack = arm_stack()
    # 1. joint goal: tip (truth) and joints (measured over CAN) at the target
    q1 = np.array([0.3, -0.7, 1.6, 1.0])
    status, res = stack.run("change_pose", joint_goal(q1))
    assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, res.message
    q = np.array(stack.q)
    assert np.max(np.abs(q - q1)) < TOL_RAD, q
    tip = settled_tip(stack)
    assert np.linalg.norm(tip - KIN.tip_position(q1)) < TOL_M, (tip, KIN.tip_position(q1))

    # 2. position + theta_w goal
    p2, th2 = np.array([6.0, 1.5, 2.5]), 1.4
    status, res = stack.run("change_pose", pwa_goal(p2, th2))
    assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, res.message
    tip = settled_tip(stack)
    assert np.linalg.norm(tip - p2) < TOL_M, (tip, p2)
    assert abs(KIN.theta_w(np.array(stack.q)) - th2) < TOL_RAD

    # 3. pose goal (position + quaternion of a reachable tip pose)
    q3 = np.array([-0.2, -0.6, 1.9, 1.3])
    status, res = stack.run("change_pose", pose_goal(q3))
    assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, res.message
    tip = settled_tip(stack)
    assert np.linalg.norm(tip - KIN.tip_position(q3)) < TOL_M, (tip, KIN.tip_position(q3))
    assert abs(KIN.theta_w(np.array(stack.q)) - KIN.theta_w(q3)) < TOL_RAD

    # 4. rejections before motion, with the reason (the arm first settles from the last goal)
    stack.spin(2.0)
    before = np.array(stack.tip)
    t_rej = time.monotonic()
    status, res = stack.run("change_pose", pwa_goal([18.0, 0.0, 1.0], 1.5), timeout=20)
    assert status == ABORTED and res.error_code.val == codes.OUT_OF_REACH, res.message
    assert "m from the boom foot" in res.message, res.message
    status, res = stack.run("change_pose", joint_goal([0.0, 0.3, 1.6, 1.0]), timeout=20)
    assert status == ABORTED and res.error_code.val == codes.JOINT_LIMIT and "boom_joint" in res.message, res.message
    status, res = stack.run("change_pose", pwa_goal([6.0, float("nan"), 2.0], 1.4), timeout=20)
    assert status == ABORTED and res.error_code.val == codes.INVALID_GOAL and "NaN" in res.message, res.message
    from tms_msg_rp.action import TmsRpZx200ChangePose

    status, res = stack.run("change_pose", TmsRpZx200ChangePose.Goal(), timeout=20)
    assert status == ABORTED and res.error_code.val == codes.INVALID_GOAL and "empty" in res.message, res.message
    stack.spin(1.0)
    assert np.linalg.norm(np.array(stack.tip) - before) < 0.01, "a rejected goal moved the arm"
    moving = [max(abs(x) for x in v) for t, _, v in stack.dq_log if t >= t_rej]
    assert moving and max(moving) < 0.02, f"joint speed during the rejected goals: {max(moving)}"

    # 5. cancel mid-motion: CANCELED only once the arm is at rest
    handle = stack.send("change_pose", joint_goal([1.2, -0.5, 1.3, 0.5]))
    assert handle.accepted
    assert stack.spin_until(lambda: stack.q is not None and abs(stack.q[0] - q3[0]) > 0.15, 30), "did not start moving"
    cancel = handle.cancel_goal_async()
    assert stack.spin_until(cancel.done, 10)
    status, res = stack.result(handle, 60)
    t_end = time.monotonic()
    assert status == CANCELED and res.error_code.val == codes.CANCELED, (status, res.message)
    _, _, v = min((s for s in stack.dq_log if s[0] >= t_end - 0.3), key=lambda s: abs(s[0] - t_end))
    assert max(abs(x) for x in v) < 0.02, f"CANCELED while moving: {v}"
    q_c = np.array(stack.q)
    stack.spin(2.0)
    assert np.max(np.abs(np.array(stack.q) - q_c)) < 0.01, "arm kept moving after CANCELED"
    for name, p in stack.procs.items():
        assert p.popen.poll() is None, f"{name} died:\n{p.output[-2000:]}"


def test_scripted_excavate_removes_soil_and_release_fills_the_vessel(arm_stack) -> None:
    from tms_msg_rp.action import TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple

    site = load_site()
    base = site.point("zx200_base")
    assert (base.x, base.y, base.yaw) == (0.0, 0.0, 0.0), "test assumes the ZX200 base at the map origin"
    mound = site.mound
    stack = arm_stack(ic120_pose="P1")
    mound0, bucket0, vessel0 = stack.soil[:3]
    # Target on the near slope of the mound, 0.35 m below its surface, as tms_sp computes it.
    cx = mound.cx
    x = cx - 0.65
    r = abs(x - cx)
    surface = mound.ground_z + mound.height * (1.0 if r <= mound.top_radius else
                                               (mound.base_radius - r) / (mound.base_radius - mound.top_radius))
    g = TmsRpZx200ExcavateSimple.Goal()
    g.position_with_angle.position.x, g.position_with_angle.position.y = x, mound.cy
    g.position_with_angle.position.z = surface - 0.35
    g.position_with_angle.theta_w = math.radians(45.0)
    g.position_with_angle.offset = 1.5
    stack.feedback.clear()
    status, res = stack.run("excavate", g, timeout=180)
    assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, res.message
    assert {"approach", "penetrate", "drag", "curl and lift"} <= set(stack.feedback), stack.feedback
    stack.spin(1.0)
    mound1, bucket1, vessel1 = stack.soil[:3]
    assert bucket1 > 0.2, stack.soil
    assert mound1 < mound0 - 0.2, (mound0, mound1)

    # Over the vessel (IC120 at P1, left of the ZX200) as the paper tree carries it (the seed's
    # target_release_pose: tip over the vessel centre, bucket closed at 85 deg), then open the bucket.
    seed, _ = load_yaml(config_path("seeds", "paper.yaml"))
    rel = next(r for r in seed["parameters"] if r.get("record_name") == "target_release_pose")
    swing = math.atan2(rel["y"] - KIN.swing_origin[1], rel["x"] - KIN.swing_origin[0])
    # pass_through as the seed's record asks: the carry ends once the commands sent bring the arm there
    assert rel.get("pass_through") == 1, rel
    carry = pwa_goal([rel["x"], rel["y"], rel["z"]], rel["theta_w"])
    status, res = stack.run("change_pose", carry, timeout=120, pass_through=True)
    assert status == SUCCEEDED, res.message
    carry_end_speed = max(abs(v) for v in stack.dq_log[-1][2])
    stack.feedback.clear()
    status, res = stack.run("release", TmsRpZx200ReleaseSimple.Goal(target_angle=swing), timeout=120)
    assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, res.message
    # still moving when handed on: faster than the controller's rest speed (0.01 rad/s), which a goal waits for
    assert carry_end_speed > 0.01, f"the pass-through carry waited for rest (joint speed {carry_end_speed:.3f} rad/s)"
    # planned from where the carry goes, not from the lagging joint_states: over the vessel already, so
    # the release opens at once (release_swing_in_open), with no swing back
    assert stack.procs["planner"].wait_for(
        "TmsRpZx200ReleaseSimple: planned from the previous goal's pass-through end", 5
    ), stack.procs["planner"].output[-2000:]
    assert "open" in set(stack.feedback) and "swing" not in set(stack.feedback), stack.feedback
    stack.spin(3.0)
    vessel2 = stack.soil[2]
    assert vessel2 > vessel1 + 0.5 * bucket1, stack.soil


def test_paper_launch_poses_and_big_swings_always_end(arm_stack) -> None:
    """Regression (paper stack hang): the seed's poses and +-1.2 rad swings under the paper launch's
    choices (paper_plant.yaml, sim speed 3, /clock every 20 ms, 50 Hz controller, 20 ms joint_states).
    Every goal must END (within its bound), SUCCEEDED, with the truth tip within 3 cm of the goal."""
    stack = arm_stack(speed=3.0, plant="paper_plant.yaml", clock_period_s=0.02, rate_hz=50.0,
                      joint_states_period_s=0.02)
    release = [1.597394, -0.75, 1.6, 1.9]  # seed release_angle with the carry pose of the paper tree
    pending = [0.0, -0.8, 1.3, 1.2]
    for q in (release, pending, [-1.2, -0.8, 1.3, 1.2], [1.2, -0.8, 1.3, 1.2]):
        status, res = stack.run("change_pose", joint_goal(q), timeout=150)
        assert status == SUCCEEDED and res.error_code.val == codes.SUCCESS, (q, status, res.message)
        tip = settled_tip(stack)
        assert np.linalg.norm(tip - KIN.tip_position(np.array(q))) < TOL_M, (q, tip, KIN.tip_position(np.array(q)))


def test_a_planner_stopped_mid_goal_cancels_the_arm_and_aborts_naming_why(arm_stack) -> None:
    """SIGINT to zx200_planner while a change_pose drives the arm: the controller goal is canceled, the arm
    comes to rest, the goal ends ABORTED saying the planner was stopping, and the planner exits 0 with no
    traceback (it used to die in the shut-down context, leaving the controller goal to run on its own)."""
    import signal

    stack = arm_stack()
    q0 = np.array(stack.q)
    handle = stack.send("change_pose", joint_goal([q0[0] + 1.2, -0.5, 1.3, 0.5]))
    assert handle.accepted
    assert stack.spin_until(lambda: abs(stack.q[0] - q0[0]) > 0.15, 30), "did not start moving"
    planner = stack.procs["planner"]
    planner.signal(signal.SIGINT)
    status, res = stack.result(handle, 30)
    t_end = time.monotonic()
    assert status == ABORTED and res.error_code.val == codes.FAILURE, (status, res.message)
    assert res.message.startswith("zx200_planner stopping (SIGINT/SIGTERM): canceled, arm at rest"), res.message
    assert planner.wait(20) == 0, planner.output[-3000:]
    assert "Traceback" not in planner.output, planner.output[-3000:]
    assert stack.procs["controller"].wait_for("canceled", 5), stack.procs["controller"].output[-2000:]
    _, _, v = min((s for s in stack.dq_log if s[0] >= t_end - 0.3), key=lambda s: abs(s[0] - t_end))
    assert max(abs(x) for x in v) < 0.02, f"ended while moving: {v}"
    q_c = np.array(stack.q)
    stack.spin(2.0)
    assert np.max(np.abs(np.array(stack.q) - q_c)) < 0.01, "arm kept moving after the planner stopped"
