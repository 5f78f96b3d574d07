"""tms_sp.machine_state: the original's tms_sp_machine documents, without ROS (the messages are the real types)."""

from __future__ import annotations

import datetime as dt
import json

import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState

from tms_sp.errors import SensingError
from tms_sp.machine_state import (
    DATA_ID,
    MachineStateSampler,
    message_to_document,
    stamp_text,
    tmsdb_fields,
)


def _joints(*position: float) -> JointState:
    msg = JointState(name=[f"j{i}" for i in range(len(position))], position=list(position))
    msg.header.stamp.sec, msg.header.frame_id = 12, "base_link"
    return msg


def _odom(x: float) -> Odometry:
    msg = Odometry(child_frame_id="base_link")
    msg.header.frame_id = "map"
    msg.pose.pose.position.x = x
    msg.pose.covariance[0] = 0.5
    return msg


def test_documents_have_the_originals_shape() -> None:
    doc = json.loads(tmsdb_fields("a", "joints", _joints(0.1, 0.2), "t")["msg"])
    # what the original's msg_to_document gives for a JointState: every field, nested, arrays as lists
    assert doc == {"header": {"stamp": {"sec": 12, "nanosec": 0}, "frame_id": "base_link"},
                   "name": ["j0", "j1"], "position": [0.1, 0.2], "velocity": [], "effort": []}
    fields = tmsdb_fields("a", "odom", _odom(3.0), "t")
    assert (fields["type"], fields["id"], fields["name"], fields["time"]) == ("machine_pose", DATA_ID, "a", "t")
    odom = json.loads(fields["msg"])
    assert odom["pose"]["pose"]["position"] == {"x": 3.0, "y": 0.0, "z": 0.0}
    assert len(odom["pose"]["covariance"]) == 36 and odom["pose"]["covariance"][0] == 0.5
    assert odom["child_frame_id"] == "base_link" and set(odom) == {"header", "child_frame_id", "pose", "twist"}
    pose = json.loads(tmsdb_fields("a", "pose", PoseStamped(), "t")["msg"])
    assert set(pose) == {"header", "pose"} and pose["pose"]["orientation"]["w"] == 1.0
    assert tmsdb_fields("a", "joints", _joints(1.0), "t")["type"] == "machine_joints"


def test_non_finite_values_become_null() -> None:
    assert message_to_document(_joints(float("nan"), 1.0))["position"] == [None, 1.0]
    json.loads(tmsdb_fields("a", "joints", _joints(float("inf")), "t")["msg"])  # strict JSON


def test_time_always_has_microseconds() -> None:
    assert stamp_text(dt.datetime(2025, 3, 4, 5, 6, 7)) == "2025-03-04T05:06:07.000000"
    dt.datetime.strptime(stamp_text(dt.datetime.now()), "%Y-%m-%dT%H:%M:%S.%f")  # the original's reader's format


def test_rate_zero_writes_every_message() -> None:
    sampler = MachineStateSampler(["a", "b"], 0.0, clock=lambda: dt.datetime(2025, 1, 1))
    out = [sampler.offer("a", "joints", _joints(float(i))) for i in range(3)]
    assert [json.loads(f["msg"])["position"] for f in out] == [[0.0], [1.0], [2.0]]
    assert sampler.take() == []


def test_a_tick_takes_the_newest_of_each_machine_and_input() -> None:
    times = iter(dt.datetime(2025, 1, 1, 0, 0, s) for s in range(10))
    sampler = MachineStateSampler(["b", "a"], 2.0, clock=lambda: next(times))
    for i in range(3):
        assert sampler.offer("a", "joints", _joints(float(i))) is None
    sampler.offer("b", "odom", _odom(7.0))
    sampler.offer("a", "odom", _odom(5.0))
    out = sampler.take()
    assert [(f["name"], f["type"]) for f in out] == [("b", "machine_pose"), ("a", "machine_joints"),
                                                     ("a", "machine_pose")]
    assert json.loads(out[1]["msg"])["position"] == [2.0] and out[1]["time"] == "2025-01-01T00:00:02.000000"
    assert sampler.take() == []  # nothing new since


def test_bad_configuration_and_input() -> None:
    with pytest.raises(SensingError, match="machines"):
        MachineStateSampler([], 1.0)
    with pytest.raises(SensingError, match="rate_hz"):
        MachineStateSampler(["a"], -1.0)
    sampler = MachineStateSampler(["a"], 1.0)
    with pytest.raises(SensingError, match="machine 'z' is not one of"):
        sampler.offer("z", "joints", _joints(1.0))
    with pytest.raises(SensingError, match="input 'imu'"):
        tmsdb_fields("a", "imu", _joints(1.0), "t")
