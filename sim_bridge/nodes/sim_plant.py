"""Node ``sim_plant``: the MuJoCo plant on COM3 CAN, publishing ``/clock`` and ``/sim/truth``.

The plant loop runs in its own thread (paced to ``speed`` x real time, or free-running with
``speed:=0``); the executor only serves parameters. Control goes *only* through the CAN buses of
``config/can/<machine>.yaml`` (overridable per machine: ``<m>_can_interface``, ``<m>_can_channel``,
``<m>_can_port``; in the composed layout's plant container the in-process link of
:func:`com3_can.bus.link_config`). Published (simulated time stamps, frame ``map``):

* ``/clock`` (rosgraph_msgs/Clock) every step,
* ``/sim/truth/<machine>/pose`` (geometry_msgs/PoseStamped), ``/sim/truth/<machine>/joint_states``
  (sensor_msgs/JointState) for every machine by name, ``/sim/truth/<excavator>/bucket_tip``
  (geometry_msgs/PointStamped) of the digging excavator (the paper's ZX200),
* ``/sim/truth/soil`` (std_msgs/Float64MultiArray ``[mound, bucket, vessel, dumped, total_error, ground]`` m^3,
  labels in ``layout.dim[0].label``), every ``truth_period_s``,
* ``/sim/truth/<carrier>/soil`` (std_msgs/Float64MultiArray ``[vessel, loaded, dumped]`` m^3, labels in
  ``layout.dim[0].label``) for every crawler carrier by name: its load now and the totals that landed in its
  vessel and that it dumped, every ``truth_period_s``,
* ``/sim/truth/<excavator>/hydraulics`` (std_msgs/Float64MultiArray, MPa, labels :data:`HYDRAULICS_LABELS` in
  ``layout.dim[0].label``) of the digging excavator: each cylinder's bottom (cap) and rod chamber, the swing motor's
  ports A and B, the pump and the cylinders' relief setting, every ``truth_period_s``,
* ``/sim/sensors/mound/points`` (sensor_msgs/PointCloud2, ``map``) and ``/sim/sensors/<carrier>/vessel_points``
  (PointCloud2, ``<carrier>/vessel``) for every crawler carrier by name: LiDAR-like soil scans for tms_sp
  (:mod:`sim_bridge.scanners`), every ``scan_period_s`` of
  simulated time (0.5 s; the mound's every ``mound_scan_period_s``, default the same), noise ``scan_noise_m``
  (0.02 m),
* ``/sim/sensors/region/points`` (PointCloud2, ``map``) when ``region_scan`` names a rectangle ``[x_min, y_min,
  x_max, y_max]`` (default ``[0, 0, 0, 0]``: none): the ground over it on a ``region_scan_spacing`` grid (0.05 m),
  read from the fine patch where there is one (:func:`sim_bridge.scanners.region_scan`; a design's work area,
  ``config/launch/design_trench.yaml``), every ``region_scan_period_s`` (0: the mound scan's period),
* ``/sim/diagnostics`` (diagnostic_msgs/DiagnosticArray): frame counters per machine (received, sent,
  ignored_out_of_range, ignored_bad_dlc, ignored_unknown_id, watchdog_trips) and the real-time factor.

``heights_npz`` (a path, default none): at the node's end the plant's true height field is written there
(``numpy.savez``: the coarse grid ``h``, ``x0``, ``y0``, ``res`` and, with a fine patch, ``fine_h``, ``fine_x0``,
``fine_y0``, ``fine_res``; rows = y from south, cols = x from west), the truth a run's surface is judged on.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering without a display (before mujoco loads)

import math
import threading
from pathlib import Path
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointCloud2, PointField
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from com3_can.bus import link_config, load_bus_config, open_bus
from sim_bridge.can_io import PlantCanIO
from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.plant import Plant, stamp_parts
from sim_bridge.render import render_png
from sim_bridge.runner import PlantRunner, TruthLog, TruthRecorder
from sim_bridge.scanners import ScanRegion, mound_scan, pack_xyz, region_scan, vessel_scan
from tms_common.node import realtime_thread, run_node
from tms_common.params import startup_parameters

SOIL_LABELS = "mound,bucket,vessel,dumped,total_error,ground"
HYDRAULICS_LABELS = ("boom_bottom,boom_rod,arm_bottom,arm_rod,bucket_bottom,bucket_rod,swing_a,swing_b,pump,"
                     "relief")
_HYDRAULICS_N = len(HYDRAULICS_LABELS.split(","))
#: front joint -> its (extending, retracting) side's labels; the extending side is the cylinder's bottom (cap)
_HYDRAULICS_SIDES = {"boom_joint": ("boom_bottom", "boom_rod"), "arm_joint": ("arm_bottom", "arm_rod"),
                     "bucket_joint": ("bucket_bottom", "bucket_rod"), "swing_joint": ("swing_a", "swing_b")}


class SimPlantNode(Node):
    """Owns the plant, its buses and the loop thread; publishes clock, truth and diagnostics."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("sim_plant", **kwargs)
        p = startup_parameters(self)
        speed = float(p("speed", 1.0).value)
        catch_up = float(p("catch_up_s", 0.0).value)
        config = str(p("config", "").value) or None
        watchdog = float(p("watchdog_s", -1.0).value)
        self._truth_period = float(p("truth_period_s", 0.05).value)
        # /clock every step by default; a longer period (a multiple of the step) saves every
        # use_sim_time node one callback per step (13 Python processes on 2 cores: this dominated).
        self._clock_period = float(p("clock_period_s", 0.0).value)
        self._next_clock = 0.0
        record = str(p("record", "").value)
        replay = str(p("replay", "").value)
        self._snapshot = str(p("snapshot_png", "").value)
        status_period = float(p("status_period_s", 1.0).value)
        self._rt_priority = int(p("realtime_priority", 0).value)
        spec = load_plant(config)
        self.plant = Plant(spec)
        buses = {}
        for machine in self.plant.machines:
            cfg = link_config(machine, load_bus_config(machine), interface=str(p(f"{machine}_can_interface", "").value),
                              channel=str(p(f"{machine}_can_channel", "").value),
                              port=int(p(f"{machine}_can_port", 0).value))
            buses[machine] = open_bus(cfg)
            self.get_logger().info(f"{machine}: CAN {cfg}")
        self.buses = buses
        self.io = PlantCanIO(self.plant, buses, watchdog_s=watchdog if watchdog > 0 else spec.watchdog_s)
        self.recorder = TruthRecorder(record, self._truth_period) if record else None
        log = TruthLog(replay) if replay else None
        self.runner = PlantRunner(self.plant, self.io, speed=speed, on_step=self._on_step, replay=log,
                                  catch_up_s=catch_up)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.pose_pub = {m: self.create_publisher(PoseStamped, f"/sim/truth/{m}/pose", 10) for m in self.plant.machines}
        self.joint_pub = {
            m: self.create_publisher(JointState, f"/sim/truth/{m}/joint_states", 10) for m in self.plant.machines
        }
        digger = spec.excavator  # the excavator digging the soil; none in a plant without the soil experiment
        self.tip_pub = self.create_publisher(PointStamped, f"/sim/truth/{digger}/bucket_tip", 10) if digger else None
        self.soil_pub = self.create_publisher(Float64MultiArray, "/sim/truth/soil", 10)
        self.hyd_pub = self._hydraulics_index = None
        if self.plant.excavator is not None:
            front = self.plant.excavator.front
            missing = [j for j in _HYDRAULICS_SIDES if j not in front.names]
            if missing:
                raise SimConfigError(f"sim_plant: excavator {digger}'s front has no {', '.join(missing)} "
                                     f"(has {', '.join(front.names)}): /sim/truth/{digger}/hydraulics needs them")
            # label -> (front function index, extending side?), in the order of HYDRAULICS_LABELS
            where = {label: (front.names.index(j), k == 0)
                     for j, pair in _HYDRAULICS_SIDES.items() for k, label in enumerate(pair)}
            self._hydraulics_index = [where[label] for label in HYDRAULICS_LABELS.split(",")[:8]]
            self._relief_mpa = front.relief[front.names.index("boom_joint")] * 1e-6
            self.hyd_pub = self.create_publisher(Float64MultiArray, f"/sim/truth/{digger}/hydraulics", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/sim/diagnostics", 10)
        self._scan_period = float(p("scan_period_s", 0.5).value)
        # The mound changes only where the bucket cuts, and its cloud (~40k points) and assessment are the costly
        # scan: a site with several carriers scans it less often than their vessels (config/launch/fleet.yaml).
        self._mound_scan_period = float(p("mound_scan_period_s", 0.0).value) or self._scan_period
        if self._scan_period < 0 or self._mound_scan_period < 0:
            raise SimConfigError(f"sim_plant: scan_period_s / mound_scan_period_s must be >= 0, got "
                              f"{self._scan_period} / {self._mound_scan_period}")
        self._scan_noise = float(p("scan_noise_m", 0.02).value)
        self._next_scan = self._next_mound_scan = 0.0
        self._scan_rng = np.random.default_rng(spec.sensors.seed + 1)
        self.mound_pub = self.create_publisher(PointCloud2, "/sim/sensors/mound/points", 2)
        self._region, self._region_period = self._region_parameters(p)
        self._next_region_scan = 0.0
        self.region_pub = (self.create_publisher(PointCloud2, "/sim/sensors/region/points", 2)
                           if self._region is not None else None)
        self._heights_npz = str(p("heights_npz", "").value)
        self.vessel_pub = {m: self.create_publisher(PointCloud2, f"/sim/sensors/{m}/vessel_points", 2)
                           for m in self.plant.carriers}
        self.carrier_soil_pub = {m: self.create_publisher(Float64MultiArray, f"/sim/truth/{m}/soil", 10)
                                 for m in self.plant.carriers}
        self._next_truth = 0.0
        self._status_period = status_period
        self._next_status = 0.0
        self._thread = threading.Thread(target=self._loop, name="plant_loop", daemon=True)
        self._thread.start()
        mode = f"replay of {replay}" if replay else "commands from CAN"
        self.get_logger().info(
            f"sim_plant: running at speed {speed} ({'free-running' if speed == 0 else 'paced'}), {mode}"
        )

    @staticmethod
    def _region_parameters(p) -> tuple[ScanRegion | None, float]:
        """``region_scan`` (all zero: none), its spacing and period; SimConfigError naming the parameter."""
        box = [float(v) for v in p("region_scan", [0.0, 0.0, 0.0, 0.0]).value]
        spacing = float(p("region_scan_spacing", 0.05).value)
        period = float(p("region_scan_period_s", 0.0).value)
        if len(box) != 4:
            raise SimConfigError(f"sim_plant: parameter region_scan: [x_min, y_min, x_max, y_max], got {box}")
        if not any(box):
            return None, 0.0
        region = ScanRegion(*box, spacing)
        problem = region.problem()
        if problem is not None:
            raise SimConfigError(f"sim_plant: parameters region_scan / region_scan_spacing: {problem}")
        if period < 0:
            raise SimConfigError(f"sim_plant: parameter region_scan_period_s must be >= 0, got {period}")
        return region, period

    def _loop(self) -> None:
        realtime_thread(self._rt_priority, "sim_plant loop", self.get_logger())  # the loop thread only
        try:
            self.runner.run()
        except Exception as exc:  # noqa: BLE001 - report, then let the process die visibly
            if not self.context.ok():  # shutting down: publishers are gone, nothing to report
                return
            self.get_logger().fatal(f"plant loop crashed: {type(exc).__name__}: {exc}")
            os._exit(1)

    def _stamp(self, t: float):
        sec, nanosec = stamp_parts(t)
        return Time(sec=sec, nanosec=nanosec)

    def _on_step(self, plant: Plant) -> None:
        stamp = self._stamp(plant.time)
        if plant.time + 1e-9 >= self._next_clock:
            self._next_clock = max(self._next_clock + self._clock_period, plant.time) if self._clock_period > 0 else 0.0
            self.clock_pub.publish(Clock(clock=stamp))
        if self.recorder is not None:
            self.recorder(plant)
        if plant.time + 1e-9 >= self._next_truth:
            self._next_truth += self._truth_period
            self._publish_truth(plant, stamp)
        if self._mound_scan_period > 0 and plant.time + 1e-9 >= self._next_mound_scan:
            self._next_mound_scan += self._mound_scan_period
            self._publish_mound_scan(plant, stamp)
        if self._region is not None and plant.time + 1e-9 >= self._next_region_scan:
            self._next_region_scan += self._region_period or self._mound_scan_period or 1.0
            pts = region_scan(plant.ground, self._region, noise=self._scan_noise, rng=self._scan_rng)
            self.region_pub.publish(self._cloud(pts, "map", stamp))
        if self._scan_period > 0 and plant.time + 1e-9 >= self._next_scan:
            self._next_scan += self._scan_period
            self._publish_vessel_scans(plant, stamp)
        if plant.time + 1e-9 >= self._next_status:
            self._next_status += self._status_period
            self._publish_status(plant, stamp)

    def _publish_truth(self, plant: Plant, stamp) -> None:
        for m in plant.machines:
            t = plant.truth(m)
            msg = PoseStamped()
            msg.header.stamp, msg.header.frame_id = stamp, "map"
            msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = t.x, t.y, t.z
            msg.pose.orientation.z, msg.pose.orientation.w = math.sin(t.yaw / 2), math.cos(t.yaw / 2)
            self.pose_pub[m].publish(msg)
            bank = plant.machines[m].bank
            js = JointState()
            js.header.stamp = stamp
            js.name, js.position, js.velocity = list(bank.names), list(bank.q), list(bank.v)
            self.joint_pub[m].publish(js)
        if self.tip_pub is not None:
            pt = PointStamped()
            pt.header.stamp, pt.header.frame_id = stamp, "map"
            pt.point.x, pt.point.y, pt.point.z = plant.bucket_tip()
            self.tip_pub.publish(pt)
        soil = Float64MultiArray()
        soil.layout.dim = [MultiArrayDimension(label=SOIL_LABELS, size=6, stride=6)]
        error = plant.total_volume() - plant.initial_volume
        soil.data = [plant.ground.mound_volume(), plant.soil.bucket, plant.soil.vessel, plant.soil.dumped, error,
                     plant.ground.ground_soil_volume()]
        self.soil_pub.publish(soil)
        if self.hyd_pub is not None:
            front = plant.excavator.front
            hyd = Float64MultiArray()
            hyd.layout.dim = [MultiArrayDimension(label=HYDRAULICS_LABELS, size=_HYDRAULICS_N, stride=_HYDRAULICS_N)]
            hyd.data = [(front.p_ext[i] if ext else front.p_ret[i]) * 1e-6 for i, ext in self._hydraulics_index] + [
                front.pump_pressure * 1e-6, self._relief_mpa]
            self.hyd_pub.publish(hyd)
        for m, pub in self.carrier_soil_pub.items():
            msg = Float64MultiArray()
            msg.layout.dim = [MultiArrayDimension(label="vessel,loaded,dumped", size=3, stride=3)]
            msg.data = [
                plant.soil.vessels.get(m, 0.0),
                plant.soil.loaded_by.get(m, 0.0),
                plant.soil.dumped_by.get(m, 0.0),
            ]
            pub.publish(msg)

    def _cloud(self, points, frame: str, stamp):
        msg = PointCloud2()
        msg.header.stamp, msg.header.frame_id = stamp, frame
        data, n = pack_xyz(points)
        msg.height, msg.width = 1, n
        msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                      for i, c in enumerate("xyz")]
        msg.is_bigendian, msg.point_step, msg.row_step, msg.is_dense = False, 12, 12 * n, True
        msg.data = data
        return msg

    def _publish_mound_scan(self, plant: Plant, stamp) -> None:
        soil = plant.spec.soil
        pts = mound_scan(plant.ground, soil.mound_center, soil.mound_base_radius + 1.5, noise=self._scan_noise,
                         rng=self._scan_rng)
        self.mound_pub.publish(self._cloud(pts, "map", stamp))

    def _publish_vessel_scans(self, plant: Plant, stamp) -> None:
        for m, pub in self.vessel_pub.items():
            vessel = plant.carriers[m].vessel
            pts = vessel_scan(plant.soil.vessels[m], vessel.inner_length, vessel.inner_width, noise=self._scan_noise,
                              rng=self._scan_rng)
            pub.publish(self._cloud(pts, f"{m}/vessel", stamp))

    def _publish_status(self, plant: Plant, stamp) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = stamp
        for machine, counters in self.io.counters().items():
            st = DiagnosticStatus(name=f"sim_plant/{machine}", hardware_id=machine, message="ok")
            st.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(counters.items())]
            arr.status.append(st)
        arr.status.append(
            DiagnosticStatus(
                name="sim_plant/loop",
                message="ok",
                values=[KeyValue(key="sim_time", value=f"{plant.time:.3f}"),
                        KeyValue(key="late_steps", value=str(self.runner.late_steps))],
            )
        )
        self.diag_pub.publish(arr)

    def _write_heights(self, path: Path) -> None:
        g = self.plant.ground
        arrays = {"h": g.h, "x0": g.x0, "y0": g.y0, "res": g.res}
        if g.fine is not None:
            arrays.update(fine_h=g.fine.h, fine_x0=g.fine.x0, fine_y0=g.fine.y0, fine_res=g.fine.res)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(path, **arrays)
            self.get_logger().info(f"true height field written to {path}")
        except OSError as exc:
            self.get_logger().error(f"true height field not written to {path}: {exc}")

    def destroy_node(self) -> None:
        self.runner.stop()
        self._thread.join(timeout=5.0)
        if self.recorder is not None:
            self.recorder.close()
        if self._heights_npz:
            self._write_heights(Path(self._heights_npz))
        if self._snapshot:
            try:
                render_png(self.plant, Path(self._snapshot))
                self.get_logger().info(f"snapshot written to {self._snapshot}")
            except Exception as exc:  # noqa: BLE001 - rendering is optional
                self.get_logger().warning(f"no snapshot: {exc}")
        for bus in self.buses.values():
            bus.shutdown()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(SimPlantNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
