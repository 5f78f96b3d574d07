"""tms_model.site: the site parsed once, the projector's round trip, file:line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from tms_common.errors import ConfigError
from tms_model.site import Projector, load_site


def test_project_site_loads_once_with_points_zone_and_mound() -> None:
    site = load_site()
    assert site is load_site()  # cached
    assert site.crs == "EPSG:6677"
    assert site.point("P1").x == pytest.approx(1.2)
    assert site.zone("dump_zone").radius == pytest.approx(3.0)
    assert "dump_zone" not in site.points
    assert site.mound.bank_volume() == pytest.approx(26.3, abs=0.1)
    with pytest.raises(KeyError, match="known"):
        site.point("P9")


def test_projector_origin_and_round_trip() -> None:
    site = load_site()
    proj = site.projector
    assert proj is site.projector
    lat, lon, alt = proj.map_to_geodetic(0.0, 0.0, 0.0)
    # the rounded geodetic origin of site.yaml is within ~0.2 m of the plane origin
    assert site.origin_geodetic is not None
    assert lat == pytest.approx(site.origin_geodetic[0], abs=2e-6)
    assert lon == pytest.approx(site.origin_geodetic[1], abs=2e-6)
    assert alt == pytest.approx(28.552)
    for x, y, z in ((10.0, -5.0, 1.0), (-250.0, 400.0, -2.0)):
        back = proj.geodetic_to_map(*proj.map_to_geodetic(x, y, z))
        assert back == pytest.approx((x, y, z), abs=1e-6)
    e, n, a = proj.map_to_plane(1.0, 2.0, 3.0)
    assert proj.plane_to_map(e, n, a) == pytest.approx((1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match="invalid GNSS fix"):
        proj.geodetic_to_map(float("nan"), 140.0)


def test_bad_site_names_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "site.yaml"
    bad.write_text(
        'crs: "EPSG:6677"\nmap_origin_plane: {easting: 1.0, northing: 2.0, altitude: 0.0}\n'
        "points:\n  P1: {x: 1.0, y: oops, yaw: 0.0}\n"
        "mound: {shape: cone, center: {x: 0, y: 0}, base_radius: 2, height: 1}\n"
    )
    with pytest.raises(ConfigError, match=r"site.yaml:4: points.P1.y: expected a number"):
        load_site(bad)
    bad.write_text(bad.read_text().replace("y: oops", "y: 1.0").replace("shape: cone", "shape: pyramid"))
    with pytest.raises(ConfigError, match=r"site.yaml:5: mound.shape: unknown mound shape"):
        load_site(bad)


def test_projection_matches_zone_ix_origin_and_axis_order() -> None:
    # Zone IX origin 36N 139 50'E is plane (0, 0): with a zero map origin the projector returns it.
    proj = Projector("EPSG:6677", (0.0, 0.0, 0.0), "EPSG:6668")
    assert proj.geodetic_to_map(36.0, 139.0 + 50.0 / 60.0)[:2] == pytest.approx((0.0, 0.0), abs=1e-3)
    site = load_site().projector
    lat, lon, _ = site.map_to_geodetic(0.0, 0.0)
    lat2, lon2, _ = site.map_to_geodetic(100.0, 50.0)  # x = east, y = north
    assert lon2 > lon and lat2 > lat


def test_projector_rejects_unknown_crs() -> None:
    with pytest.raises(ValueError, match="EPSG:999999"):
        Projector("EPSG:999999", (0.0, 0.0, 0.0))
