"""``tms_ss_terrain_static``: a survey (LAS/LAZ point cloud) or a 16-bit PNG heightmap -> the static terrain in the DB.

The original's path is ``save_image_to_mongodb.py`` (LAS -> ``las2heightmap`` -> PNG -> GridFS, fields ``time``,
``type``, ``id``, ``height``, ``width``, ``elevation``, ``offset_x``, ``offset_y``) and ``tms_ss_terrain_static``
(``type: static``, ``id`` 3030). This command does both in one step through :mod:`tms_sp.terrain`::

    tms_ss_terrain_static site.las [--filename site.png] [--resolution 0.1] [--z-min 0.0] [--db-path DIR]
    tms_ss_terrain_static hm.png --x-min 2 --y-min -4.5 --size-x 9 --size-y 9 --z-min 0

Exit 0 printing the file id; exit 1 naming the file and the problem (missing, not LAS, empty cloud, not a 16-bit
PNG, relief over 16 m), nothing stored then.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tms_common.errors import TmsError
from tms_db import open_store
from tms_sp.terrain import STATIC_ID, heightmap_from_file, now_text, store_heightmap

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="tms_ss_terrain_static", description=__doc__.split("\n\n")[0])
    ap.add_argument("input", help="LAS/LAZ point cloud or 16-bit grayscale PNG heightmap")
    ap.add_argument("--filename", default="", help="stored filename (default: the input's name, .png)")
    ap.add_argument("--type", default="static", help="file document type (the original: static; heightmap)")
    ap.add_argument("--id", type=int, default=STATIC_ID, help="file document id (the original's 3030)")
    ap.add_argument("--resolution", type=float, default=0.1, help="cell size [m] of a point cloud's heightmap")
    ap.add_argument("--z-min", type=float, default=None,
                    help="height [m] of pixel 0 (LAS: default its lowest point; PNG: default 0)")
    for name in ("x-min", "y-min", "size-x", "size-y"):
        ap.add_argument(f"--{name}", type=float, default=0.0, help="PNG placement on the map [m]")
    ap.add_argument("--db-uri", default="", help="mongodb://... (default: the embedded store)")
    ap.add_argument("--db-path", default="", help="embedded store directory")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    filename = args.filename or Path(args.input).with_suffix(".png").name
    try:
        hm = heightmap_from_file(args.input, cell=args.resolution, x_min=args.x_min, y_min=args.y_min,
                                 size_x=args.size_x, size_y=args.size_y, z_min=args.z_min)
        with open_store(uri=args.db_uri or None, path=args.db_path or None) as store:
            file_id = store_heightmap(store, hm, kind=args.type, ident=args.id, filename=filename, time=now_text())
    except TmsError as exc:
        print(f"tms_ss_terrain_static: {exc}", file=sys.stderr)
        return 1
    print(f"{file_id} {args.type} {filename}: {hm.cols} x {hm.rows} cells, x {hm.x_min:.3f}..{hm.x_max:.3f}, "
          f"y {hm.y_min:.3f}..{hm.y_max:.3f}, z_min {hm.z_min:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
