"""Simulated sensors: RTK-GNSS and IMU roll/pitch, with seeded Gaussian noise.

GNSS: map (x east, y north, z up) -> plane rectangular coordinates of the site CRS -> geodetic latitude
and longitude through the site's one projector (:class:`tms_model.site.Projector`). Noise is white
Gaussian with the RTK-fix sigmas of ``config/sim/plant.yaml``.
"""

from __future__ import annotations

import random

from sim_bridge.spec import SensorSpec
from tms_model.site import Site

__all__ = ["Gnss", "Noise"]


class Noise:
    """Seeded Gaussian noise source (one per plant, so runs are reproducible)."""

    def __init__(self, spec: SensorSpec) -> None:
        self.spec = spec
        self._rng = random.Random(spec.seed)

    def gauss(self, sigma: float) -> float:
        return self._rng.gauss(0.0, sigma) if sigma > 0 else 0.0


class Gnss:
    """Map <-> geodetic conversion for the site (its projector), and a noisy fix."""

    def __init__(self, site: Site) -> None:
        self.site = site
        self.projector = site.projector

    def map_to_plane(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Map frame -> (easting, northing, altitude) in the site CRS."""
        return self.projector.map_to_plane(x, y, z)

    def map_to_geodetic(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """Map frame -> (latitude deg, longitude deg, altitude m)."""
        return self.projector.map_to_geodetic(x, y, z)

    def geodetic_to_map(self, lat: float, lon: float, alt: float) -> tuple[float, float, float]:
        """Inverse of :meth:`map_to_geodetic` (for evaluation and tests)."""
        return self.projector.geodetic_to_map(lat, lon, alt)

    def fix(self, x: float, y: float, z: float, noise: Noise) -> tuple[float, float, float]:
        """A noisy RTK fix of the antenna at map (x, y, z): (lat, lon, alt)."""
        s = noise.spec
        return self.map_to_geodetic(
            x + noise.gauss(s.gnss_sigma_h), y + noise.gauss(s.gnss_sigma_h), z + noise.gauss(s.gnss_sigma_v)
        )
