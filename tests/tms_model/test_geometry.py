"""tms_model.geometry: yaw <-> quaternion for tuples and message-like objects, angle wrap, planar poses."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tms_model.geometry import Pose2D, quaternion_from_yaw, wrap_angle, yaw_from_quaternion, yaw_from_wxyz


@pytest.mark.parametrize("yaw", [0.0, 0.3, -1.2, 3.0, -3.1, math.pi / 2])
def test_yaw_round_trip_tuple_array_and_message(yaw: float) -> None:
    q = quaternion_from_yaw(yaw)
    assert yaw_from_quaternion(q) == pytest.approx(yaw, abs=1e-12)
    assert yaw_from_quaternion(np.array(q)) == pytest.approx(yaw, abs=1e-12)
    msg = SimpleNamespace(x=q[0], y=q[1], z=q[2], w=q[3])
    assert yaw_from_quaternion(msg) == pytest.approx(yaw, abs=1e-12)
    assert yaw_from_wxyz((q[3], q[0], q[1], q[2])) == pytest.approx(yaw, abs=1e-12)


def test_yaw_ignores_roll_and_pitch() -> None:
    # roll 0.4 then yaw 1.0 (ZYX): the yaw read back is 1.0
    cr, sr = math.cos(0.2), math.sin(0.2)
    cy, sy = math.cos(0.5), math.sin(0.5)
    q = (sr * cy, sr * sy, cr * sy, cr * cy)
    assert yaw_from_quaternion(q) == pytest.approx(1.0, abs=1e-12)


def test_bad_quaternion_length_names_it() -> None:
    with pytest.raises(ValueError, match="4 components"):
        yaw_from_quaternion((0.0, 0.0, 1.0))


def test_wrap_angle() -> None:
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_angle(0.25) == 0.25
    for a in np.linspace(-20, 20, 101):
        w = wrap_angle(float(a))
        assert -math.pi <= w <= math.pi
        assert math.sin(w) == pytest.approx(math.sin(a), abs=1e-9)
        assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-9)


def test_pose2d_round_trip() -> None:
    pose = Pose2D(2.0, -1.0, 0.7, 0.5)
    pts = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 0.0]])
    assert np.allclose(pose.from_map(pose.to_map(pts)), pts)
    assert np.allclose(pose.to_map(np.array([1.0, 0.0, 0.0])), [2.0 + math.cos(0.7), -1.0 + math.sin(0.7), 0.5])
