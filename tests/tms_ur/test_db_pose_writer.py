"""tms_ur.db_pose_writer: which pose writes the parameter writer could apply."""

from __future__ import annotations

import pytest

from tms_ur.db_pose_writer import PoseWrite, PoseWriteError, check_pose_write


@pytest.mark.parametrize("record_type", ["pose", "pose_query"])
def test_pose_writes_need_a_machine_and_a_record(record_type):
    check_pose_write(PoseWrite("ic120", record_type, "LOAD_PATH", "over_write", 0))
    with pytest.raises(PoseWriteError, match="machine_name: empty"):
        check_pose_write(PoseWrite("", record_type, "LOAD_PATH", "", 0))
    with pytest.raises(PoseWriteError, match="record_name: empty"):
        check_pose_write(PoseWrite("ic120", record_type, "", "", 0))


def test_joint_writes_need_five_positions_and_types_are_the_writers():
    check_pose_write(PoseWrite("zx200", "joint", "dig_pose", "", 5))
    with pytest.raises(PoseWriteError, match="joints: 4 positions, a joint write needs 5"):
        check_pose_write(PoseWrite("zx200", "joint", "dig_pose", "", 4))
    with pytest.raises(PoseWriteError, match="record_type 'para': expected one of pose, joint, pose_query"):
        check_pose_write(PoseWrite("zx200", "para", "dig_pose", "", 5))
