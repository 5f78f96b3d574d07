"""Simulated sensors: RTK-GNSS (pyproj), IMU roll/pitch, with seeded Gaussian noise.

GNSS: map (x east, y north, z up) -> plane rectangular coordinates of the site CRS (EPSG:6677, Japan
Plane Rectangular CS IX; map origin from ``config/site.yaml``) -> JGD2011 geographic latitude and
longitude with pyproj. Altitude = site altitude + z (no geoid model, as gnss_localizer_ros2 does).
Noise is white Gaussian with the RTK-fix sigmas of ``config/sim/plant.yaml``.
"""

from __future__ import annotations

import random

from pyproj import CRS, Transformer

from sim_bridge.config import SensorSpec, SiteSpec

__all__ = ["Gnss", "Noise"]


class Noise:
    """Seeded Gaussian noise source (one per plant, so runs are reproducible)."""

    def __init__(self, spec: SensorSpec) -> None:
        self.spec = spec
        self._rng = random.Random(spec.seed)

    def gauss(self, sigma: float) -> float:
        return self._rng.gauss(0.0, sigma) if sigma > 0 else 0.0


class Gnss:
    """Map <-> geodetic conversion for the site, and a noisy fix."""

    def __init__(self, site: SiteSpec) -> None:
        self.site = site
        plane = CRS.from_user_input(site.crs)
        geographic = plane.geodetic_crs
        if geographic is None:
            raise ValueError(f"{site.crs} has no geodetic CRS")
        self._to_geo = Transformer.from_crs(plane, geographic, always_xy=True)
        self._to_plane = Transformer.from_crs(geographic, plane, always_xy=True)

    def map_to_plane(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Map frame -> (easting, northing, altitude) in the site CRS."""
        return self.site.easting + x, self.site.northing + y, self.site.altitude + z

    def map_to_geodetic(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Map frame -> (latitude deg, longitude deg, altitude m)."""
        e, n, alt = self.map_to_plane(x, y, z)
        lon, lat = self._to_geo.transform(e, n)
        return lat, lon, alt

    def geodetic_to_map(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """Inverse of :meth:`map_to_geodetic` (for evaluation and tests)."""
        e, n = self._to_plane.transform(lon, lat)
        return e - self.site.easting, n - self.site.northing, alt - self.site.altitude

    def fix(self, x: float, y: float, z: float, noise: Noise) -> tuple[float, float, float]:
        """A noisy RTK fix of the antenna at map (x, y, z): (lat, lon, alt)."""
        s = noise.spec
        return self.map_to_geodetic(x + noise.gauss(s.gnss_sigma_h), y + noise.gauss(s.gnss_sigma_h), z + noise.gauss(s.gnss_sigma_v))
