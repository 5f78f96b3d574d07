"""The user interface's pose and joint writes into the DB, as the original's ``tms_ur_db_writer`` makes them.

A user (or a sensing PC) sends a machine's pose and joints as ``tms_msg_ur/TmsdbPoseWriteMsg`` on
``/input/WriteDB/pose_joint`` or as the service ``/input/DB_machine/data`` (``TmsdbTerrainDBPoseWriteSrv``);
the writer turns each into one ``tms_msg_db/TmsdbQuery`` on ``tms_db_param_data``, which tms_db's parameter
writer applies. ``record_type`` picks what the DB does with it (the parameter writer's ``type``): ``pose`` (a new
pose record), ``joint`` (a new static joint record) or ``pose_query`` (a waypoint appended to, or with
``write_target`` ``over_write`` replacing, the path of an existing record).

Beside the original: the query carries the request's ``record_name`` (the original leaves it empty, so its
parameter writer stores records without a name) and ``write_target`` as the query's ``writemode``; a request the
parameter writer could not apply (an unknown ``record_type``, no machine or record name, a joint write without
positions) is refused here, named, and nothing is published.
"""

from __future__ import annotations

from dataclasses import dataclass

from tms_common.errors import TmsError

__all__ = ["RECORD_TYPES", "PoseWrite", "PoseWriteError", "check_pose_write"]

#: The parameter writer's query types a pose write may name.
RECORD_TYPES = ("pose", "joint", "pose_query")
#: The data id the original's writer stamps on its queries.
DATA_ID = 3012


class PoseWriteError(TmsError):
    """A pose write the DB could not apply; the message names the field."""


@dataclass(frozen=True)
class PoseWrite:
    """The fields of one request that decide the query (the pose and joints are copied as they are)."""

    machine_name: str
    record_type: str
    record_name: str
    write_target: str
    joint_count: int


def check_pose_write(write: PoseWrite) -> None:
    """Raise :class:`PoseWriteError` naming the field when the parameter writer could not apply ``write``."""
    if write.record_type not in RECORD_TYPES:
        raise PoseWriteError(f"record_type {write.record_type!r}: expected one of {', '.join(RECORD_TYPES)}")
    if not write.machine_name:
        raise PoseWriteError("machine_name: empty (the record's model_name)")
    if not write.record_name:
        raise PoseWriteError(f"record_name: empty (a {write.record_type} write names its record)")
    if write.record_type == "joint" and write.joint_count < 5:
        raise PoseWriteError(
            f"joints: {write.joint_count} positions, a joint write needs 5 (swing, boom, arm, bucket, bucket_end)"
        )
