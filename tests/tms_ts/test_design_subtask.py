"""The design subtask end to end on ROS with planning stubs: ``tms_ts_subtasks`` reads the design and the dynamic
heightmap from the store, runs a pass as the original's excavate, change_pose and release goals, and ends SUCCEEDED
when the newest terrain is within tolerance; a missing design or one out of reach ends with a message naming it."""

from __future__ import annotations

import sys
import time

import numpy as np
import pytest

from tests.rosproc import executable
from tests.tms_ts.test_subtask_outcomes import _spin_until
from tms_db import open_store, put_design
from tms_model.excavator.kinematics import site_excavator_kind
from tms_rp.excavation.design import Design
from tms_sp.terrain import DYNAMIC_ID, Heightmap, now_text, store_heightmap
from tms_ts.subtask_specs import SUBTASKS

KIND = site_excavator_kind()
ROW = next(s for s in SUBTASKS.values() if s.name.endswith("_excavate_design") and s.machine == KIND)
TRENCH = {"name": "tr", "kind": "trench", "start": [-5.0, -2.0], "end": [-5.0, 2.0], "width": 1.0, "depth": 0.3,
          "ground_z": 0.0, "margin": 0.5}
FAR = {**TRENCH, "name": "far", "start": [-25.0, -2.0], "end": [-25.0, 2.0]}
BOX = {"x_min": -27.0, "x_max": 3.0, "y_min": -6.0, "y_max": 6.0}


def terrain(store, dug: bool) -> None:
    """A flat dynamic heightmap at 0.1 m cells; ``dug``: with the trench cut to its design."""
    z = np.zeros((120, 300))
    hm = Heightmap(z=z, z_min=-1.0, **BOX)
    if dug:
        xc, yc = hm.centres()
        hm = Heightmap(z=Design.from_dict(TRENCH).height(xc, yc), z_min=-1.0, **BOX)
    store_heightmap(store, hm, kind="dynamic", ident=DYNAMIC_ID, filename="dynamic_terrain.png", time=now_text())


@pytest.fixture
def design_servers(tmp_path, procs):
    db = str(tmp_path / "db")
    with open_store(path=db) as store:
        for name in ("tr", "far", "gone"):
            store.upsert_parameter({"model_name": KIND, "type": "static", "record_name": f"job_{name}",
                                    "design": name, "base_x": 0.0, "base_y": 0.0, "base_yaw": 0.0,
                                    "dump_x": 1.0, "dump_y": -7.5})
        store.upsert_parameter({"model_name": KIND, "type": "static", "record_name": "job_far_measured",
                                "design": "far", "base_measured": 1, "scope": "reachable", "dump_x": 1.0,
                                "dump_y": -7.5})
        put_design(store, TRENCH)
        put_design(store, FAR)
        terrain(store, dug=False)
    stub = procs([sys.executable, "-m", "tests.tms_ts.planning_stub", "--ros-args", "-p", f"model_names:={KIND}",
                  "-p", "duration_s:=0.2"], name="stub")
    subtasks = procs([executable("tms_ts", "tms_ts_subtasks"), "--ros-args", "-p", f"machine:={KIND}",
                      "-p", f"db_path:={db}", "-p", "terrain_wait_s:=20.0"], name="subtasks")
    assert subtasks.wait_for("subtask servers", 60), subtasks.output
    return db, stub, subtasks


