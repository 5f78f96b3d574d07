"""The report's site map: the site, the machines and their paths in one plot readable at a glance.

Drawn from the models, not from hand-kept numbers: the mound, the route poses and the dump zone from
:class:`tms_model.site.Site`; the ZX200's footprint and its swing reach (the kinematic envelope of
:class:`tms_model.excavator.kinematics.ExcavatorKinematics`) at its base pose; the IC120's footprint and
vessel (:class:`tms_model.machines.Machine`) at the loading pose. Labels are placed so that they do not
overlap each other (poses at one position share one label), and the axes are sized to the site so the
plot fills its figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_model.geometry import Pose2D
from tms_model.machines import Machine
from tms_model.site import Site

__all__ = ["render_site_map"]

COLORS = {"ic120": "tab:orange", "zx200": "tab:blue"}
# label offsets tried in order [points]: right, above, left, below, then the diagonals, then further out
_OFFSETS = [(6, 4), (0, 10), (-6, 4), (0, -14), (8, 10), (-8, 10), (8, -14), (-8, -14)]
_OFFSETS += [(2 * dx, 2 * dy) for dx, dy in _OFFSETS]


def _rect(pose: Pose2D, cx: float, cy: float, length: float, width: float) -> np.ndarray:
    """Corners (closed) of a length x width rectangle centred at (cx, cy) of ``pose``'s frame, in map."""
    hl, hw = length / 2.0, width / 2.0
    local = np.array([[cx - hl, cy - hw, 0], [cx + hl, cy - hw, 0], [cx + hl, cy + hw, 0], [cx - hl, cy + hw, 0],
                      [cx - hl, cy - hw, 0]], dtype=float)
    return pose.to_map(local)[:, :2]


def _group_points(site: Site) -> list[tuple[float, float, str]]:
    """Route poses, those at one position merged into one label ("P3 / ic120_start")."""
    groups: dict[tuple[float, float], list[str]] = {}
    for name, p in site.points.items():
        groups.setdefault((round(p.x, 2), round(p.y, 2)), []).append(name)
    return [(x, y, " / ".join(names)) for (x, y), names in groups.items()]


def _place_labels(fig: Any, ax: Any, items: Sequence[tuple[float, float, str]]) -> list[Any]:
    """Annotate each (x, y, text) at the first offset whose box overlaps no label placed so far."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    placed: list[Any] = []
    boxes: list[Any] = []
    for x, y, text in items:
        chosen = None
        for dx, dy in _OFFSETS:
            ann = ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=9,
                              ha="left" if dx >= 0 else "right", va="bottom" if dy >= 0 else "top",
                              bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
            box = ann.get_window_extent(renderer)
            if not any(box.overlaps(b) for b in boxes):
                chosen = ann
                break
            ann.remove()
        if chosen is None:  # every offset collides: keep the first; the test of the paper site catches this
            chosen = ax.annotate(text, (x, y), textcoords="offset points", xytext=_OFFSETS[0], fontsize=9)
        boxes.append(chosen.get_window_extent(renderer))
        placed.append(chosen)
    return placed


def render_site_map(
    path: Path,
    site: Site,
    *,
    zx200: ExcavatorKinematics,
    ic120: Machine,
    paths: Mapping[str, Sequence[Sequence[float]]] | None = None,
    title: str = "Site map: machine paths (truth)",
) -> dict[str, Any]:
    """Write the site map PNG to ``path``; returns what was drawn (label texts and boxes, axes extent) for tests.

    ``paths``: per machine ``[(t, x, y), ...]`` truth samples.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    paths = paths or {}
    base = site.point("zx200_base")
    swing = base.to_map(np.array([zx200.swing_origin[0], zx200.swing_origin[1], 0.0]))
    reach = zx200.envelope()["max_reach"]
    loading = site.point("P1")
    dump = site.zone("dump_zone")
    m = site.mound

    # extent: everything drawn, plus a margin; the figure takes the site's aspect so the plot fills it
    xs = [p.x for p in site.points.values()] + [swing[0] - reach, swing[0] + reach, dump.x + dump.radius]
    ys = [p.y for p in site.points.values()] + [swing[1] - reach, swing[1] + reach, dump.y + dump.radius]
    for samples in paths.values():
        xs += [s[1] for s in samples]
        ys += [s[2] for s in samples]
    margin = 2.0
    x0, x1 = min(xs) - margin, max(xs) + margin
    y0, y1 = min(ys) - margin, max(ys) + margin
    # legend below the plot, so the axes take the full width; height = axes at the site's aspect plus the
    # title, the x label and two legend rows
    width_in = 12.0
    height_in = min(10.0, max(4.0, (width_in - 0.8) * (y1 - y0) / (x1 - x0) + 1.6))
    fig, ax = plt.subplots(figsize=(width_in, height_in), layout="constrained")

    ax.add_patch(Circle((m.cx, m.cy), m.base_radius, color="sienna", alpha=0.35, label="mound (base)"))
    if m.top_radius > 0:
        ax.add_patch(Circle((m.cx, m.cy), m.top_radius, color="sienna", alpha=0.35))
    ax.add_patch(Circle((dump.x, dump.y), dump.radius, fc="tab:olive", alpha=0.3, ec="tab:olive", hatch="//",
                        label="dump zone"))
    ax.add_patch(Circle((float(swing[0]), float(swing[1])), reach, fill=False, ls="--", color=COLORS["zx200"],
                        label=f"ZX200 swing reach ({reach:.1f} m)"))
    fp = zx200.machine.footprint
    ax.add_patch(Polygon(_rect(base, 0.0, 0.0, fp.length, fp.width), closed=True, fc=COLORS["zx200"], alpha=0.5,
                         label="ZX200"))
    assert ic120.vessel is not None
    v = ic120.vessel
    ic_fp = ic120.footprint
    ax.add_patch(Polygon(_rect(loading, 0.0, 0.0, ic_fp.length, ic_fp.width), closed=True, fc=COLORS["ic120"],
                         alpha=0.35, label="IC120 at loading"))
    vessel_cx = v.hinge_xyz[0] + v.inner_length / 2.0
    ax.add_patch(Polygon(_rect(loading, vessel_cx, v.hinge_xyz[1], v.inner_length, v.inner_width), closed=True,
                         fill=False, ec="saddlebrown", lw=2, label="IC120 vessel"))
    for machine, samples in paths.items():
        if len(samples) > 1:
            ax.plot([s[1] for s in samples], [s[2] for s in samples], "-", color=COLORS.get(machine), lw=1.5,
                    label=f"{machine} path")
            ax.plot(samples[-1][1], samples[-1][2], "o", color=COLORS.get(machine))
    for x, y, _ in _group_points(site):
        ax.plot(x, y, "k^", ms=6)
    for p in site.points.values():
        ax.annotate("", (p.x + 1.2 * math.cos(p.yaw), p.y + 1.2 * math.sin(p.yaw)), (p.x, p.y),
                    arrowprops={"arrowstyle": "->", "color": "0.3", "lw": 0.8})

    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x [m] (map, east)")
    ax.set_ylabel("y [m] (map, north)")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    fig.legend(loc="outside lower center", ncol=5, fontsize=9, frameon=False)
    labels = _place_labels(fig, ax, _group_points(site) + [(dump.x, dump.y + dump.radius, "dump zone")])
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    info = {
        "labels": [(a.get_text(), a.get_window_extent(renderer)) for a in labels],
        "axes_fraction": ax.get_window_extent(renderer).width * ax.get_window_extent(renderer).height
        / (fig.bbox.width * fig.bbox.height),
        "reach": reach,
    }
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return info
