"""Node ``tms_ur_db_writer``: a machine's pose and joints from the user interface into the DB.

Takes ``tms_msg_ur/TmsdbPoseWriteMsg`` on ``/input/WriteDB/pose_joint`` and the service ``/input/DB_machine/data``
(``tms_msg_ur/TmsdbTerrainDBPoseWriteSrv``), the original's ``tms_ur_db_writer`` names, and publishes one
``tms_msg_db/TmsdbQuery`` on ``tms_db_param_data`` per write (:mod:`tms_ur.db_pose_writer` says what is checked).
The service answers ``written`` false with the reason in ``log_data`` for a write it refused, and for any write
while no parameter writer subscribes to ``tms_db_param_data`` (the query would reach no one). The node logs each
change in the number of parameter writers it reaches.
"""

from __future__ import annotations

import sys
from datetime import datetime
from typing import Any

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node

from tms_common.node import run_node
from tms_msg_db.msg import TmsdbQuery
from tms_msg_ur.msg import TmsdbPoseWriteMsg
from tms_msg_ur.srv import TmsdbTerrainDBPoseWriteSrv
from tms_ur.db_pose_writer import DATA_ID, PoseWrite, PoseWriteError, check_pose_write

__all__ = ["DbPoseWriter", "main"]

TOPIC = "/input/WriteDB/pose_joint"
SERVICE = "/input/DB_machine/data"
QUERY_TOPIC = "tms_db_param_data"


class DbPoseWriter(Node):
    """See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_db_writer", **kwargs)
        self._pub = self.create_publisher(TmsdbQuery, QUERY_TOPIC, 10,
                                          event_callbacks=PublisherEventCallbacks(matched=self._on_matched))
        self.create_subscription(TmsdbPoseWriteMsg, TOPIC, self._on_write, 10)
        self.create_service(TmsdbTerrainDBPoseWriteSrv, SERVICE, self._on_request)
        self.get_logger().info(f"tms_ur_db_writer ready: {TOPIC}, {SERVICE} -> {QUERY_TOPIC}")

    def _on_matched(self, info: Any) -> None:
        self.get_logger().info(f"{QUERY_TOPIC}: {info.current_count} parameter writer(s) subscribed")

    def _on_write(self, msg: Any) -> None:
        try:
            self._publish(msg)
        except PoseWriteError as exc:
            self.get_logger().error(f"{TOPIC}: refused, nothing written: {exc}")

    def _on_request(self, request: Any, response: Any) -> Any:
        try:
            self._publish(request)
        except PoseWriteError as exc:
            self.get_logger().error(f"{SERVICE}: refused, nothing written: {exc}")
            response.written, response.log_data = False, f"refused: {exc}"
            return response
        response.written = True
        response.log_data = f"{request.record_type} {request.machine_name}/{request.record_name} -> {QUERY_TOPIC}"
        return response

    def _publish(self, write: Any) -> None:
        check_pose_write(PoseWrite(write.machine_name, write.record_type, write.record_name, write.write_target,
                                   len(write.joints.position)))
        if self._pub.get_subscription_count() == 0:
            # a publish with no subscriber is lost; saying "written" then would be a lie
            raise PoseWriteError(f"no parameter writer subscribes to {QUERY_TOPIC} (is tms_db_writer_param running?)")
        query = TmsdbQuery()
        query.time = datetime.now().isoformat()
        query.type = write.record_type
        query.id = DATA_ID
        query.writemode = write.write_target
        query.record_name = write.record_name
        query.vehicle_name = write.machine_name
        query.add_path = write.pose
        query.add_joints = write.joints
        self._pub.publish(query)


def main(args: list[str] | None = None) -> int:
    return run_node(DbPoseWriter, args)


if __name__ == "__main__":
    sys.exit(main())
