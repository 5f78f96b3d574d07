"""SiteSensing: the sensing processors wired to the document store (no rclpy).

The node (:mod:`tms_sp.nodes.tms_sp_sensing`) feeds it sensor data; it runs the pure cores and writes what
changed through a tms_db store (``open_store``), as the original tms_sp updaters did:

* the excavation target -> ``(<excavator>, target_excavate_pose)`` (position_with_angle:1 + x,y,z,theta_w,offset,
  excavator base frame), skipped while the record's ``LOCK_FLG`` is true, rewritten only when it moved
  more than ``update_threshold``; with it ``(<excavator>, target_excavate_approach_pose)``, the same point
  ``approach_height`` higher (the paper tree returns the arm there after a release);
* the release target -> ``(<excavator>, target_release_pose)`` and the swing angle -> ``(<excavator>,
  release_angle)``, only while the sensed carrier stands at the loading point (elsewhere its vessel is not where
  the excavator releases);
* the flags SENSING_ARRIVAL_FLG, SENSING_LOADED_FLG, SENSING_CHECK_MOUND_FLG -> every global-blackboard
  record of ``blackboard_records`` (the records the running tasks read them from: the paper's trees name
  GLOBAL_BLACKBOARD_EARTHWORK, the original's 2024-12 trees SAMPLE_BLACKBOARD_SHIMIZU), written whenever a
  record holds another value than the assessment (also after a tree reset the flag). Meanings as the seed paper's Table
  7: SENSING_CHECK_MOUND_FLG is true
  when there is *not* enough soil in the mound (initially false).

``<excavator>`` is the configuration's excavator name (sensing.yaml ``excavator``).

Several carriers (the fleet experiment): the pose and vessel inputs are those of one carrier, ``carrier``
(default: the configuration's first carrier). :meth:`SiteSensing.follow_holder` reads the carrier's name from a field of
the
global-blackboard record (``LOADAREA_MACHINE``: the carrier that claimed the loading point writes it) and
:meth:`select_carrier` switches to it: a new arrival detector, that carrier's vessel geometry (``vessels``), and
the release target and SENSING_LOADED_FLG assessed afresh from its own vessel.

Every write goes through :class:`tms_sp.ingest.SensingWriter`, the rule by which the original's updaters
(and our ``tms_sp_ingest`` node, for an external sensing PC) write: only ``type: dynamic`` records, only
fields the seeded record has. :meth:`SiteSensing.check_records` raises :class:`SensingError` naming a
record that is missing or static.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tms_db import RecordNotFound
from tms_model.geometry import Pose2D
from tms_sp.arrival import ArrivalDetector
from tms_sp.config import SensingConfig
from tms_sp.heightgrid import rasterize
from tms_sp.ingest import SensingWriter
from tms_sp.mound import MoundAssessment, assess_mound
from tms_sp.vessel import VesselAssessment, VesselGeometry, assess_vessel, release_in_excavator

__all__ = ["SiteSensing", "FLAGS"]

log = logging.getLogger(__name__)
FLAGS = ("SENSING_ARRIVAL_FLG", "SENSING_LOADED_FLG", "SENSING_CHECK_MOUND_FLG")


@dataclass
class SiteSensing:
    """Runs the three processors and writes their results to ``store``."""

    cfg: SensingConfig
    store: Any
    carrier_pose: Pose2D | None = None
    excavator_pose: Pose2D | None = None
    mound: MoundAssessment | None = None
    vessel: VesselAssessment | None = None
    flags: dict[str, bool] = field(default_factory=dict)
    writes: int = 0
    _last_target: tuple[float, float, float] | None = None
    _last_target_xy: tuple[float, float] | None = None  # map frame, kept by assess_mound while it scores near the best
    _last_release: tuple[float, float, float] | None = None
    _release_spot: tuple[float, float] | None = None  # vessel frame x, y of the written release target
    _arrival: ArrivalDetector | None = None
    _writer: SensingWriter | None = None
    #: the carrier whose pose and vessel are sensed (the one at or coming to the loading point; "" = the
    #: configuration's first carrier)
    carrier: str = ""
    #: vessel geometry per carrier name (those of the configuration's carriers, and any selected since)
    vessels: dict[str, VesselGeometry] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.carrier = self.carrier or self.cfg.carriers[0]
        self.vessels = {**self.cfg.vessels, **self.vessels}
        self._arrival = ArrivalDetector(self.cfg.points[self.cfg.arrival_point], self.cfg.arrival)
        self._writer = SensingWriter(self.store)

    @property
    def vessel_geom(self) -> VesselGeometry:
        """The vessel geometry of the sensed carrier (its kind's)."""
        if self.carrier not in self.vessels:
            self.vessels[self.carrier] = self.cfg.vessel_geometry(self.carrier)
        return self.vessels[self.carrier]

    # ---- carriers ---------------------------------------------------------------------------------
    def select_carrier(self, name: str) -> bool:
        """Sense carrier ``name`` from now on; True when that is a change (its state is then started afresh)."""
        if name == self.carrier:
            return False
        log.info("sensing carrier %s (was %s)", name, self.carrier)
        self.carrier = name
        self.carrier_pose = None
        self.vessel = None
        self._arrival = ArrivalDetector(self.cfg.points[self.cfg.arrival_point], self.cfg.arrival)
        self._last_release = None
        self._release_spot = None
        self.flags["SENSING_LOADED_FLG"] = False  # hysteresis starts from this carrier's own vessel
        return True

    def follow_holder(self, field_name: str, known: set[str] | None = None) -> str:
        """Select the carrier named in ``field_name`` of the global-blackboard record (when it names one of
        ``known``, or any non-empty name when ``known`` is None); returns the sensed carrier."""
        try:
            name = self.store.get_record(self.cfg.blackboard_records[0]).get(field_name)
        except RecordNotFound:
            return self.carrier
        if isinstance(name, str) and name and (known is None or name in known):
            self.select_carrier(name)
        return self.carrier

    # ---- setup ------------------------------------------------------------------------------------
    def check_records(self) -> None:
        """Every record this processor writes exists and is dynamic; else SensingError naming it."""
        wanted = [(None, record) for record in self.cfg.blackboard_records] + [
            (self.cfg.excavator, self.cfg.excavation_record),
            (self.cfg.excavator, self.cfg.approach_record),
            (self.cfg.excavator, self.cfg.release_record),
            (self.cfg.excavator, self.cfg.angle_record),
        ]
        for model, record in wanted:
            if not record:  # an optional record switched off ("")
                continue
            self._writer.record(record, model)

    # ---- inputs -----------------------------------------------------------------------------------
    def on_carrier_pose(self, t: float, pose: Pose2D) -> bool:
        """Measured pose of the sensed carrier at time ``t`` [s] -> SENSING_ARRIVAL_FLG."""
        self.carrier_pose = pose
        arrived = self._arrival.update(t, pose)
        self._set_flag("SENSING_ARRIVAL_FLG", arrived)
        return arrived

    def on_excavator_pose(self, pose: Pose2D) -> None:
        """Measured excavator base pose (default: its ``excavator_base`` point of site.yaml)."""
        self.excavator_pose = pose

    @property
    def base(self) -> Pose2D:
        return self.excavator_pose or self.cfg.excavator_base

    def on_mound_points(self, points: np.ndarray) -> MoundAssessment:
        """Mound points (map frame) -> excavation target + SENSING_CHECK_MOUND_FLG (true: not enough soil)."""
        grid = rasterize(points, self.cfg.mound_grid, sensor="mound points")
        axis = self.base.to_map(np.array([*self.cfg.swing_axis_in_base, 0.0]))
        a = assess_mound(grid, (float(axis[0]), float(axis[1])), self.cfg.excavation, previous_xy=self._last_target_xy,
                         was_depleted=self.flags.get("SENSING_CHECK_MOUND_FLG") is True)
        self.mound = a
        if a.target is not None:
            fields = a.target.record_fields(self.base)
            xyz = (fields["x"], fields["y"], fields["z"])
            if self._moved(self._last_target, xyz, self.cfg.excavation_update_threshold):
                doc = self._writer.record(self.cfg.excavation_record, self.cfg.excavator)
                if doc.get("LOCK_FLG") is True:
                    log.debug("excavation target locked (LOCK_FLG): not updated")
                else:
                    self._writer.write(self.cfg.excavation_record, fields, model_name=self.cfg.excavator,
                                       strict=True)
                    if self.cfg.approach_record:
                        approach = a.target.approach_record_fields(self.base, self.cfg.approach_height)
                        self._writer.write(self.cfg.approach_record, approach, model_name=self.cfg.excavator,
                                           strict=True)
                    self.writes += 1
                    self._last_target = xyz
                    self._last_target_xy = (a.target.x, a.target.y)
        self._set_flag("SENSING_CHECK_MOUND_FLG", not a.has_soil)  # Table 7: true = not enough soil
        return a

    def on_vessel_points(self, points: np.ndarray) -> VesselAssessment:
        """Vessel points (vessel frame, see :mod:`tms_sp.vessel`) -> release target + SENSING_LOADED_FLG."""
        geom = self.vessel_geom
        spec = geom.grid_spec(self.cfg.resolution)
        grid = rasterize(points, spec, sensor="vessel points")
        v = assess_vessel(grid, geom, self.cfg.vessel, previous_xy=self._release_spot,
                          was_loaded=self.flags.get("SENSING_LOADED_FLG", False))
        self.vessel = v
        if self.carrier_pose is not None and self._at_loading_point():
            pose, angle = release_in_excavator(
                v.release_xyz, self.carrier_pose, self.base, geom,
                self.cfg.swing_axis_in_base, self.cfg.vessel.carry_theta_w,
            )
            xyz = (pose["x"], pose["y"], pose["z"])
            if self._moved(self._last_release, xyz, self.cfg.vessel_update_threshold):
                self._writer.write(self.cfg.release_record, pose, model_name=self.cfg.excavator, strict=True)
                self._writer.write(self.cfg.angle_record, angle, model_name=self.cfg.excavator, strict=True)
                self.writes += 2
                self._last_release = xyz
                self._release_spot = (v.release_xyz[0], v.release_xyz[1])
        self._set_flag("SENSING_LOADED_FLG", v.loaded)
        return v

    # ---- helpers ----------------------------------------------------------------------------------
    def _at_loading_point(self) -> bool:
        target = self.cfg.points[self.cfg.arrival_point]
        p = self.carrier_pose
        return math.hypot(p.x - target.x, p.y - target.y) <= self.cfg.arrival.position_tolerance

    @staticmethod
    def _moved(last: tuple[float, float, float] | None, new: tuple[float, float, float], threshold: float) -> bool:
        return last is None or math.dist(last, new) > threshold

    def _set_flag(self, name: str, value: bool) -> None:
        """Write the assessment where a record holds another value. Compared with the record, not with what
        sensing wrote last: the original's trees also write the Manual flags (the 2024-12 IC120 tree resets
        SENSING_LOADED_FLG after leaving P1), and sensing must assert its assessment again at its next scan."""
        self.flags[name] = value
        changed = False
        for record in self.cfg.blackboard_records:
            if self._writer.record(record).get(name) is not value:
                self._writer.write(record, {name: bool(value)}, strict=True)
                changed = True
        if changed:
            self.writes += 1
            log.info("%s -> %s", name, value)
