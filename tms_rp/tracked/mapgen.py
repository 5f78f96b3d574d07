"""Generate the IC120 site map (config/nav/site_map.pgm + .yaml) from config/site.yaml.

Obstacles: the soil mound (its base circle) and the ZX200 (a circle of its tail-swing radius around
``points.zx200_base``, so the upper body may swing freely). Extent and resolution come from the ``map``
section of config/nav/site_map_source.yaml. Run ``python -m tms_rp.tracked.mapgen`` after editing either file.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tms_common.config import config_path, load_yaml
from tms_model.site import load_site
from tms_rp.tracked.costmap import FREE, OCCUPIED, OccupancyMap, save_map


def build_site_map(source_yaml: str | Path | None = None, site_yaml: str | Path | None = None, *,
                   include_zx200: bool = True) -> OccupancyMap:
    """The occupancy grid of the paper's site (without the ZX200's circle when ``include_zx200`` is false)."""
    src, swhere = load_yaml(source_yaml or config_path("nav", "site_map_source.yaml"))
    site = load_site(site_yaml)
    try:
        m = src["map"]
        res, x0, y0 = float(m["resolution"]), float(m["x_min"]), float(m["y_min"])
        w, h = round(float(m["size_x"]) / res), round(float(m["size_y"]) / res)
    except (KeyError, TypeError, ValueError) as exc:
        raise swhere.error(("map",), f"map section: {exc}") from None
    grid = np.full((h, w), FREE, dtype=np.int8)
    yy, xx = np.mgrid[0:h, 0:w]
    cx = x0 + (xx + 0.5) * res
    cy = y0 + (yy + 0.5) * res
    try:
        clearance = float(src["zx200_clearance_radius"])
    except (KeyError, TypeError, ValueError) as exc:
        raise swhere.error(("zx200_clearance_radius",), f"zx200_clearance_radius: {exc}") from None
    base = site.point("zx200_base")
    circles = [(site.mound.cx, site.mound.cy, site.mound.base_radius)]
    if include_zx200:
        circles.append((base.x, base.y, clearance))
    for ox, oy, r in circles:
        grid[(cx - ox) ** 2 + (cy - oy) ** 2 <= r * r] = OCCUPIED
    if src.get("border", True):
        grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = OCCUPIED
    return OccupancyMap(grid, res, (x0, y0))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    include_zx200 = "--without-zx200" not in argv
    argv = [a for a in argv if a != "--without-zx200"]
    out = Path(argv[0]) if argv else config_path("nav", "site_map.yaml")
    save_map(build_site_map(include_zx200=include_zx200), out)
    print(f"wrote {out} and {out.with_suffix('.pgm')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
