"""Node ``tms_sp_tf``: the site's ``/tf``, ``/tf_static`` and each machine's ``robot_description``.

What ``robot_state_publisher`` and a localisation's tf broadcaster give an RViz user, for every machine of
the site in one node (the tree and its names: :mod:`tms_sp.site_tf`, :mod:`tms_model.urdf`):

* ``/<machine>/robot_description`` (std_msgs/String, reliable, transient local, depth 1: latched): the URDF
  generated from the machine's description, OPERA's link and joint names;
* ``/tf_static`` (tf2_msgs/TFMessage, reliable, transient local, depth 1): ``world -> map`` and every
  fixed joint, once at start;
* ``/tf`` (tf2_msgs/TFMessage, reliable, depth 100): on every ``/<machine>/joint_states`` the moving joints
  it drives, on every ``/<machine>/odom_pose`` (nav_msgs/Odometry) ``odom -> base_link`` (and ``map ->
  odom`` for a pose in ``map``), on every ``/<machine>/map_to_odom`` (geometry_msgs/TransformStamped)
  ``map -> odom``; each stamped with its message's stamp.

Parameters (read at start-up): ``machines`` (string array of names of config/site.yaml ``machines``; [] = those
of ``config``; each machine is one tree, its kind's description with its own /tf prefix, its topics under
``/<name>/``), ``config`` (default config/tms_sp/site_tf.yaml), ``site`` (site YAML, default config/site.yaml).
A malformed message is logged naming the machine and field and publishes nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from tf2_msgs.msg import TFMessage
from tms_common.config import config_path
from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_common.schema import load_schema
from tms_model.fleet import load_named
from tms_model.site import load_site
from tms_model.urdf import machine_tree
from tms_sp.site_tf import SiteTf, StampedTransform

__all__ = ["LATCHED", "TF_QOS", "TfConfig", "TfPublisher", "main"]

#: robot_description and /tf_static: what robot_state_publisher and tf2's static broadcaster offer.
LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /tf: tf2's broadcaster and listener profile.
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)


@dataclass(frozen=True)
class TfConfig:
    """config/tms_sp/site_tf.yaml."""

    machines: tuple[str, ...]  # site machine names


def _seconds(stamp: Any) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def _msg(t: StampedTransform) -> TransformStamped:
    out = TransformStamped()
    out.header.stamp.sec = int(t.stamp // 1)
    out.header.stamp.nanosec = min(int(round((t.stamp % 1) * 1e9)), 999_999_999)
    out.header.frame_id, out.child_frame_id = t.parent, t.child
    tr, rot = out.transform.translation, out.transform.rotation
    tr.x, tr.y, tr.z = t.transform.translation
    rot.x, rot.y, rot.z, rot.w = t.transform.rotation
    return out


class TfPublisher(Node):
    """Feeds :class:`SiteTf` from the machines' topics and publishes its transforms; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sp_tf", **kwargs)
        self._log = self.get_logger()
        machines = [str(m) for m in declare_startup(self, "machines", [""]).value if m]
        config = str(declare_startup(self, "config", "").value)
        site_path = str(declare_startup(self, "site", "").value)
        if not machines:
            machines = list(load_schema(TfConfig, config or config_path("tms_sp", "site_tf.yaml")).machines)
        site = load_site(site_path or None)
        # each machine by its name: its kind's description with its own /tf prefix
        trees = [machine_tree(load_named(m, site=site)) for m in machines]
        self.core = SiteTf(trees, site)
        self.pub_tf = self.create_publisher(TFMessage, "/tf", TF_QOS)
        self.pub_static = self.create_publisher(TFMessage, "/tf_static", LATCHED)
        self.pub_description = {}
        for name, t in self.core.trees.items():
            pub = self.create_publisher(String, f"/{name}/robot_description", LATCHED)
            pub.publish(String(data=t.urdf()))
            self.pub_description[name] = pub
            self.create_subscription(JointState, f"/{name}/joint_states", lambda m, k=name: self._on_joints(k, m), 50)
            self.create_subscription(Odometry, f"/{name}/odom_pose", lambda m, k=name: self._on_odom(k, m), 50)
            self.create_subscription(TransformStamped, f"/{name}/map_to_odom",
                                     lambda m, k=name: self._on_map_to_odom(k, m), 50)
        static = self.core.static(_seconds(self.get_clock().now().to_msg()))
        self.pub_static.publish(TFMessage(transforms=[_msg(t) for t in static]))
        self._log.info(f"tms_sp_tf ready: machines {machines}, {len(static)} static transforms")

    def _publish(self, what: str, machine: str, make: Any) -> None:
        try:
            transforms = make()
        except ValueError as exc:
            self._log.warning(f"{what} ignored: {exc}", throttle_duration_sec=1.0)
            return
        if transforms:
            self.pub_tf.publish(TFMessage(transforms=[_msg(t) for t in transforms]))

    def _on_joints(self, machine: str, msg: JointState) -> None:
        self._publish("joint_states", machine, lambda: self.core.joint_states(
            machine, list(msg.name), list(msg.position), _seconds(msg.header.stamp)))

    def _on_odom(self, machine: str, msg: Odometry) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        self._publish("odom_pose", machine, lambda: self.core.odometry(
            machine, msg.header.frame_id, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), _seconds(msg.header.stamp)))

    def _on_map_to_odom(self, machine: str, msg: TransformStamped) -> None:
        t, r = msg.transform.translation, msg.transform.rotation
        self._publish("map_to_odom", machine, lambda: self.core.map_to_odom(
            machine, msg.header.frame_id, (t.x, t.y, t.z), (r.x, r.y, r.z, r.w), _seconds(msg.header.stamp)))


def main() -> int:
    return run_node(TfPublisher)
