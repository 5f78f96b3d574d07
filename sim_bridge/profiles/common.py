"""What the plant profiles share: MJCF number formatting and the state frames of every machine on tracks.

The carrier and the dozer report their travel, heading, attitude, GNSS fix and machine state in the same frames
(our COM3 extension DBCs share them); :func:`tracked_state` builds those, each profile the frames of its own
implement.
"""

from __future__ import annotations

from com3_can.signal_map import CARRIER_FRAMES
from com3_can.signal_map import CARRIER_VESSEL as V
from sim_bridge.profiles.base import PlantBus, Side
from tms_model.geometry import wrap_angle

__all__ = ["vec", "tracked_state"]

#: the travel feedback frame, named alike in the carrier and the dozer DBC
TRACK_VELOCITY = CARRIER_FRAMES["track_velocity"]


def vec(values: tuple[float, ...] | list[float]) -> str:
    """An MJCF vector attribute (``pos``, ``euler``, ``axis``, ``size``)."""
    return " ".join(f"{v:.6g}" for v in values)


def tracked_state(io: PlantBus, side: Side, frame: str) -> dict[str, float]:
    """Physical values of a tracked machine's shared state frame ``frame`` (KeyError for any other)."""
    m = side.machine
    if frame == "Machine_State":
        return io.machine_state(side)
    if frame == TRACK_VELOCITY:
        return {V.left_track_velocity: m.base.vl, V.right_track_velocity: m.base.vr}
    if frame == "Vehicle_Azimuth":
        return {"track_body_azimuth": -wrap_angle(m.base.yaw), "yaw_rate": -m.base.w}
    if frame == "Roll_Pitch_Angle":
        return io.roll_pitch(side.name)
    if frame.startswith("GNSS_"):
        if frame == "GNSS_Latitude" or side.fix is None:  # one fix per 100 ms cycle, shared by the three frames
            side.fix = io.gnss.fix(m.base.x, m.base.y, m.z, io.noise)
        fix = side.fix
        if frame == "GNSS_Latitude":
            return {"latitude": fix[0]}
        if frame == "GNSS_Longitude":
            return {"longitude": fix[1]}
        return {"altitude": fix[2], "fix_status": 3.0, "num_satellites": 20.0,
                "horizontal_accuracy": io.sensors.gnss_sigma_h}
    raise KeyError(f"{side.name}: no builder for state frame {frame}")
