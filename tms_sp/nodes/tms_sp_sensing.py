"""Node ``tms_sp_sensing``: simulated sensors of the site -> dynamic DB parameters and SENSING_* flags.

Subscribes (all topics are parameters; defaults below):

* ``/sim/sensors/mound/points`` (sensor_msgs/PointCloud2, x/y/z FLOAT32, frame ``map``): LiDAR-like
  samples of the mound surface (points outside the mound's region are ignored);
* ``/sim/sensors/ic120/vessel_points`` (sensor_msgs/PointCloud2, frame ``ic120/vessel``: origin at the
  vessel floor centre, x forward, z up, vessel lowered): samples of the load surface, floor = 0;
* ``/sim/truth/ic120/pose`` and ``/sim/truth/zx200/pose`` (geometry_msgs/PoseStamped, map): the machines'
  measured poses (a site camera / total station stands in for them in simulation).

Clouds are processed at ``rate_hz`` (latest one of each wins); results go to the DB through
:class:`tms_sp.processor.SiteSensing` and a summary is published on ``/tms_sp/status``
(diagnostic_msgs/DiagnosticArray, one status ``tms_sp/site`` with key/values: mound_volume_m3,
mound_in_reach_m3, vessel_volume_m3, vessel_fill, the three flags, target_x/y/z/theta_w).

Parameters: ``db_uri``, ``db_path`` (contract [C]), ``config`` (sensing YAML, default
config/tms_sp/sensing.yaml), ``site``/``ic120``/``zx200`` (YAML paths, default config/...),
``rate_hz`` (2.0), ``mound_topic``, ``vessel_topic``, ``ic120_pose_topic``, ``zx200_pose_topic``,
``blackboard_records`` ([] = the sensing YAML's: every global-blackboard record the running tasks read the
SENSING_* flags from; the first one is also read, for ``holder_field``), ``approach_record`` ("-" = the sensing
YAML's, "" = none: the original's trees have no approach record), ``target_fill`` (0.0 = the sensing YAML's ``vessel.target_fill``:
the fill fraction at which a vessel counts as loaded; the fleet loads part of each vessel so that its three rounds
fit the one mound).

Several carriers (the fleet experiment): ``carriers`` (default ``[ic120]``) names the carriers on the site; with
more than one, each one's pose and vessel come from ``/sim/truth/<name>/pose`` and
``/sim/sensors/<name>/vessel_points`` (the single-carrier topics above are the paper's), and the carrier sensed is
the one named in field ``holder_field`` (``LOADAREA_MACHINE``) of the global-blackboard record: the carrier that
claimed the loading point (:meth:`tms_sp.processor.SiteSensing.follow_holder`); its vessel geometry is its kind's.
On start every record it writes must exist and be ``type: dynamic`` (seed first), else it exits 1
naming the record.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_db.nodes.common import declare_and_open
from tms_model.geometry import Pose2D, yaw_from_quaternion
from tms_sp.config import load_sensing_config
from tms_sp.errors import SensingError
from tms_sp.pointcloud import xyz_from_cloud
from tms_sp.processor import SiteSensing


def pose2d(msg: PoseStamped) -> Pose2D:
    p, q = msg.pose.position, msg.pose.orientation
    return Pose2D(p.x, p.y, yaw_from_quaternion(q), p.z)


class SensingNode(Node):
    """Feeds SiteSensing from ROS topics; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sp_sensing", **kwargs)
        self._log = self.get_logger()
        paths = {k: declare_startup(self, k, "").value for k in ("config", "site", "ic120", "zx200")}
        cfg = load_sensing_config(paths["config"] or None, paths["site"] or None, paths["ic120"] or None,
                                  paths["zx200"] or None)
        rate = float(declare_startup(self, "rate_hz", 2.0).value)
        if rate <= 0:
            raise ConfigError(f"tms_sp_sensing: parameter rate_hz must be > 0, got {rate}")
        topics = {
            "mound_topic": "/sim/sensors/mound/points",
            "vessel_topic": "/sim/sensors/ic120/vessel_points",
            "ic120_pose_topic": "/sim/truth/ic120/pose",
            "zx200_pose_topic": "/sim/truth/zx200/pose",
        }
        topics = {k: declare_startup(self, k, v).value for k, v in topics.items()}
        records = [str(r) for r in declare_startup(self, "blackboard_records", [""]).value if r]
        if records:
            if len(set(records)) != len(records):
                raise ConfigError(f"tms_sp_sensing: parameter blackboard_records names a record twice: {records}")
            cfg = dataclasses.replace(cfg, blackboard_records=tuple(records))
        approach = str(declare_startup(self, "approach_record", "-").value)
        if approach != "-":
            cfg = dataclasses.replace(cfg, approach_record=approach)
        fill = float(declare_startup(self, "target_fill", 0.0).value)
        if fill:
            try:
                cfg = dataclasses.replace(cfg, vessel=dataclasses.replace(cfg.vessel, target_fill=fill))
            except ValueError as exc:
                raise ConfigError(f"tms_sp_sensing: parameter target_fill: {exc}") from None
        self.carriers = [str(c) for c in declare_startup(self, "carriers", ["ic120"]).value]
        self.holder_field = str(declare_startup(self, "holder_field", "LOADAREA_MACHINE").value)
        if not self.carriers:
            raise ConfigError("tms_sp_sensing: parameter carriers must name at least one carrier")
        self.store = declare_and_open(self)
        self.sensing = SiteSensing(cfg, self.store, carrier=self.carriers[0])
        if len(self.carriers) > 1:
            from tms_sp.config import carrier_vessel_geometry

            self.sensing.vessels = {c: carrier_vessel_geometry(cfg, c) for c in self.carriers}
        self.sensing.check_records()
        self._mound = None
        self._vessel: dict[str, Any] = {}
        self._topics = topics
        self.create_subscription(PointCloud2, topics["mound_topic"], lambda m: setattr(self, "_mound", m), 2)
        if len(self.carriers) == 1:
            c = self.carriers[0]
            self._vessel_topics = {c: topics["vessel_topic"]}
            pose_topics = {c: topics["ic120_pose_topic"]}
        else:
            self._vessel_topics = {c: f"/sim/sensors/{c}/vessel_points" for c in self.carriers}
            pose_topics = {c: f"/sim/truth/{c}/pose" for c in self.carriers}
        for c in self.carriers:
            self.create_subscription(PointCloud2, self._vessel_topics[c], lambda m, c=c: self._vessel.__setitem__(c, m), 2)
            self.create_subscription(PoseStamped, pose_topics[c], lambda m, c=c: self._on_carrier(c, m), 10)
        self.create_subscription(PoseStamped, topics["zx200_pose_topic"],
                                 lambda m: self.sensing.on_zx200_pose(pose2d(m)), 10)
        self._status = self.create_publisher(DiagnosticArray, "/tms_sp/status", 10)
        self.create_timer(1.0 / rate, self._process)
        self._kv = (KeyValue, DiagnosticStatus, DiagnosticArray)
        self._log.info(f"sensing: flags to {', '.join(cfg.blackboard_records)}, topics {topics}, {rate:g} Hz")

    def _on_carrier(self, name: str, msg: PoseStamped) -> None:
        if name != self.sensing.carrier:
            return
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if t == 0.0:
            t = self.get_clock().now().nanoseconds * 1e-9
        self.sensing.on_ic120_pose(t, pose2d(msg))

    def _process(self) -> None:
        if len(self.carriers) > 1:
            self.sensing.follow_holder(self.holder_field, set(self.carriers))
        carrier = self.sensing.carrier
        vessel = self._vessel.pop(carrier, None)
        mound, self._mound = self._mound, None
        for msg, topic, handler in (
            (mound, self._topics["mound_topic"], self.sensing.on_mound_points),
            (vessel, self._vessel_topics[carrier], self.sensing.on_vessel_points),
        ):
            if msg is None:
                continue
            try:
                handler(xyz_from_cloud(msg, topic=topic))
            except SensingError as exc:
                self._log.warning(str(exc), throttle_duration_sec=5.0)
        self._publish_status()

    def _publish_status(self) -> None:
        key_value, status_t, array_t = self._kv
        s = self.sensing
        values = {f: str(v).lower() for f, v in s.flags.items()}
        values["carrier"] = s.carrier
        if s.mound is not None:
            values["mound_volume_m3"] = f"{s.mound.volume_total:.3f}"
            values["mound_in_reach_m3"] = f"{s.mound.volume_in_reach:.3f}"
            if s.mound.target is not None:
                t = s.mound.target
                values.update(target_x=f"{t.x:.3f}", target_y=f"{t.y:.3f}", target_z=f"{t.z:.3f}",
                              target_theta_w=f"{t.theta_w:.3f}")
        if s.vessel is not None:
            values["vessel_volume_m3"] = f"{s.vessel.volume:.3f}"
            values["vessel_fill"] = f"{s.vessel.fill:.3f}"
        st = status_t(level=status_t.OK, name="tms_sp/site", message="ok" if s.flags else "no sensor data yet",
                      hardware_id="tms_sp")
        st.values = [key_value(key=k, value=v) for k, v in sorted(values.items())]
        msg = array_t(status=[st])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._status.publish(msg)

    def destroy_node(self) -> None:
        try:
            self.store.close()
        finally:
            super().destroy_node()


def main() -> int:
    return run_node(SensingNode)


if __name__ == "__main__":
    sys.exit(main())
