"""Sensing processors: speed per update and accuracy against the synthetic truth.

Prints, over 50 noisy scans (sigma 3 cm, 1 % outliers of up to 2 m): mound update time (40,000 points),
vessel update time (8,000 points), |sensed - true| mound volume, excavation-target surface error, and
vessel volume error at 50 % fill.
"""

from __future__ import annotations

import time

import numpy as np

from tests.bench.stats import summary_ms
from tms_sp import synthetic as syn
from tms_sp.config import load_sensing_config
from tms_sp.heightgrid import rasterize
from tms_sp.mound import assess_mound
from tms_sp.vessel import assess_vessel


def main() -> None:
    cfg = load_sensing_config()
    m, g = cfg.mound, cfg.mound_grid
    cone = syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height, m.ground_z)
    vg = cfg.vessel_geom
    vs = vg.grid_spec(cfg.resolution)
    heap = syn.vessel_heap(0.5 * vg.capacity, vg.inner_length, vg.inner_width, cx=0.5)
    t_mound, t_vessel, vol_err, surf_err, vessel_err = [], [], [], [], []
    for seed in range(50):
        rng = np.random.default_rng(seed)
        pts = syn.scan(cone, (g.x_min, g.x_max), (g.y_min, g.y_max), 40000, rng)
        t0 = time.perf_counter()
        a = assess_mound(rasterize(pts, g), cfg.swing_axis_map(), cfg.excavation)
        t_mound.append(time.perf_counter() - t0)
        vol_err.append(abs(a.volume_total - m.bank_volume()))
        surf_err.append(abs(a.target.surface_z - float(cone(np.array(a.target.x), np.array(a.target.y)))))
        vpts = syn.scan(heap, (vs.x_min, vs.x_max), (vs.y_min, vs.y_max), 8000, rng, noise=0.02)
        t0 = time.perf_counter()
        v = assess_vessel(rasterize(vpts, vs), vg, cfg.vessel)
        t_vessel.append(time.perf_counter() - t0)
        vessel_err.append(abs(v.volume - 0.5 * vg.capacity))
    print(f"mound update (40k points): {summary_ms(t_mound)}")
    print(f"vessel update (8k points): {summary_ms(t_vessel)}")
    print(
        f"mound volume error: mean {np.mean(vol_err):.3f} m3 of {m.bank_volume():.2f} m3, max {np.max(vol_err):.3f} m3"
    )
    print(f"target surface error: mean {100 * np.mean(surf_err):.1f} cm, max {100 * np.max(surf_err):.1f} cm")
    print(f"vessel volume error at 50% fill: mean {np.mean(vessel_err):.3f} m3, max {np.max(vessel_err):.3f} m3")


if __name__ == "__main__":
    main()
