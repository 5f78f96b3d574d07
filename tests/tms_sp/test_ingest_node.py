"""A sensing PC speaking only the original's ``sensing_msgs`` drives the DB through a ``tms_sp_ingest`` process."""

from __future__ import annotations

import time

import pytest

from tests.rosproc import executable
from tests.tms_sp.test_ingest import FLAGS, PATH, POSE
from tms_db import open_store

pytestmark = pytest.mark.integration

RELEASE = {"model_name": "zx200", "type": "dynamic", "record_name": "release_angle", "target_angle": 0.0}


def _wait_db(db, predicate, timeout: float, what: str, proc):
    deadline = time.monotonic() + timeout
    while True:
        with open_store(path=db) as store:
            if predicate(store):
                return
        assert time.monotonic() < deadline, f"timed out waiting for {what}:\n{proc.output[-3000:]}"
        time.sleep(0.2)


def test_sensing_msgs_publishers_set_flags_and_targets(procs, ros_node, tmp_path) -> None:
    from sensing_msgs.msg import ChangePose, Flgs202508, FollowWaypoints, ReleaseAngle

    db = tmp_path / "db"
    with open_store(path=db) as store:
        for doc in (FLAGS, POSE, PATH, RELEASE):
            store.upsert_parameter(doc)
    ingest = procs([executable("tms_sp", "tms_sp_ingest"), "--ros-args", "-p", f"db_path:={db}"], name="ingest")
    assert ingest.wait_for("tms_sp_ingest ready", 60), ingest.output
    pubs = {topic: ros_node.create_publisher(t, topic, 10) for topic, t in
            (("/Flgs", Flgs202508), ("/tms_sp_change_pose", ChangePose), ("/tms_sp_follow_waypoints", FollowWaypoints),
             ("/tms_sp_release_angle", ReleaseAngle))}
    deadline = time.monotonic() + 30
    while not all(p.get_subscription_count() for p in pubs.values()):
        assert time.monotonic() < deadline, f"tms_sp_ingest never subscribed:\n{ingest.output}"
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)

    # a message for a record the DB lacks is named and dropped; the node goes on
    pubs["/tms_sp_change_pose"].publish(ChangePose(model_name="zx200", record_name="missing_pose", swing_joint=1.0))
    pubs["/Flgs"].publish(Flgs202508(record_name="GLOBAL_BLACKBOARD_EARTHWORK", continue_flg=True,
                                     sensing_arrival_flg=True, keep_val_flgs=["SENSING_LOADED_FLG"]))
    _wait_db(db, lambda s: s.get_record("GLOBAL_BLACKBOARD_EARTHWORK")["SENSING_ARRIVAL_FLG"] is True, 30,
             "SENSING_ARRIVAL_FLG true", ingest)
    with open_store(path=db) as store:
        doc = store.get_record("GLOBAL_BLACKBOARD_EARTHWORK")
    assert doc["SENSING_LOADED_FLG"] is False and doc["CONTINUE_FLG"] is True  # kept; carried unchanged
    assert ingest.wait_for("/tms_sp_change_pose: dropped: record (zx200, missing_pose) not in the DB", 10), (
        ingest.output
    )

    pubs["/tms_sp_change_pose"].publish(ChangePose(model_name="zx200", record_name="dig_pose", swing_joint=0.5,
                                                   boom_joint=-0.25, arm_joint=1.0, bucket_joint=0.75))
    pubs["/tms_sp_follow_waypoints"].publish(FollowWaypoints(
        model_name="ic120", record_name="LOAD_PATH", x=[1.0, 2.0], y=[3.0, 4.0], z=[0.0, 0.0],
        qx=[0.0, 0.0], qy=[0.0, 0.0], qz=[0.0, 0.0], qw=[1.0, 1.0]))
    _wait_db(db, lambda s: s.get_parameter("ic120", "LOAD_PATH")["x"] == [1.0, 2.0]
             and s.get_parameter("zx200", "dig_pose")["swing_joint"] == 0.5, 30, "the targets", ingest)
    with open_store(path=db) as store:
        pose = store.get_parameter("zx200", "dig_pose")
        assert (pose["boom_joint"], pose["arm_joint"], pose["bucket_joint"], pose["trajectory"]) == (
            -0.25,
            1.0,
            0.75,
            1,
        )
        assert store.get_parameter("ic120", "LOAD_PATH")["y"] == [3.0, 4.0]

    # an updater the original's newest main added (ReleaseAngle on /tms_sp_release_angle)
    pubs["/tms_sp_release_angle"].publish(ReleaseAngle(model_name="zx200", record_name="release_angle",
                                                       target_angle=1.25))
    _wait_db(db, lambda s: s.get_parameter("zx200", "release_angle")["target_angle"] == 1.25, 30, "release_angle",
             ingest)
