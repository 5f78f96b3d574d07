"""``com3_bridge``: the ROS 2 <-> COM3 CAN converter of one machine (thin rclpy wrapper of BridgeCore).

Run in the machine's namespace, e.g. ``com3_bridge --ros-args -r __ns:=/<name>`` for a machine ``<name>`` of the
site (``machines:`` of config/site.yaml). Parameters: ``machine`` (its name; default the last segment of the
namespace), ``can_config`` (YAML, default config/can/<kind>.yaml of its kind),
``can_interface`` / ``can_channel`` / ``can_port`` (override the YAML; empty/0 = keep; the link is chosen by
:func:`com3_can.bus.link_config`, in-process when the plant shares this process), ``watchdog_s``,
``joint_states_period_s``, ``odom_period_s`` and ``imu_period_s`` (publish ``joint_states`` / ``odom_pose`` /
``imu`` at most once per this period of the node clock; 0 = on every state frame: 100 Hz, ``imu`` 50 Hz; the
odometry is integrated on every frame either way, so a longer period drops samples, not accuracy).

Three threads touch the core (it locks): the executor (command callbacks send their frame at once),
a sender thread (cyclic frames at DBC cycle times, watchdog), and a receiver thread (state frames ->
``joint_states``, ``odom_pose``, ``imu``, ``gnss/fix``). ``diagnostic`` is published every
``diagnostic_period_s`` and at once when its level or message changes.

Command topics and types are OPERA com3_ros's (``com3_msgs``), per machine type: an excavator takes
``front_cmd`` and ``tracks_cmd`` (com3_msgs/JointCmd), ``machine_setting`` (ExcavatorCom3MachineSetting); a
crawler carrier takes ``track_cmd`` and ``rot_dump_cmd`` (com3_msgs/JointCmd; ``dump_joint`` POSITION = vessel
angle, ``rotate_joint`` POSITION = swing angle where it has a swing) and ``crawler_carrier_machine_setting``
(CrawlerCarrierCom3MachineSetting); a dozer takes ``track_cmd`` and ``blade_cmd`` (com3_msgs/JointCmd, ``lift_joint``
POSITION or VELOCITY; ours, OPERA has no public one); all take ``cmd_vel``
(geometry_msgs/Twist) and ``emg_stop`` (std_msgs/Bool).

Site watchdog (a machine PC cut off from the site, docs/deployment.md): ``site_heartbeat_topic`` (std_msgs/String,
e.g. the subtask servers' ``/tms_ts/subtask_heartbeat``; heartbeats whose data is this ``machine``) and
``site_timeout_s`` (> 0 with a topic): after the first heartbeat, none for ``site_timeout_s`` [s wall] while
the machine is driven (a non-neutral command) latches emg_stop and engages the pilot cut-off, as a received
emg_stop does; an explicit emg_stop ``false`` clears it.
Default: no topic, no site watchdog.

Pilot cut-off (:mod:`com3_can.pilot_cutoff`): ``lock`` (std_msgs/Bool, reliable) true engages the
hydraulic lock (``Pilot_Cutoff_Cmd`` = 1 at once, then every 100 ms), false releases it; a latched
``emg_stop`` engages it too. Motion commands are still accepted while locked (the machine ignores
them until the release); the emg_stop latch still refuses them.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import can
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu, JointState, NavSatFix, NavSatStatus
from std_msgs.msg import Bool, String

from com3_can.bridge_config import BridgeConfig
from com3_can.bridge_core import BridgeCore
from com3_can.bus import link_config, load_bus_config, open_bus
from com3_can.errors import Com3CommandError
from com3_can.outputs import FixOut, ImuOut, JointStateOut, OdomOut, Tx
from com3_can.pilot_cutoff import FRAME as CUTOFF_FRAME
from com3_can.pilot_cutoff import CutoffSender
from com3_can.profiles import PROFILES
from com3_msgs.msg import CrawlerCarrierCom3MachineSetting, ExcavatorCom3MachineSetting, JointCmd
from tms_common.errors import ConfigError
from tms_common.node import run_node
from tms_common.params import declare_startup
from tms_model.fleet import machine_name

__all__ = ["main", "Com3Bridge"]

SITE_CHECK_S = 0.02  # [s wall] site watchdog check period (with a site heartbeat topic only)


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


class Com3Bridge(Node):
    """ROS 2 <-> COM3 converter; see the module docstring for topics and parameters."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("com3_bridge", **kwargs)
        machine = machine_name(str(declare_startup(self, "machine", "").value), self.get_namespace())
        can_config = str(declare_startup(self, "can_config", "").value)
        interface = str(declare_startup(self, "can_interface", "").value)
        channel = str(declare_startup(self, "can_channel", "").value)
        port = int(declare_startup(self, "can_port", 0).value)
        watchdog = float(declare_startup(self, "watchdog_s", 0.5).value)
        site_topic = str(declare_startup(self, "site_heartbeat_topic", "").value)
        site_timeout = float(declare_startup(self, "site_timeout_s", 0.0).value)
        if bool(site_topic) != (site_timeout > 0):
            raise ConfigError(f"com3_bridge: site_heartbeat_topic {site_topic!r} and site_timeout_s {site_timeout:g} "
                              "go together: both set (a topic and > 0 s) or neither")
        # joint_states at most once per this period [s of the node clock] per joint set; 0 = every
        # state frame (100 Hz for the ZX200 front). Every subscriber pays per message.
        self._js_period = float(declare_startup(self, "joint_states_period_s", 0.0).value)
        if self._js_period < 0:
            raise ConfigError(f"com3_bridge: joint_states_period_s must be >= 0, got {self._js_period}")
        self._odom_period = float(declare_startup(self, "odom_period_s", 0.0).value)
        if self._odom_period < 0:
            raise ConfigError(f"com3_bridge: odom_period_s must be >= 0, got {self._odom_period}")
        self._imu_period = float(declare_startup(self, "imu_period_s", 0.0).value)
        if self._imu_period < 0:
            raise ConfigError(f"com3_bridge: imu_period_s must be >= 0, got {self._imu_period}")
        self._last_published: dict[Any, float] = {}
        cfg = load_bus_config(machine, can_config or None)
        self.config = BridgeConfig.load(machine, cfg, watchdog_s=watchdog, site_timeout_s=site_timeout)
        bus_cfg = link_config(machine, cfg, interface=interface, channel=channel, port=port)
        # the registry is consulted here, not by the core: the core runs the profile it is given
        profile = PROFILES.get(self.config.machine_type)(machine)
        self.core = BridgeCore(self.config, time.monotonic(), profile)
        self.bus = open_bus(bus_cfg)
        self._log = self.get_logger()
        self._log.info(f"{machine}: CAN {bus_cfg} watchdog {self.config.watchdog_s:g} s")
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._last_diag: tuple[int, str] | None = None
        self._last_diag_time = 0.0

        depth = 10
        reliable = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        self.pub_joints = self.create_publisher(JointState, "joint_states", depth)
        self.pub_odom = self.create_publisher(Odometry, "odom_pose", depth)
        self.pub_fix = self.create_publisher(NavSatFix, "gnss/fix", depth)
        self.pub_imu = self.create_publisher(Imu, "imu", depth)
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostic", depth)
        self.create_subscription(Bool, "emg_stop", self._on_emg, reliable)
        self.cutoff = CutoffSender()
        self._cutoff_lock = threading.Lock()
        self.create_subscription(Bool, "lock", self._on_lock, reliable)
        if site_topic:
            # best effort: a lost datagram must not hold the following heartbeats back for a reliable repair;
            # the check runs on this executor (BridgeCore.site_check) and on wall time: a cut-off PC gets no /clock
            self.create_subscription(String, site_topic, self._on_site_heartbeat, qos_profile_sensor_data)
            self.create_timer(SITE_CHECK_S, self._site_check, clock=Clock(clock_type=ClockType.STEADY_TIME))
        # the machine type's profile names the topics it takes (com3_ros's names for that type)
        self.create_subscription(JointCmd, profile.tracks_topic, self._on_tracks, depth)
        self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, depth)
        if "front_cmd" in self.core.topics:
            self.create_subscription(JointCmd, "front_cmd", self._on_front, depth)
            self.create_subscription(ExcavatorCom3MachineSetting, profile.setting_topic, self._on_zx_setting, depth)
        if "rot_dump_cmd" in self.core.topics:
            self.create_subscription(JointCmd, "rot_dump_cmd", self._on_rot_dump, depth)
            self.create_subscription(CrawlerCarrierCom3MachineSetting, profile.setting_topic, self._on_ic_setting,
                                     depth)
        if "blade_cmd" in self.core.topics:
            self.create_subscription(JointCmd, "blade_cmd", self._on_blade, depth)
        self.create_timer(0.05, self._diag_timer)
        self._threads = [
            threading.Thread(target=self._send_loop, name="com3_tx", daemon=True),
            threading.Thread(target=self._recv_loop, name="com3_rx", daemon=True),
        ]
        for t in self._threads:
            t.start()
        self._log.info("com3_bridge ready")

    # -------------------------------------------------------------- CAN side
    def _send(self, produce: Callable[[], list[Tx]]) -> None:
        """Compute the frames with ``produce()`` and put them on the bus, both under one lock. Computed outside
        it, a cyclic command frame the sender thread built just before an emg_stop latched reached the wire
        after the emg_stop's neutral frame (seen on a slow machine): the two threads' frames must leave in the
        order the core produced them."""
        with self._send_lock:
            for tx in produce():
                try:
                    self.bus.send(can.Message(arbitration_id=tx.arbitration_id, data=tx.data, is_extended_id=True))
                except can.CanError as exc:
                    self.core.counters["tx_error"] += 1
                    self._log.warning(f"CAN send of {tx.name} failed: {exc}", throttle_duration_sec=1.0)

    def _send_loop(self) -> None:
        while not self._stop.is_set():
            now = time.monotonic()
            self._send(lambda now=now: self.core.tick(now))
            with self._cutoff_lock:
                frame = self.cutoff.due(now)
            if frame is not None:
                self._send(lambda frame=frame: [Tx(CUTOFF_FRAME, self.cutoff.frame_id, frame)])
            wait = self.core.next_wake() - time.monotonic()
            if wait > 0:
                self._stop.wait(min(wait, 0.01))

    def _recv_loop(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(0.1)
            except (can.CanError, OSError, ValueError) as exc:  # a garbled datagram must not kill the loop
                self.core.counters["rx_garbage"] += 1
                self._log.warning(f"CAN receive error: {exc}", throttle_duration_sec=1.0)
                continue
            if msg is None:
                continue
            stamp = self.get_clock().now()
            outs = self.core.on_frame(
                msg.arbitration_id, bytes(msg.data), is_extended_id=msg.is_extended_id,
                is_error_frame=msg.is_error_frame, is_remote_frame=msg.is_remote_frame,
                stamp=stamp.nanoseconds * 1e-9,
            )
            try:
                for out in outs:
                    self._publish(out, stamp.to_msg())
            except Exception:
                if not self.context.ok():  # SIGINT shut the context down before destroy_node stopped us
                    return
                raise

    def _publish(self, out: Any, stamp: Any) -> None:
        if isinstance(out, JointStateOut):
            if self._too_soon(tuple(out.name), self._js_period, stamp):
                return
            js = JointState()
            js.header.stamp = stamp
            js.name, js.position, js.velocity = list(out.name), list(out.position), list(out.velocity)
            self.pub_joints.publish(js)
        elif isinstance(out, OdomOut):
            if self._too_soon(("odom", out.frame_id), self._odom_period, stamp):
                return
            od = Odometry()
            od.header.stamp = stamp
            od.header.frame_id = out.frame_id
            od.child_frame_id = "base_link"
            od.pose.pose.position.x, od.pose.pose.position.y, od.pose.pose.position.z = out.x, out.y, out.z
            q = quaternion(0.0, 0.0, out.yaw)
            o = od.pose.pose.orientation
            o.x, o.y, o.z, o.w = q
            od.twist.twist.linear.x, od.twist.twist.angular.z = out.v, out.yaw_rate
            self.pub_odom.publish(od)
        elif isinstance(out, ImuOut):
            if self._too_soon("imu", self._imu_period, stamp):
                return
            imu = Imu()
            imu.header.stamp = stamp
            imu.header.frame_id = "base_link"
            o = imu.orientation
            o.x, o.y, o.z, o.w = quaternion(out.roll, out.pitch, out.yaw)
            if out.yaw_rate is None:
                imu.angular_velocity_covariance[0] = -1.0  # not provided
            else:
                imu.angular_velocity.z = out.yaw_rate
            imu.linear_acceleration_covariance[0] = -1.0
            self.pub_imu.publish(imu)
        elif isinstance(out, FixOut):
            fix = NavSatFix()
            fix.header.stamp = stamp
            fix.header.frame_id = "gnss"
            fix.status.status = out.status
            fix.status.service = NavSatStatus.SERVICE_GPS
            fix.latitude, fix.longitude, fix.altitude = out.latitude, out.longitude, out.altitude
            if out.horizontal_accuracy is not None:
                var = out.horizontal_accuracy**2
                fix.position_covariance[0] = fix.position_covariance[4] = var
                fix.position_covariance[8] = 4 * var
                fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_APPROXIMATED
            self.pub_fix.publish(fix)

    def _too_soon(self, key: Any, period: float, stamp: Any) -> bool:
        """True when ``key`` was published less than ``period`` ago (then skip it); else record ``stamp``."""
        if period <= 0:
            return False
        t = stamp.sec + stamp.nanosec * 1e-9
        if t - self._last_published.get(key, -1e18) < period - 1e-6:
            return True
        self._last_published[key] = t
        return False

    # -------------------------------------------------------------- ROS commands
    def _command(self, fn: Any, *args: Any) -> None:
        try:
            self._send(lambda: fn(*args, time.monotonic()))
        except Com3CommandError as exc:
            self._log.warning(f"rejected: {exc}", throttle_duration_sec=0.5)

    def _on_front(self, msg: Any) -> None:
        self._command(self.core.front_cmd, list(msg.joint_name), msg.control_type, list(msg.velocity), list(msg.effort))

    def _on_tracks(self, msg: Any) -> None:
        self._command(
            self.core.tracks_cmd, list(msg.joint_name), msg.control_type, list(msg.velocity), list(msg.effort)
        )

    def _on_cmd_vel(self, msg: Any) -> None:
        self._command(self.core.cmd_vel, msg.linear.x, msg.angular.z)

    def _on_rot_dump(self, msg: Any) -> None:
        self._command(self.core.rot_dump_cmd, list(msg.joint_name), msg.control_type, list(msg.position))

    def _on_blade(self, msg: Any) -> None:
        self._command(self.core.blade_cmd, list(msg.joint_name), msg.control_type, list(msg.position),
                      list(msg.velocity))

    def _on_zx_setting(self, msg: Any) -> None:
        self._command(self.core.machine_setting, {
            "engine_rpm": msg.engine_rpm,
            # com3_msgs: false = power, true = eco; the DBC's value table: 1 "Power Mode", 0 "Eco Mode"
            "power_eco_mode": 0.0 if msg.power_eco_mode else 1.0,
            "travel_speed_mode": float(msg.travel_speed_mode),  # true = turtle = DBC 1
            "working_mode_notice": float(msg.working_mode_notice),
            "yellow_led_mode": float(msg.yellow_led_mode),
            "front_signal_switch_command": float(msg.front_control_mode),
            "travel_signal_switch_command": float(msg.tracks_control_mode),
        })

    def _on_ic_setting(self, msg: Any) -> None:
        if msg.swing_mode and self.config.swing_range is None:  # lever input for a rotating body it lacks (IC120)
            self._log.warning(f"rejected: {self.core.profile.setting_topic}: swing_mode true (lever input) but the "
                              f"{self.config.machine} has no rotating body", throttle_duration_sec=0.5)
            return
        self._command(self.core.machine_setting, {
            "operation_mode": float(msg.operation_mode),
            "velocity_mode": float(msg.velocity_mode),
            "dump_mode": float(msg.dump_mode),
            "swing_mode": float(msg.swing_mode),
            "eco_mode": float(msg.eco_mode),
            "speed_mode": float(msg.speed_mode),
        })

    def _set_cutoff(self, source: str, on: bool) -> None:
        with self._cutoff_lock:
            before = self.cutoff.engaged
            frame = self.cutoff.set(source, on, time.monotonic())
            after = self.cutoff.engaged
        if frame is not None:
            self._send(lambda: [Tx(CUTOFF_FRAME, self.cutoff.frame_id, frame)])
        if before != after:
            self._log.warning(f"pilot cut-off {'ENGAGED' if after else 'released'} ({source})")

    def _on_lock(self, msg: Any) -> None:
        self._set_cutoff("lock", bool(msg.data))

    def _on_site_heartbeat(self, msg: Any) -> None:
        if msg.data == self.config.machine:
            self.core.site_heartbeat(time.monotonic())

    def _site_check(self) -> None:
        self._send(lambda: self.core.site_check(time.monotonic()))
        if self.core.emg_latched and not self.cutoff.sources.get("emg_stop"):  # the site watchdog latched it
            self._log.error(f"{self.core.emg_reason}: emg_stop latched, neutral frames, pilot cut-off")
            self._set_cutoff("emg_stop", True)
            self._diag_timer(force=True)

    def _on_emg(self, msg: Any) -> None:
        was = self.core.emg_latched
        self._send(lambda: self.core.emg_stop(bool(msg.data), time.monotonic()))
        self._set_cutoff("emg_stop", self.core.emg_latched)
        if was != self.core.emg_latched:
            self._log.warning("emg_stop latched: neutral frames" if msg.data else "emg_stop cleared")
        self._diag_timer(force=True)

    # -------------------------------------------------------------- diagnostics
    def _diag_timer(self, force: bool = False) -> None:
        now = time.monotonic()
        snap = self.core.diagnostics(now)
        key = (snap.level, snap.message.split(" for ")[0])
        if not force and key == self._last_diag and now - self._last_diag_time < self.config.diagnostic_period_s:
            return
        self._last_diag, self._last_diag_time = key, now
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        st = DiagnosticStatus()
        st.level = bytes([snap.level])
        st.name = f"{self.get_namespace().rstrip('/')}/com3_bridge"
        st.hardware_id = self.config.machine
        st.message = snap.message
        st.values = [KeyValue(key=k, value=v) for k, v in snap.values]
        arr.status = [st]
        self.pub_diag.publish(arr)

    def destroy_node(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=1.0)
        try:
            self.bus.shutdown()
        finally:
            super().destroy_node()


def main() -> int:
    """Console script ``com3_bridge``."""
    return run_node(Com3Bridge)


if __name__ == "__main__":
    raise SystemExit(main())