@pytest.mark.integration
def test_a_pass_runs_as_the_originals_goals_and_the_design_ends_within_tolerance(design_servers, ros_node):
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_common.goals import OUTCOME_QOS
    from tms_msg.msg import SubtaskOutcome
    from tms_msg_ts.action import LeafNodeBase

    db, stub, _ = design_servers
    client = ActionClient(ros_node, LeafNodeBase, f"/{KIND}/{ROW.name}")
    outcomes: dict[bytes, SubtaskOutcome] = {}
    ros_node.create_subscription(SubtaskOutcome, f"/{KIND}/subtask_outcome",
                                 lambda m: outcomes.__setitem__(bytes(m.goal_id.uuid), m), OUTCOME_QOS)
    _spin_until(ros_node, client.server_is_ready, 30, "the subtask server")

    def run(record: str, during=None) -> tuple[int, SubtaskOutcome]:
        future = client.send_goal_async(LeafNodeBase.Goal(model_name=KIND, record_name=record))
        _spin_until(ros_node, future.done, 10, "the goal response")
        handle = future.result()
        result = handle.get_result_async()
        if during is not None:
            during()
        _spin_until(ros_node, result.done, 60, f"the result of {record}")
        key = bytes(handle.goal_id.uuid)
        _spin_until(ros_node, lambda: key in outcomes, 5, "the SubtaskOutcome")
        return result.result().status, outcomes[key]

    def dig_after_the_first_excavate() -> None:  # the machine "dug": sensing stores the finished trench
        assert stub.wait_for("GOAL", 30), stub.output
        with open_store(path=db) as store:
            terrain(store, dug=True)

    started = time.monotonic()
    status, outcome = run("job_tr", dig_after_the_first_excavate)
    assert status == GoalStatus.STATUS_SUCCEEDED, outcome.error_msg
    assert outcome.error_msg.startswith("design 'tr' done after 1 pass(es)") and "within tolerance" in outcome.error_msg
    assert time.monotonic() - started < 60
    assert stub.wait_for("DONE", 5)
    goals = [line.split()[1] for line in stub.output.splitlines() if line.startswith("GOAL ")]
    assert [g.rsplit("/", 1)[-1] for g in goals] == [ROW.steps[w].planning_action for w in
                                                      ("excavate", "change_pose", "release")], goals

    status, outcome = run("job_far")
    assert status == GoalStatus.STATUS_ABORTED and outcome.error_code == SubtaskOutcome.PLANNING_FAILED
    assert outcome.error_msg.startswith("design 'far': the pass planner stops after 0 pass(es)")
    assert "nothing reachable to cut" in outcome.error_msg

    status, outcome = run("job_gone")
    assert status == GoalStatus.STATUS_ABORTED and outcome.error_code == SubtaskOutcome.RECORD_INVALID
    assert "design 'gone': not in the store's collection 'design' (stored: 'far', 'tr'" in outcome.error_msg

    # a leg of a tree of several bases: without the machine's pose in map, nothing; with it, the base it measured
    status, outcome = run("job_far_measured")
    assert status == GoalStatus.STATUS_ABORTED and outcome.error_code == SubtaskOutcome.PLANNING_UNAVAILABLE
    assert f"design 'far': base pose from /{KIND}/odom_pose: 0 message(s) in frame 'map' within" in outcome.error_msg

    from nav_msgs.msg import Odometry

    pose_pub = ros_node.create_publisher(Odometry, f"/{KIND}/odom_pose", 10)

    def publish_pose() -> None:  # the converter's pose in map of a machine standing at (3, 1) facing north
        msg = Odometry()
        msg.header.frame_id = "map"
        msg.pose.pose.position.x, msg.pose.pose.position.y = 3.0, 1.0
        msg.pose.pose.orientation.z = msg.pose.pose.orientation.w = 0.5 ** 0.5
        pose_pub.publish(msg)

    timer = ros_node.create_timer(0.02, publish_pose)
    try:
        status, outcome = run("job_far_measured")
    finally:
        ros_node.destroy_timer(timer)
    assert status == GoalStatus.STATUS_SUCCEEDED, outcome.error_msg
    # base_link from the swing centre: less the description's swing origin (0.108, -0.034) turned to face north
    assert outcome.error_msg.startswith("design 'far': the part reachable from the base at (2.97, 0.89, yaw 1.571) "
                                        "done after 0 pass(es)"), outcome.error_msg
