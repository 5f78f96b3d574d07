"""Generate the site map (config/nav/site_map.pgm + .yaml) from config/site.yaml.

Obstacles: the soil mound (its base circle) and every machine parked on the site (``parked`` of
config/nav/site_map_source.yaml: a circle of its clearance radius around a ``points`` entry of config/site.yaml,
e.g. an excavator's tail-swing radius around its base, so its upper body may swing freely). Extent and
resolution come from the ``map`` section of config/nav/site_map_source.yaml (read with
:mod:`tms_common.schema`). Run ``python -m tms_rp.tracked.mapgen`` after editing either file;
``--without-parked`` leaves the parked machines out (the map of the machines that are parked there).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tms_common.config import config_path
from tms_common.schema import load_schema, setting
from tms_model.site import load_site
from tms_rp.tracked.costmap import FREE, OCCUPIED, OccupancyMap, save_map

__all__ = ["MapSource", "build_site_map", "main"]

WITHOUT_PARKED = "--without-parked"


@dataclass(frozen=True)
class MapExtent:
    """The grid: lower-left corner, size [m] and cell size [m]."""

    x_min: float
    y_min: float
    size_x: float = setting(lo=0.1)
    size_y: float = setting(lo=0.1)
    resolution: float = setting(lo=0.001)


@dataclass(frozen=True)
class ParkedMachine:
    """A machine that stands on the site: a circle of ``clearance_radius`` [m] around the site point ``point``."""

    point: str
    clearance_radius: float = setting(lo=0.0)


@dataclass(frozen=True)
class MapSource:
    """config/nav/site_map_source.yaml."""

    map: MapExtent
    parked: tuple[ParkedMachine, ...] = ()
    border: bool = setting(True, doc="a 1-cell wall around the map edge")


def build_site_map(source_yaml: str | Path | None = None, site_yaml: str | Path | None = None, *,
                   include_parked: bool = True) -> OccupancyMap:
    """The occupancy grid of the site (without the parked machines' circles when ``include_parked`` is false)."""
    src = load_schema(MapSource, source_yaml or config_path("nav", "site_map_source.yaml"))
    site = load_site(site_yaml)
    m = src.map
    res, x0, y0 = m.resolution, m.x_min, m.y_min
    w, h = round(m.size_x / res), round(m.size_y / res)
    grid = np.full((h, w), FREE, dtype=np.int8)
    yy, xx = np.mgrid[0:h, 0:w]
    cx = x0 + (xx + 0.5) * res
    cy = y0 + (yy + 0.5) * res
    circles = [(site.mound.cx, site.mound.cy, site.mound.base_radius)]
    for parked in src.parked:
        base = site.point(parked.point)  # a missing point is named by the site
        if include_parked:
            circles.append((base.x, base.y, parked.clearance_radius))
    for ox, oy, r in circles:
        grid[(cx - ox) ** 2 + (cy - oy) ** 2 <= r * r] = OCCUPIED
    if src.border:
        grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = OCCUPIED
    return OccupancyMap(grid, res, (x0, y0))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    include_parked = WITHOUT_PARKED not in argv
    argv = [a for a in argv if a != WITHOUT_PARKED]
    out = Path(argv[0]) if argv else config_path("nav", "site_map.yaml")
    save_map(build_site_map(include_parked=include_parked), out)
    print(f"wrote {out} and {out.with_suffix('.pgm')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
