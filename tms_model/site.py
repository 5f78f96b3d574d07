"""The site: named poses and zones, the soil mound, the map origin and the one map <-> geodetic projector.

Read once from ``config/site.yaml`` by :func:`load_site`. The map frame is the site CRS's plane
rectangular frame (Japan Plane Rectangular CS IX, EPSG:6677, for the PWRI field) shifted to
``map_origin_plane``: ROS x = easting - origin easting, y = northing - origin northing, z = altitude -
origin altitude (no geoid model, as gnss_localizer_ros2). pyproj does the projection with
``always_xy=True``, so plane coordinates are (easting, northing) even though EPSG:6677 lists northing
first, and geodetic ones (lon, lat) inside pyproj.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from pyproj import CRS, Transformer

from tms_common.config import config_path, load_yaml
from tms_common.schema import Reader
from tms_model.geometry import Pose2D

__all__ = ["Mound", "Projector", "Site", "SiteMachine", "Zone", "load_site"]

#: a machine name is a ROS namespace segment (the original's model_name: zx200, ic120_1, d37pxi_24)
MACHINE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


@dataclass(frozen=True)
class Zone:
    """A circular area on the site (e.g. where dumped soil lands): centre [m] in map, radius [m]."""

    x: float
    y: float
    radius: float


@dataclass(frozen=True)
class Mound:
    """The soil mound to dig: a (truncated) cone on flat ground; all in metres, map frame."""

    shape: str  # "truncated_cone" | "cone"
    cx: float
    cy: float
    base_radius: float
    top_radius: float
    height: float
    ground_z: float

    def bank_volume(self) -> float:
        r1, r2, h = self.base_radius, self.top_radius, self.height
        return math.pi * h / 3.0 * (r1 * r1 + r1 * r2 + r2 * r2)


class Projector:
    """Map frame <-> plane rectangular (site CRS) <-> geodetic (the CRS's own datum, JGD2011 for EPSG:6677).

    Args:
        crs: the projected CRS of the site (``"EPSG:6677"``).
        origin: map origin in that CRS: (easting, northing, altitude) [m].
        geodetic_crs: CRS of latitude/longitude; default the projected CRS's geodetic datum (WGS84 fixes
            agree with JGD2011 to cm level).
    """

    def __init__(self, crs: str, origin: tuple[float, float, float], geodetic_crs: str | None = None) -> None:
        try:
            plane = CRS.from_user_input(crs)
            geo = CRS.from_user_input(geodetic_crs) if geodetic_crs else plane.geodetic_crs
            if geo is None:
                raise ValueError(f"{crs} has no geodetic CRS")
            self._to_geo = Transformer.from_crs(plane, geo, always_xy=True)
            self._to_plane = Transformer.from_crs(geo, plane, always_xy=True)
        except Exception as exc:  # pyproj raises CRSError (a ProjError subclass)
            raise ValueError(f"cannot build transformer {geodetic_crs or 'geodetic'} <-> {crs}: {exc}") from exc
        self.crs = crs
        self.origin = origin

    def map_to_plane(self, x: float, y: float, z: float = 0.0) -> tuple[float, float, float]:
        """Map -> (easting, northing, altitude) in the site CRS."""
        e0, n0, a0 = self.origin
        return e0 + x, n0 + y, a0 + z

    def plane_to_map(self, easting: float, northing: float, altitude: float = 0.0) -> tuple[float, float, float]:
        e0, n0, a0 = self.origin
        return easting - e0, northing - n0, altitude - a0

    def plane_to_geodetic(self, easting: float, northing: float) -> tuple[float, float]:
        """Plane (easting, northing) -> (latitude, longitude) [deg]."""
        lon, lat = self._to_geo.transform(easting, northing)
        return float(lat), float(lon)

    def geodetic_to_plane(self, lat: float, lon: float) -> tuple[float, float]:
        """(latitude, longitude) [deg] -> plane (easting, northing)."""
        easting, northing = self._to_plane.transform(lon, lat)
        return float(easting), float(northing)

    def map_to_geodetic(self, x: float, y: float, z: float = 0.0) -> tuple[float, float, float]:
        """Map (x, y, z) [m] -> (lat, lon, alt): what a GNSS receiver at that point reports."""
        e, n, alt = self.map_to_plane(x, y, z)
        lat, lon = self.plane_to_geodetic(e, n)
        return lat, lon, alt

    def geodetic_to_map(self, lat: float, lon: float, alt: float = 0.0) -> tuple[float, float, float]:
        """Geodetic degrees (+ altitude [m]) -> map (x east, y north, z up) [m].

        Raises ValueError for a non-finite or out-of-range latitude/longitude; a non-finite altitude
        (a 2-D fix) gives z = 0 on the flat site.
        """
        if not (math.isfinite(lat) and math.isfinite(lon)) or abs(lat) > 90.0 or abs(lon) > 180.0:
            raise ValueError(f"invalid GNSS fix lat={lat!r} lon={lon!r}")
        e, n = self.geodetic_to_plane(lat, lon)
        x, y, z = self.plane_to_map(e, n, alt if math.isfinite(alt) else self.origin[2])
        return x, y, z


@dataclass(frozen=True)
class SiteMachine:
    """A machine on the site: its name (the original's ``model_name``, the namespace of its nodes), its kind
    (``config/machines/<kind>.yaml``) and what its CAN link changes from its kind's bus settings
    (``config/can/<kind>.yaml``): two machines of one kind need links of their own."""

    name: str
    kind: str
    can: Mapping[str, object] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True)
class Site:
    """``config/site.yaml``: CRS, map origin, named poses, zones and the mound."""

    crs: str
    origin_plane: tuple[float, float, float]  # easting, northing, altitude [m]
    origin_geodetic: tuple[float, float] | None  # lat, lon [deg] (documentation; the projector uses the plane)
    points: Mapping[str, Pose2D]
    zones: Mapping[str, Zone]
    mound: Mound
    machines: Mapping[str, SiteMachine] = field(default_factory=lambda: MappingProxyType({}))
    source: str = field(default="", compare=False)

    def machine(self, name: str) -> SiteMachine:
        """The machine called ``name``; KeyError lists the site's machines."""
        try:
            return self.machines[name]
        except KeyError:
            raise KeyError(f"{self.source}: no machine {name!r} in machines (known: {sorted(self.machines)})") from None

    def point(self, name: str) -> Pose2D:
        """The named pose; KeyError lists the known names."""
        try:
            return self.points[name]
        except KeyError:
            raise KeyError(f"{self.source}: no pose {name!r} in points (known: {sorted(self.points)})") from None

    def zone(self, name: str) -> Zone:
        try:
            return self.zones[name]
        except KeyError:
            raise KeyError(f"{self.source}: no zone {name!r} in points (known: {sorted(self.zones)})") from None

    @functools.cached_property
    def projector(self) -> Projector:
        """The one map <-> plane <-> geodetic projector of the site (built on first use)."""
        return Projector(self.crs, self.origin_plane)


def _parse(path: Path) -> Site:
    data, where = load_yaml(path)
    top = Reader(data, where)
    crs = top.string("crs")
    try:
        CRS.from_user_input(crs)
    except Exception as exc:  # noqa: BLE001 - pyproj raises its own CRSError and others for a bad text
        raise top.key_error("crs", f"not a CRS pyproj knows: {exc}") from None
    o = top.sub("map_origin_plane")
    o.only({"easting", "northing", "altitude"})
    origin = (o.number("easting"), o.number("northing"), o.number("altitude", default=0.0))
    geodetic = None
    if top.has("map_origin_geodetic"):
        g = top.sub("map_origin_geodetic")
        g.only({"lat", "lon"})
        geodetic = (g.number("lat", lo=-90, hi=90), g.number("lon", lo=-180, hi=180))
    points: dict[str, Pose2D] = {}
    zones: dict[str, Zone] = {}
    pts = top.sub("points")
    for name in pts.keys():
        p = pts.sub(name)
        if p.has("radius"):
            p.only({"x", "y", "radius"})
            zones[name] = Zone(p.number("x"), p.number("y"), p.number("radius", lo=0.0))
        else:
            p.only({"x", "y", "yaw"})
            points[name] = Pose2D(p.number("x"), p.number("y"), p.number("yaw"))
    m = top.sub("mound")
    m.only({"shape", "center", "base_radius", "top_radius", "height", "ground_z"})
    shape = m.string("shape")
    if shape not in ("truncated_cone", "cone"):
        raise m.key_error("shape", f"unknown mound shape {shape!r}; expected truncated_cone or cone")
    c = m.sub("center")
    base = m.number("base_radius", lo=0.0)
    top_r = m.number("top_radius", lo=0.0) if shape == "truncated_cone" else 0.0
    if shape == "truncated_cone" and not top_r < base:
        raise m.key_error("top_radius", f"must be < base_radius {base}, got {top_r}")
    height = m.number("height")
    if height <= 0:
        raise m.key_error("height", f"must be > 0, got {height}")
    mound = Mound(shape, c.number("x"), c.number("y"), base, top_r, height, m.number("ground_z", default=0.0))
    return Site(
        machines=_machines(top),
        crs=crs,
        origin_plane=origin,
        origin_geodetic=geodetic,
        points=MappingProxyType(points),
        zones=MappingProxyType(zones),
        mound=mound,
        source=str(path),
    )


_CAN_KEYS = {"interface", "channel", "port"}


def _machines(top: Reader) -> Mapping[str, SiteMachine]:
    if not top.has("machines"):
        return MappingProxyType({})
    r = top.sub("machines")
    out: dict[str, SiteMachine] = {}
    for name in r.keys():
        if not MACHINE_NAME.fullmatch(str(name)):
            raise r.key_error(name, "a machine name is a ROS namespace segment: a letter, then letters, digits or _")
        m = r.sub(name)
        m.only({"kind", "can"})
        kind = m.string("kind")
        can: dict[str, object] = {}
        if m.has("can"):
            c = m.sub("can")
            c.only(_CAN_KEYS)
            can = {k: (int(c.number(k, lo=1, hi=65535)) if k == "port" else c.string(k)) for k in c.keys()}
        out[name] = SiteMachine(name, kind, MappingProxyType(can))
    return MappingProxyType(out)


@functools.lru_cache(maxsize=8)
def _cached(path: str) -> Site:
    return _parse(Path(path))


def load_site(path: str | Path | None = None) -> Site:
    """The site of ``path`` (default ``config/site.yaml``), parsed once per file.

    Raises:
        tms_common.errors.ConfigError: ``file:line: key: problem`` for a missing or malformed value.
    """
    resolved = Path(path) if path else config_path("site.yaml")
    return _cached(str(resolved.resolve()))
