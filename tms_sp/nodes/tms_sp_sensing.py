"""Node ``tms_sp_sensing``: simulated sensors of the site -> dynamic DB parameters and SENSING_* flags.

Machines are known by their site names (config/site.yaml ``machines``): the excavator (parameter ``excavator``,
"" = the sensing YAML's) and the carriers it loads (parameter ``carriers``, [] = the sensing YAML's); their
facts come from their kinds' descriptions (:mod:`tms_sp.config`). Subscribes (topics by name; defaults below):

* ``/sim/sensors/mound/points`` (sensor_msgs/PointCloud2, x/y/z FLOAT32, frame ``map``): LiDAR-like
  samples of the mound surface (points outside the mound's region are ignored);
* ``/sim/sensors/<carrier>/vessel_points`` (sensor_msgs/PointCloud2, frame ``<carrier>/vessel``: origin at the
  vessel floor centre, x forward, z up, vessel lowered): samples of the load surface, floor = 0;
* ``/sim/truth/<carrier>/pose`` and ``/sim/truth/<excavator>/pose`` (geometry_msgs/PoseStamped, map): the
  machines' measured poses (a site camera / total station stands in for them in simulation).

Clouds are processed at ``rate_hz`` (latest one of each wins); results go to the DB through
:class:`tms_sp.processor.SiteSensing` and a summary is published on ``/tms_sp/status``
(diagnostic_msgs/DiagnosticArray, one status ``tms_sp/site`` with key/values: mound_volume_m3,
mound_in_reach_m3, vessel_volume_m3, vessel_fill, the three flags, target_x/y/z/theta_w).

Parameters: ``db_uri``, ``db_path`` (contract [C]), ``config`` (sensing YAML, default
config/tms_sp/sensing.yaml), ``site`` (site YAML, default config/site.yaml), ``excavator``, ``carriers``,
``rate_hz`` (2.0), ``mound_topic``; with one carrier ``vessel_topic``, ``carrier_pose_topic`` and
``excavator_pose_topic`` ("" = by name, as above); ``blackboard_records`` ([] = the sensing YAML's: every
global-blackboard record the running tasks read the SENSING_* flags from; the first one is also read, for
``holder_field``), ``approach_record`` ("-" = the sensing YAML's, "" = none: the original's trees have no approach
record), ``target_fill`` (0.0 = the sensing YAML's ``vessel.target_fill``: the fill fraction at which a vessel
counts as loaded; the fleet loads part of each vessel so that its three rounds fit the one mound).

Several carriers (the fleet experiment): the carrier sensed is the one named in field ``holder_field``
(``LOADAREA_MACHINE``) of the global-blackboard record: the carrier that claimed the loading point
(:meth:`tms_sp.processor.SiteSensing.follow_holder`); its vessel geometry is its kind's.
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
from tms_db import StoreOwner, declare_and_open
from tms_model.geometry import Pose2D, yaw_from_quaternion
from tms_sp.config import load_sensing_config
from tms_sp.errors import SensingError
from tms_sp.pointcloud import xyz_from_cloud
from tms_sp.processor import SiteSensing


def pose2d(msg: PoseStamped) -> Pose2D:
    p, q = msg.pose.position, msg.pose.orientation
    return Pose2D(p.x, p.y, yaw_from_quaternion(q), p.z)


class SensingNode(StoreOwner, Node):
    """Feeds SiteSensing from ROS topics; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_sp_sensing", **kwargs)
        self._log = self.get_logger()
        config = str(declare_startup(self, "config", "").value)
        site = str(declare_startup(self, "site", "").value)
        excavator = str(declare_startup(self, "excavator", "").value)
        carriers = [str(c) for c in declare_startup(self, "carriers", [""]).value if c]
        cfg = load_sensing_config(config or None, site or None, excavator=excavator, carriers=carriers)
        rate = float(declare_startup(self, "rate_hz", 2.0).value)
        if rate <= 0:
            raise ConfigError(f"tms_sp_sensing: parameter rate_hz must be > 0, got {rate}")
        mound_topic = str(declare_startup(self, "mound_topic", "/sim/sensors/mound/points").value)
        single = {k: str(declare_startup(self, k, "").value)
                  for k in ("vessel_topic", "carrier_pose_topic", "excavator_pose_topic")}
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
        self.carriers = list(cfg.carriers)
        self.holder_field = str(declare_startup(self, "holder_field", "LOADAREA_MACHINE").value)
        self.store = declare_and_open(self)
        self.sensing = SiteSensing(cfg, self.store)
        self.sensing.check_records()
        self._mound = None
        self._vessel: dict[str, Any] = {}
        self._mound_topic = mound_topic
        self.create_subscription(PointCloud2, mound_topic, lambda m: setattr(self, "_mound", m), 2)
        self._vessel_topics = {c: f"/sim/sensors/{c}/vessel_points" for c in self.carriers}
        pose_topics = {c: f"/sim/truth/{c}/pose" for c in self.carriers}
        if len(self.carriers) == 1:  # one carrier's topics may be remapped by parameter
            c = self.carriers[0]
            self._vessel_topics[c] = single["vessel_topic"] or self._vessel_topics[c]
            pose_topics[c] = single["carrier_pose_topic"] or pose_topics[c]
        excavator_pose_topic = single["excavator_pose_topic"] or f"/sim/truth/{cfg.excavator}/pose"
        for c in self.carriers:
            self.create_subscription(
                PointCloud2, self._vessel_topics[c], lambda m, c=c: self._vessel.__setitem__(c, m), 2
            )
            self.create_subscription(PoseStamped, pose_topics[c], lambda m, c=c: self._on_carrier(c, m), 10)
        self.create_subscription(PoseStamped, excavator_pose_topic,
                                 lambda m: self.sensing.on_excavator_pose(pose2d(m)), 10)
        self._status = self.create_publisher(DiagnosticArray, "/tms_sp/status", 10)
        self.create_timer(1.0 / rate, self._process)
        self._kv = (KeyValue, DiagnosticStatus, DiagnosticArray)
        self._log.info(f"sensing: excavator {cfg.excavator}, carriers {self.carriers}, flags to "
                       f"{', '.join(cfg.blackboard_records)}, topics {mound_topic}, {self._vessel_topics}, "
                       f"{pose_topics}, {excavator_pose_topic}, {rate:g} Hz")

    def _on_carrier(self, name: str, msg: PoseStamped) -> None:
        if name != self.sensing.carrier:
            return
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if t == 0.0:
            t = self.get_clock().now().nanoseconds * 1e-9
        self.sensing.on_carrier_pose(t, pose2d(msg))

    def _process(self) -> None:
        if len(self.carriers) > 1:
            self.sensing.follow_holder(self.holder_field, set(self.carriers))
        carrier = self.sensing.carrier
        vessel = self._vessel.pop(carrier, None)
        mound, self._mound = self._mound, None
        for msg, topic, handler in (
            (mound, self._mound_topic, self.sensing.on_mound_points),
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


def main() -> int:
    return run_node(SensingNode)


if __name__ == "__main__":
    sys.exit(main())
