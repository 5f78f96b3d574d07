"""Node ``tms_sp_machine``: every machine's joints, odometry and pose into the DB, as the original's
``tms_sp_machine_joints`` / ``_odom`` / ``_posest`` writers (one node for all machines and inputs here).

For each machine of ``machines``: ``/<machine>/<joints_topic>`` (sensor_msgs/JointState) -> type ``machine_joints``,
``/<machine>/<odom_topic>`` (nav_msgs/Odometry) and ``/<machine>/<pose_topic>`` (geometry_msgs/PoseStamped) -> type
``machine_pose``; each as a ``tms_msg_db/Tmsdb`` (id 3012, name the machine, msg the message's JSON, time the wall
clock) on ``/tms_db_data``, where ``tms_db_writer`` stores it (:mod:`tms_sp.machine_state`).

Parameters (read at start-up): ``machines`` (names; [] = every machine of config/site.yaml), ``site``,
``joints_topic`` (``joint_states``), ``odom_topic`` (``odometry/global``: the localisation's output), ``pose_topic``
(``""``: none; an empty name turns an input off), ``rate_hz`` (1.0: the newest message of each machine and input
once a second; 0: every message, as the original, which at 50 Hz joint states fills a disk).
"""

from __future__ import annotations

from typing import Any

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_model.site import load_site
from tms_msg_db.msg import Tmsdb
from tms_sp.machine_state import MachineStateSampler

__all__ = ["TmsSpMachine", "main", "DATA_TOPIC"]

#: the original's writer topic (tms_db_writer subscribes it)
DATA_TOPIC = "/tms_db_data"
_INPUTS = (("joints", "joints_topic", "joint_states", JointState), ("odom", "odom_topic", "odometry/global", Odometry),
           ("pose", "pose_topic", "", PoseStamped))


class TmsSpMachine(Node):
    """Feeds :class:`MachineStateSampler` from the machines' topics and publishes its documents."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sp_machine", **kwargs)
        machines = [str(m) for m in declare_startup(self, "machines", [""]).value if m]
        site_path = str(declare_startup(self, "site", "").value)
        rate_hz = float(declare_startup(self, "rate_hz", 1.0).value)
        if not machines:
            machines = list(load_site(site_path or None).machines)
        self.core = MachineStateSampler(machines, rate_hz)
        self.pub = self.create_publisher(Tmsdb, DATA_TOPIC, QoSProfile(depth=100,
                                                                        reliability=ReliabilityPolicy.RELIABLE))
        topics = []
        for source, param, default, msg_type in _INPUTS:
            name = str(declare_startup(self, param, default).value).strip("/")
            if not name:
                continue
            for machine in self.core.machines:
                topic = f"/{machine}/{name}"
                self.create_subscription(msg_type, topic, lambda m, k=machine, s=source: self._on_msg(k, s, m), 50)
                topics.append(topic)
        if rate_hz > 0:
            self.create_timer(1.0 / rate_hz, self._tick)
        self.get_logger().info(f"tms_sp_machine ready: {len(topics)} inputs ({', '.join(topics)}) -> {DATA_TOPIC} "
                               f"{f'at {rate_hz:g} Hz' if rate_hz else 'every message'}")

    def _publish(self, fields: dict) -> None:
        self.pub.publish(Tmsdb(**fields))

    def _on_msg(self, machine: str, source: str, msg: Any) -> None:
        fields = self.core.offer(machine, source, msg)
        if fields is not None:
            self._publish(fields)

    def _tick(self) -> None:
        for fields in self.core.take():
            self._publish(fields)


def main() -> int:
    return run_node(TmsSpMachine)
