"""GNSS latitude/longitude -> site map coordinates (Japan Plane Rectangular CS, EPSG:6677 for zone IX).

The map frame is the plane-rectangular frame shifted to the site origin of ``config/site.yaml``
(``map_origin_plane``): ROS x = easting - origin easting, y = northing - origin northing, z = altitude -
origin altitude (no geoid correction, as gnss_localizer_ros2). pyproj does the projection; with
``always_xy=True`` the projected output is (easting, northing) even though EPSG:6677 lists northing first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pyproj import Transformer

from tms_common.config import config_path, load_yaml

__all__ = ["GnssProjector", "projector_from_site"]


@dataclass(frozen=True)
class _Origin:
    easting: float
    northing: float
    altitude: float


class GnssProjector:
    """Converts between geodetic (lat, lon, alt) and the site map frame.

    Args:
        crs: projected CRS of the site ("EPSG:6677").
        origin: map origin in that CRS, ``{easting, northing, altitude}`` [m].
        geodetic_crs: CRS of the incoming fixes ("EPSG:6668" JGD2011; WGS84 fixes agree to cm level).
    """

    def __init__(self, crs: str, origin: dict, geodetic_crs: str = "EPSG:6668") -> None:
        try:
            self._fwd = Transformer.from_crs(geodetic_crs, crs, always_xy=True)
            self._inv = Transformer.from_crs(crs, geodetic_crs, always_xy=True)
        except Exception as exc:  # pyproj raises CRSError (a ProjError subclass)
            raise ValueError(f"cannot build transformer {geodetic_crs} -> {crs}: {exc}") from exc
        try:
            self.origin = _Origin(float(origin["easting"]), float(origin["northing"]), float(origin.get("altitude", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"map origin needs numeric easting/northing[/altitude], got {origin!r}") from exc

    def to_map(self, lat: float, lon: float, alt: float = 0.0) -> tuple[float, float, float]:
        """Geodetic degrees (+ altitude [m]) -> map (x east, y north, z up) [m]."""
        if not (math.isfinite(lat) and math.isfinite(lon)) or abs(lat) > 90.0 or abs(lon) > 180.0:
            raise ValueError(f"invalid GNSS fix lat={lat!r} lon={lon!r}")
        easting, northing = self._fwd.transform(lon, lat)
        z = alt - self.origin.altitude if math.isfinite(alt) else 0.0
        return easting - self.origin.easting, northing - self.origin.northing, z

    def to_geodetic(self, x: float, y: float, z: float = 0.0) -> tuple[float, float, float]:
        """Map (x, y, z) [m] -> (lat, lon, alt): what a GNSS receiver at that point reports."""
        lon, lat = self._inv.transform(x + self.origin.easting, y + self.origin.northing)
        return lat, lon, z + self.origin.altitude


def projector_from_site(site_yaml: str | None = None, geodetic_crs: str = "EPSG:6668") -> GnssProjector:
    """The projector for ``config/site.yaml`` (keys ``crs`` and ``map_origin_plane``)."""
    data, where = load_yaml(site_yaml or config_path("site.yaml"))
    for key in ("crs", "map_origin_plane"):
        if not isinstance(data, dict) or key not in data:
            raise where.error((key,), f"site config: missing key {key!r}")
    return GnssProjector(data["crs"], data["map_origin_plane"], geodetic_crs)
