"""``tracked_localization``: localisation of a tracked machine (thin rclpy wrapper of TrackedEkf / GlobalPoseRelay).

Run in the machine's namespace: ``tracked_localization --ros-args -r __ns:=/ic120_1`` (the machine is the
``machine`` parameter, else the namespace's last segment; ``ic120_localization`` is this node under its
former name). Its description (``tms_model.fleet.load_named``) names its frames and its kind's
nav file configures it (:mod:`tms_rp.tracked.config`).

Odometry in frame ``odom`` (a crawler carrier's converter integrates the track speeds) is fused by the EKF.
Subscribes ``odom_pose`` (nav_msgs/Odometry, frame odom), ``gnss/fix`` (sensor_msgs/NavSatFix) and ``imu``
(sensor_msgs/Imu, orientation yaw = azimuth, ENU). Publishes ``odometry/global`` (nav_msgs/Odometry,
frame ``map``, child ``base_link``, pose covariance of x, y, yaw; twist copied from odometry; stamped with
the odometry message's stamp) on every odometry message once a GNSS fix arrived, and ``map_to_odom``
(geometry_msgs/TransformStamped, the REP-105
map -> odom correction, which ``tms_sp_tf`` puts on /tf).

An ``odom_pose`` already in frame ``map`` (an excavator's converter: RTK GNSS at the swing centre) needs no
filter: it is passed through to ``odometry/global`` with the body velocity estimated from the poses of the
last ``velocity_window_s`` (:class:`tms_rp.tracked.rtk.GlobalPoseRelay`); ``map_to_odom`` is not published
(map = odom for such a machine; ``tms_sp_tf`` takes the identity from the pose's frame). From the first such
pose on, ``gnss/fix`` and ``imu`` are not filtered (the EKF, with no odometry to predict with, gated every azimuth of
a standing ZX200 against a heading it never updated: thousands of warnings).

Parameters: ``machine`` (name on the site; default: the namespace), ``nav_config`` (YAML, default
config/nav/<kind>_nav.yaml over config/nav/tracked_nav.yaml), ``site_config`` (default config/site.yaml),
``use_azimuth`` (true), ``base_frame`` / ``odom_frame`` (default: the machine's /tf frames, e.g.
``ic120_1_tf/base_link`` / ``ic120_1_tf/odom``) / ``map_frame``, ``velocity_window_s`` (1.0).
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
from tms_model.fleet import machine_name
from tms_model.geometry import yaw_from_quaternion
from tms_model.site import Projector, load_site
from tms_rp.tracked.config import load_nav_config
from tms_rp.tracked.ekf import TrackedEkf
from tms_rp.tracked.rtk import GlobalPoseRelay

__all__ = ["main", "TrackedLocalization"]


class TrackedLocalization(Node):
    def __init__(self, node_name: str = "tracked_localization", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.machine = machine_name(str(declare_startup(self, "machine", "").value), self.get_namespace())
        nav_config = str(declare_startup(self, "nav_config", "").value)
        site_config = str(declare_startup(self, "site_config", "").value)
        self.use_azimuth = bool(declare_startup(self, "use_azimuth", True).value)
        window = float(declare_startup(self, "velocity_window_s", 1.0).value)
        cfg = load_nav_config(nav_config or None, machine=self.machine)
        machine = cfg.machine
        self.base_frame = str(declare_startup(self, "base_frame", machine.frame("base_link")).value)
        self.odom_frame = str(declare_startup(self, "odom_frame", machine.frame("odom")).value)
        self.map_frame = str(declare_startup(self, "map_frame", "map").value)
        site = load_site(site_config or None)
        self.projector = Projector(site.crs, site.origin_plane, cfg.geodetic_crs)
        self.ekf = TrackedEkf(cfg.ekf)
        self.relay = GlobalPoseRelay(window)
        self._pose_sigma = (cfg.ekf.gnss_sigma, cfg.ekf.azimuth_sigma)
        self._log = self.get_logger()
        self.pub = self.create_publisher(Odometry, "odometry/global", 10)
        self.pub_tf = self.create_publisher(TransformStamped, "map_to_odom", 10)
        self.create_subscription(Odometry, "odom_pose", self._on_odom, 50)
        self.create_subscription(NavSatFix, "gnss/fix", self._on_fix, 50)
        self.create_subscription(Imu, "imu", self._on_imu, 50)
        self._rejected_logged = 0
        # an odom_pose in map has come: the pose is passed through, and the EKF (no odometry to predict with) would
        # only gate the azimuth and fixes against a heading it never updates
        self._relaying = False
        self._yaw_rejected_logged = 0
        self._log.info(f"{self.machine} ({machine.kind}): EKF ready ({cfg.file}); waiting for the first GNSS fix "
                       f"(or an odom_pose in frame {self.map_frame!r}, passed through)")

    def _now(self, header=None) -> float:
        """Measurement time: the message stamp (com3_bridge's clock) if set, else this node's clock."""
        if header is not None and (header.stamp.sec or header.stamp.nanosec):
            return header.stamp.sec + header.stamp.nanosec * 1e-9
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_fix(self, msg: NavSatFix) -> None:
        if msg.status.status < 0 or self._relaying:
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
                f"GNSS outlier rejected (Mahalanobis^2 {result.mahalanobis2:.1f}); "
                f"{self.ekf.stats.gnss_rejected} so far"
            )

    def _on_imu(self, msg: Imu) -> None:
        if not self.use_azimuth or self._relaying:
            return
        q = msg.orientation
        if q.x == q.y == q.z == q.w == 0.0 or msg.orientation_covariance[0] < 0:
            return
        sigma = math.sqrt(msg.orientation_covariance[8]) if msg.orientation_covariance[8] > 0 else None
        try:
            result = self.ekf.azimuth(self._now(msg.header), yaw_from_quaternion(q), sigma)
        except ValueError as exc:
            self._log.warning(f"imu ignored: {exc}")
            return
        if not result.accepted and self.ekf.stats.yaw_rejected - self._yaw_rejected_logged >= 20:
            self._yaw_rejected_logged = self.ekf.stats.yaw_rejected
            self._log.warning(f"azimuth rejected (Mahalanobis^2 {result.mahalanobis2:.1f}, estimate "
                              f"{math.degrees(self.ekf.pose[2]):.1f} deg); {self.ekf.stats.yaw_rejected} so far")

    def _on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose
        if msg.header.frame_id == self.map_frame:
            if not self._relaying:
                self._relaying = True
                self._log.info(f"odom_pose in frame {self.map_frame!r}: passed through (the EKF, its GNSS fixes "
                               "and azimuths unused)")
            self._relay(msg)
            return
        try:
            self.ekf.odometry(self._now(msg.header), p.position.x, p.position.y, yaw_from_quaternion(p.orientation))
        except ValueError as exc:
            self._log.warning(f"odom_pose ignored: {exc}")
            return
        if not self.ekf.initialised:
            return
        # stamped with the odometry's measurement time, so consumers can align it with other data
        stamp = (
            msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) else self.get_clock().now().to_msg()
        )
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


    def _relay(self, msg: Odometry) -> None:
        """A pose already in the map frame: passed through, with the body velocity of the last poses."""
        p = msg.pose.pose
        yaw = yaw_from_quaternion(p.orientation)
        try:
            v, w = self.relay.update(self._now(msg.header), p.position.x, p.position.y, yaw)
        except ValueError as exc:
            self._log.warning(f"odom_pose ignored: {exc}")
            return
        out = Odometry()
        out.header.stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) \
            else self.get_clock().now().to_msg()
        out.header.frame_id = self.map_frame
        out.child_frame_id = self.base_frame
        out.pose.pose = p
        c = [0.0] * 36
        sxy, syaw = self._pose_sigma
        c[0] = c[7] = sxy * sxy
        c[35] = syaw * syaw
        c[14] = c[21] = c[28] = 1e6  # not estimated (2-D)
        out.pose.covariance = c
        out.twist.twist.linear.x, out.twist.twist.angular.z = v, w
        self.pub.publish(out)


def main() -> int:
    return run_node(TrackedLocalization)
