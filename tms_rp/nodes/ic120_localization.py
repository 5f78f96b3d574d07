"""``ic120_localization``: EKF fusion of track odometry, GNSS and azimuth (thin rclpy wrapper of Ic120Ekf).

Run in the machine namespace: ``ic120_localization --ros-args -r __ns:=/ic120``.
Subscribes ``odom_pose`` (nav_msgs/Odometry, frame odom), ``gnss/fix`` (sensor_msgs/NavSatFix) and ``imu``
(sensor_msgs/Imu, orientation yaw = azimuth, ENU). Publishes ``odometry/global`` (nav_msgs/Odometry,
frame ``map``, child ``base_link``, pose covariance of x, y, yaw; twist copied from odometry; stamped with
the odometry message's stamp) on every odometry message once a GNSS fix arrived, and ``map_to_odom`` (geometry_msgs/TransformStamped, the REP-105
map -> odom correction, which ``tms_sp_tf`` puts on /tf). Parameters: ``nav_config`` (YAML,
default config/nav/ic120_nav.yaml), ``site_config`` (default config/site.yaml), ``use_azimuth`` (true),
``base_frame`` / ``odom_frame`` (default: the IC120's /tf frames, ``ic120_tf/base_link`` / ``ic120_tf/odom``)
/ ``map_frame``.
"""

from __future__ import annotations

import math
from typing import Any

from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import Imu, NavSatFix

from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_model.geometry import yaw_from_quaternion
from tms_model.machines import load_machine
from tms_model.site import Projector, load_site
from tms_rp.ic120.config import load_nav_config
from tms_rp.ic120.ekf import Ic120Ekf

__all__ = ["main", "Ic120Localization"]


class Ic120Localization(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__("ic120_localization", **kwargs)
        nav_config = str(declare_startup(self, "nav_config", "").value)
        site_config = str(declare_startup(self, "site_config", "").value)
        self.use_azimuth = bool(declare_startup(self, "use_azimuth", True).value)
        machine = load_machine("ic120")
        self.base_frame = str(declare_startup(self, "base_frame", machine.frame("base_link")).value)
        self.odom_frame = str(declare_startup(self, "odom_frame", machine.frame("odom")).value)
        self.map_frame = str(declare_startup(self, "map_frame", "map").value)
        cfg = load_nav_config(nav_config or None)
        site = load_site(site_config or None)
        self.projector = Projector(site.crs, site.origin_plane, cfg.geodetic_crs)
        self.ekf = Ic120Ekf(cfg.ekf)
        self._log = self.get_logger()
        self.pub = self.create_publisher(Odometry, "odometry/global", 10)
        self.pub_tf = self.create_publisher(TransformStamped, "map_to_odom", 10)
        self.create_subscription(Odometry, "odom_pose", self._on_odom, 50)
        self.create_subscription(NavSatFix, "gnss/fix", self._on_fix, 50)
        self.create_subscription(Imu, "imu", self._on_imu, 50)
        self._rejected_logged = 0
        self._log.info(f"EKF ready ({cfg.file}); waiting for the first GNSS fix")

    def _now(self, header=None) -> float:  # noqa: ANN001
        """Measurement time: the message stamp (com3_bridge's clock) if set, else this node's clock."""
        if header is not None and (header.stamp.sec or header.stamp.nanosec):
            return header.stamp.sec + header.stamp.nanosec * 1e-9
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_fix(self, msg: NavSatFix) -> None:
        if msg.status.status < 0:
            return
        try:
            x, y, _ = self.projector.geodetic_to_map(msg.latitude, msg.longitude, msg.altitude)
        except ValueError as exc:
            self._log.warning(f"gnss/fix ignored: {exc}")
            return
        sigma = None
        if msg.position_covariance_type > 0:
            sigma = math.sqrt(max(msg.position_covariance[0], msg.position_covariance[4], 0.0)) or None
        first = not self.ekf.initialised
        result = self.ekf.gnss(self._now(msg.header), x, y, sigma)
        if first:
            self._log.info(f"initialised on GNSS at ({x:.2f}, {y:.2f})")
        if not result.accepted and self.ekf.stats.gnss_rejected - self._rejected_logged >= 10:
            self._rejected_logged = self.ekf.stats.gnss_rejected
            self._log.warning(
                f"GNSS outlier rejected (Mahalanobis^2 {result.mahalanobis2:.1f}); {self.ekf.stats.gnss_rejected} so far"
            )

    def _on_imu(self, msg: Imu) -> None:
        if not self.use_azimuth:
            return
        q = msg.orientation
        if q.x == q.y == q.z == q.w == 0.0 or msg.orientation_covariance[0] < 0:
            return
        sigma = math.sqrt(msg.orientation_covariance[8]) if msg.orientation_covariance[8] > 0 else None
        try:
            self.ekf.azimuth(self._now(msg.header), yaw_from_quaternion(q), sigma)
        except ValueError as exc:
            self._log.warning(f"imu ignored: {exc}")

    def _on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose
        try:
            self.ekf.odometry(self._now(msg.header), p.position.x, p.position.y, yaw_from_quaternion(p.orientation))
        except ValueError as exc:
            self._log.warning(f"odom_pose ignored: {exc}")
            return
        if not self.ekf.initialised:
            return
        # stamped with the odometry's measurement time, so consumers can align it with other data
        stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) else self.get_clock().now().to_msg()
        x, y, yaw = self.ekf.pose
        cov = self.ekf.cov
        out = Odometry()
        out.header.stamp = stamp
        out.header.frame_id = self.map_frame
        out.child_frame_id = self.base_frame
        out.pose.pose.position.x, out.pose.pose.position.y = x, y
        out.pose.pose.orientation.z, out.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        c = [0.0] * 36
        idx = (0, 1, 5)  # x, y, yaw in the 6x6 (x y z roll pitch yaw)
        for i, a in enumerate(idx):
            for j, b in enumerate(idx):
                c[a * 6 + b] = float(cov[i, j])
        c[2 * 6 + 2] = c[3 * 6 + 3] = c[4 * 6 + 4] = 1e6  # not estimated (2-D filter)
        out.pose.covariance = c
        out.twist = msg.twist
        self.pub.publish(out)
        tx, ty, tyaw = self.ekf.map_to_odom()
        tf = TransformStamped()
        tf.header.stamp = stamp
        tf.header.frame_id = self.map_frame
        tf.child_frame_id = self.odom_frame
        tf.transform.translation.x, tf.transform.translation.y = tx, ty
        tf.transform.rotation.z, tf.transform.rotation.w = math.sin(tyaw / 2), math.cos(tyaw / 2)
        self.pub_tf.publish(tf)


def main() -> int:
    return run_node(Ic120Localization)
