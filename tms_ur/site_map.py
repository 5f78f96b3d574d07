"""The report's site map: the site, the machines and their paths in one plot readable at a glance.

Drawn from the models, not from hand-kept numbers: the mound, the route poses and the dump zone from
:class:`tms_model.site.Site`; each machine from its description (:class:`tms_model.machines.Machine`) by its
type: an excavator's footprint and its swing reach (the kinematic envelope of
:class:`tms_model.excavator.kinematics.ExcavatorKinematics`) at its base pose (the site point ``<name>_base``, else
where its path starts); a carrier's footprint and vessel at the loading point; a dozer's footprint and blade where its
path ends. Labels are placed so that they do not overlap each other (poses at one position share one label), and the
axes are sized to the site so the plot fills its figure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_model.geometry import Pose2D
from tms_model.machines import CRAWLER_DUMP, DOZER, EXCAVATOR, TYPES, Machine
from tms_model.site import Site

__all__ = ["machine_colors", "order_machines", "render_site_map"]

#: colours given to the machines in their order (:func:`order_machines`): excavators first, so a site of one
#: excavator and one carrier draws them blue and orange
PALETTE = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:cyan",
           "tab:gray", "gold", "navy")

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
    """Route poses, those at one position merged into one label ("P3 / <machine>_start")."""
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


def order_machines(machines: Sequence[Machine]) -> list[Machine]:
    """Excavators, then carriers, then dozers (the order of ``TYPES``), each type in the given order."""
    return sorted(machines, key=lambda m: TYPES.index(m.type) if m.type in TYPES else len(TYPES))


def machine_colors(machines: Sequence[Machine]) -> dict[str, str]:
    """Machine name -> its colour in the plot (``PALETTE`` in :func:`order_machines` order)."""
    return {m.model_name: PALETTE[i % len(PALETTE)] for i, m in enumerate(order_machines(machines))}


def _label(machine: Machine) -> str:
    """``<name> (<kind>)`` for a machine whose name is not its kind, else the name."""
    return machine.model_name if machine.model_name == machine.kind else f"{machine.model_name} ({machine.kind})"


def _start_pose(samples: Sequence[Sequence[float]] | None, index: int) -> Pose2D | None:
    """The pose of path sample ``index`` (heading from its neighbour; 0 for a lone sample), None without a path."""
    if not samples:
        return None
    s = samples[index]
    other = samples[index + 1] if index == 0 and len(samples) > 1 else samples[index - 1] if len(samples) > 1 else s
    dx, dy = (other[1] - s[1], other[2] - s[2]) if index == 0 else (s[1] - other[1], s[2] - other[2])
    return Pose2D(float(s[1]), float(s[2]), math.atan2(dy, dx) if (dx or dy) else 0.0)


def render_site_map(
    path: Path,
    site: Site,
    *,
    machines: Sequence[Machine],
    paths: Mapping[str, Sequence[Sequence[float]]] | None = None,
    loading_point: str = "P1",
    title: str = "Site map: machine paths (truth)",
) -> dict[str, Any]:
    """Write the site map PNG to ``path``; returns what was drawn (label texts and boxes, axes extent, each
    excavator's reach, the machines drawn) for tests.

    ``machines``: the descriptions of the machines to draw (:func:`tms_model.fleet.load_named`); ``paths``: per
    machine name ``[(t, x, y), ...]`` truth samples; ``loading_point``: the site point where carriers are drawn.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    paths = paths or {}
    ordered = order_machines(machines)
    colors = machine_colors(ordered)
    loading = site.point(loading_point) if loading_point in site.points else None
    dump = site.zone("dump_zone")
    m = site.mound

    # where each machine is drawn, by its type (a machine with nowhere to be drawn shows its path only)
    excavators: list[tuple[Machine, Pose2D, np.ndarray, float]] = []
    placed: list[tuple[Machine, Pose2D]] = []
    for machine in ordered:
        name = machine.model_name
        if machine.type == EXCAVATOR:
            base = site.points.get(f"{name}_base") or _start_pose(paths.get(name), 0)
            if base is None:
                continue
            kin = ExcavatorKinematics(machine)
            swing = base.to_map(np.array([kin.swing_origin[0], kin.swing_origin[1], 0.0]))
            excavators.append((machine, base, swing, kin.envelope()["max_reach"]))
        elif machine.type == CRAWLER_DUMP and loading is not None:
            placed.append((machine, loading))
        elif machine.type == DOZER:
            pose = _start_pose(paths.get(name), -1)
            if pose is not None:
                placed.append((machine, pose))

    # extent: everything drawn, plus a margin; the figure takes the site's aspect so the plot fills it
    xs = [p.x for p in site.points.values()] + [dump.x + dump.radius]
    ys = [p.y for p in site.points.values()] + [dump.y + dump.radius]
    for _, _, swing, reach in excavators:
        xs += [swing[0] - reach, swing[0] + reach]
        ys += [swing[1] - reach, swing[1] + reach]
    for samples in paths.values():
        xs += [s[1] for s in samples]
        ys += [s[2] for s in samples]
    margin = 2.0
    x0, x1 = min(xs) - margin, max(xs) + margin
    y0, y1 = min(ys) - margin, max(ys) + margin
    # legend below the plot, so the axes take the full width; height = axes at the site's aspect plus the
    # title, the x label and the legend rows
    width_in = 12.0
    legend_rows = math.ceil((3 + 2 * len(excavators) + 2 * len(placed) + len(paths)) / 5)
    height_in = min(10.0, max(4.0, (width_in - 0.8) * (y1 - y0) / (x1 - x0) + 1.0 + 0.3 * legend_rows))
    fig, ax = plt.subplots(figsize=(width_in, height_in), layout="constrained")

    ax.add_patch(Circle((m.cx, m.cy), m.base_radius, color="sienna", alpha=0.35, label="mound (base)"))
    if m.top_radius > 0:
        ax.add_patch(Circle((m.cx, m.cy), m.top_radius, color="sienna", alpha=0.35))
    ax.add_patch(Circle((dump.x, dump.y), dump.radius, fc="tab:olive", alpha=0.3, ec="tab:olive", hatch="//",
                        label="dump zone"))
    for machine, base, swing, reach in excavators:
        color = colors[machine.model_name]
        ax.add_patch(Circle((float(swing[0]), float(swing[1])), reach, fill=False, ls="--", color=color,
                            label=f"{_label(machine)} swing reach ({reach:.1f} m)"))
        fp = machine.footprint
        ax.add_patch(Polygon(_rect(base, 0.0, 0.0, fp.length, fp.width), closed=True, fc=color, alpha=0.5,
                             label=_label(machine)))
    for machine, pose in placed:
        color = colors[machine.model_name]
        fp = machine.footprint
        where = "at loading" if machine.type == CRAWLER_DUMP else "(last pose)"
        ax.add_patch(Polygon(_rect(pose, 0.0, 0.0, fp.length, fp.width), closed=True, fc=color, alpha=0.35,
                             label=f"{_label(machine)} {where}"))
        if machine.vessel is not None:
            v = machine.vessel
            vessel_cx = v.hinge_xyz[0] + v.inner_length / 2.0
            ax.add_patch(Polygon(_rect(pose, vessel_cx, v.hinge_xyz[1], v.inner_length, v.inner_width), closed=True,
                                 fill=False, ec=color, lw=2, label=f"{_label(machine)} vessel"))
        if machine.blade is not None:
            b = machine.blade
            edge = pose.to_map(np.array([[b.edge_xyz[0], -b.width / 2.0, 0.0], [b.edge_xyz[0], b.width / 2.0, 0.0]]))
            ax.plot(edge[:, 0], edge[:, 1], "-", color=color, lw=3, label=f"{_label(machine)} blade")
    for name, samples in paths.items():
        if len(samples) > 1:
            ax.plot([s[1] for s in samples], [s[2] for s in samples], "-", color=colors.get(name, "0.4"), lw=1.5,
                    label=f"{name} path")
            ax.plot(samples[-1][1], samples[-1][2], "o", color=colors.get(name, "0.4"))
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
    reaches = {machine.model_name: reach for machine, _, _, reach in excavators}
    info = {
        "labels": [(a.get_text(), a.get_window_extent(renderer)) for a in labels],
        "axes_fraction": ax.get_window_extent(renderer).width * ax.get_window_extent(renderer).height
        / (fig.bbox.width * fig.bbox.height),
        "reach": next(iter(reaches.values()), None),
        "reaches": reaches,
        "drawn": [machine.model_name for machine, *_ in excavators] + [machine.model_name for machine, _ in placed],
        "colors": colors,
        "legend": [t.get_text() for t in fig.legends[0].get_texts()],
    }
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return info
