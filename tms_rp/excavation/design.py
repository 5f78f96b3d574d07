"""A design surface as data: what the ground of an area must look like when the excavation is done.

A :class:`Design` is a name, a kind, the frame (``map``, always), an area polygon (the cells the error is judged
on) and a target height function ``z(x, y)`` [m, map frame] built from the kind's parameters. Three kinds:

* ``trench``: a straight axis ``start`` -> ``end``; a flat bottom ``width`` wide over the axis, ``depth`` below the
  original ground ``ground_z`` (or at the absolute ``bottom_z``); walls rising ``1 / side_slope`` per metre
  (``side_slope`` is the horizontal run per metre of depth, H:V; 0 = vertical walls) up to ``ground_z``. The walls
  also close both ends.
* ``embankment`` (two-faced): a crest on the line ``start`` -> ``end``, ``crest_width`` wide, ``height`` above
  ``base_z``; the face left of the line (seen from ``start`` towards ``end``) falls with ``slope_left`` (H:V), the
  right face with ``slope_right``; round the ends the nearer face's slope continues as a half cone.
* ``s_curve``: an embankment (same profile) whose crest follows an S: from ``start`` along ``heading`` [rad] for
  ``length`` [m], offset to the left by ``amplitude * sin(2 pi t / length)`` at the distance ``t`` along.

Outside the trench and the embankment body the target is the surrounding ground (``ground_z`` / ``base_z``). The
area is the footprint grown by ``margin`` [m] (an apron around it, where the ground must be left flat), or the
polygon given as ``area``.

The DB document (:meth:`Design.to_dict` / :meth:`Design.from_dict`) is a flat mapping; points are ``[x, y]``:

=================  ==========================================================================================
key                meaning (kinds)
=================  ==========================================================================================
``name``           the design's name (all; non-empty)
``kind``           ``trench``, ``embankment`` or ``s_curve``
``frame``          ``map`` (optional; no other frame is accepted)
``area``           optional polygon ``[[x, y], ...]`` (>= 3 points, non-zero area); default: footprint + margin
``margin``         [m] apron around the footprint in the default area (default 0; 0..50)
``start``, ``end`` axis of a trench, crest line of an embankment (``end`` not for s_curve)
``width``          [m] trench bottom width (0.1..50)
``ground_z``       [m] the original ground the trench is cut into
``depth``          [m] trench bottom below ``ground_z`` (0.01..20); or ``bottom_z``, exactly one of the two
``bottom_z``       [m] absolute trench bottom height (below ``ground_z``, at most 20 m)
``side_slope``     trench wall run per metre of depth, H:V (default 0 = vertical; 0..10)
``base_z``         [m] the ground an embankment stands on
``crest_width``    [m] (0..50)
``height``         [m] crest above ``base_z`` (0.01..20)
``slope_left``,    face slopes H:V (0.1..10)
``slope_right``
``heading``        [rad] s_curve axis direction (-2 pi..2 pi)
``length``         [m] s_curve axis length (0.5..1000)
``amplitude``      [m] s_curve lateral swing (0..length / 2)
=================  ==========================================================================================

A key the kind does not have, a missing required key, a non-number, NaN, or a value out of its range is refused
with a :class:`DesignError` naming the design and the key.

Grids follow the terrain heightmaps of the sensing package: ``z[row, col]`` in image order, row 0 the north edge
(``y_max``), col 0 the west edge (``x_min``), cells covering ``[x_min, x_max] x [y_min, y_max]`` (any object with
those attributes; a sensed heightmap is one). Pure numpy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from tms_common.errors import TmsError

__all__ = [
    "FRAME", "KINDS", "DesignError", "Design", "Grid", "GridLike", "Sampled", "SurfaceError", "cell_centres",
    "trench", "embankment", "s_curve", "surface_error",
]

FRAME = "map"
KINDS = ("trench", "embankment", "s_curve")
#: segments of the sampled S-shaped crest line (a multiple of 4: the S's crests and turning points are vertices)
S_SEGMENTS = 256
_COORD = 1.0e6  # [m] bound of any coordinate or height
_REQUIRED = object()


class DesignError(TmsError, ValueError):
    """A design document or a design's use is wrong; the message names the design and the key."""


# ---- grids -------------------------------------------------------------------------------------------------------
class GridLike(Protocol):
    z: np.ndarray
    x_min: float
    y_min: float
    x_max: float
    y_max: float


@dataclass(frozen=True)
class Grid:
    """A height grid in the heightmaps' convention (row 0 = north edge ``y_max``, col 0 = west edge ``x_min``)."""

    z: np.ndarray
    x_min: float
    y_min: float
    x_max: float
    y_max: float


def _geometry(grid: GridLike) -> tuple[int, int, float, float]:
    z = np.asarray(grid.z)
    if z.ndim != 2 or z.size == 0:
        raise DesignError(f"terrain grid: heights must be a non-empty 2-D array, got shape {z.shape}")
    if not (grid.x_max > grid.x_min and grid.y_max > grid.y_min):
        raise DesignError(f"terrain grid: empty extent x [{grid.x_min}, {grid.x_max}] y [{grid.y_min}, {grid.y_max}]")
    rows, cols = z.shape
    return rows, cols, (grid.x_max - grid.x_min) / cols, (grid.y_max - grid.y_min) / rows


def cell_centres(grid: GridLike) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre map coordinates ``(X, Y)``, each ``(rows, cols)``, in image order (as the heightmaps')."""
    rows, cols, cx, cy = _geometry(grid)
    xs = grid.x_min + (np.arange(cols) + 0.5) * cx
    ys = grid.y_max - (np.arange(rows) + 0.5) * cy
    return np.meshgrid(xs, ys)


@dataclass(frozen=True)
class Sampled:
    """A design on a grid: ``target[row, col]`` [m] at every cell centre, ``inside`` the cells of the design
    area, ``cell_area`` [m^2]."""

    target: np.ndarray
    inside: np.ndarray
    cell_area: float


# ---- geometry helpers --------------------------------------------------------------------------------------------
def _in_polygon(x: np.ndarray, y: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule: True where ``(x, y)`` lies inside the polygon ``(N, 2)``."""
    inside = np.zeros(np.shape(x), dtype=bool)
    xj, yj = poly[-1]
    for xi, yi in poly:
        crosses = (yi > y) != (yj > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = (xj - xi) * (y - yi) / (yj - yi) + xi
        inside ^= crosses & (x < x_cross)
        xj, yj = xi, yi
    return inside


def _polygon_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def distance_to_polygon(x: np.ndarray, y: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance [m] from each point to the polygon's boundary (0 on it; the same inside and outside)."""
    pts = np.stack([np.ravel(x), np.ravel(y)], axis=1)
    best = np.full(len(pts), np.inf)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        ab = b - a
        t = np.clip((pts - a) @ ab / max(float(ab @ ab), 1e-18), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(pts - (a + t[:, None] * ab), axis=1))
    return best.reshape(np.shape(x))


def _polyline_distance(x: np.ndarray, y: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance to the polyline ``(N, 2)``, True where the point is left of the nearest segment)."""
    pts = np.stack([np.ravel(x), np.ravel(y)], axis=1)
    a, b = line[:-1], line[1:]
    ab = b - a
    ab2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    dist = np.empty(len(pts))
    left = np.empty(len(pts), dtype=bool)
    for lo in range(0, len(pts), 2048):
        p = pts[lo:lo + 2048]
        ap = p[:, None, :] - a[None, :, :]
        t = np.clip(np.einsum("mnk,nk->mn", ap, ab) / ab2, 0.0, 1.0)
        d = np.linalg.norm(ap - t[:, :, None] * ab[None, :, :], axis=2)
        k = np.argmin(d, axis=1)
        rows = np.arange(len(p))
        dist[lo:lo + 2048] = d[rows, k]
        cross = ab[k, 0] * ap[rows, k, 1] - ab[k, 1] * ap[rows, k, 0]
        left[lo:lo + 2048] = cross >= 0.0
    return dist.reshape(np.shape(x)), left.reshape(np.shape(x))


def _frame(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    d = end - start
    length = float(np.hypot(*d))
    u = d / length
    return u, np.array([-u[1], u[0]]), length


# ---- the document ------------------------------------------------------------------------------------------------
#: per kind: key -> (what, lo, hi, default); what is "point" or "number"; _REQUIRED = no default
_COMMON = {"margin": ("number", 0.0, 50.0, 0.0)}
_BODY = {
    "crest_width": ("number", 0.0, 50.0, _REQUIRED),
    "height": ("number", 0.01, 20.0, _REQUIRED),
    "base_z": ("number", -_COORD, _COORD, _REQUIRED),
    "slope_left": ("number", 0.1, 10.0, _REQUIRED),
    "slope_right": ("number", 0.1, 10.0, _REQUIRED),
}
_SPECS: dict[str, dict[str, tuple[str, float, float, Any]]] = {
    "trench": {
        "start": ("point", -_COORD, _COORD, _REQUIRED),
        "end": ("point", -_COORD, _COORD, _REQUIRED),
        "width": ("number", 0.1, 50.0, _REQUIRED),
        "ground_z": ("number", -_COORD, _COORD, _REQUIRED),
        "depth": ("number", 0.01, 20.0, None),
        "bottom_z": ("number", -_COORD, _COORD, None),
        "side_slope": ("number", 0.0, 10.0, 0.0),
        **_COMMON,
    },
    "embankment": {
        "start": ("point", -_COORD, _COORD, _REQUIRED),
        "end": ("point", -_COORD, _COORD, _REQUIRED),
        **_BODY,
        **_COMMON,
    },
    "s_curve": {
        "start": ("point", -_COORD, _COORD, _REQUIRED),
        "heading": ("number", -2.0 * math.pi, 2.0 * math.pi, _REQUIRED),
        "length": ("number", 0.5, 1000.0, _REQUIRED),
        "amplitude": ("number", 0.0, 500.0, _REQUIRED),
        **_BODY,
        **_COMMON,
    },
}
_TOP = ("name", "kind", "frame", "area")


def _number(value: Any, who: str, key: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DesignError(f"{who}: {key} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise DesignError(f"{who}: {key} must be finite, got {value!r}")
    if not lo <= v <= hi:
        raise DesignError(f"{who}: {key} = {v:g} is out of range [{lo:g}, {hi:g}]")
    return v


def _point(value: Any, who: str, key: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise DesignError(f"{who}: {key} must be a point [x, y], got {value!r}")
    return (_number(value[0], who, f"{key}[0]", -_COORD, _COORD), _number(value[1], who, f"{key}[1]", -_COORD, _COORD))


@dataclass(frozen=True)
class Design:
    """A design surface. Build it with :func:`trench`, :func:`embankment`, :func:`s_curve` or
    :meth:`from_dict` (which validate); ``params`` are the kind's keys with defaults filled in."""

    name: str
    kind: str
    params: Mapping[str, Any]
    area: tuple[tuple[float, float], ...]
    frame: str = FRAME
    _line: np.ndarray | None = field(default=None, compare=False, repr=False)

    # ------------------------------------------------------------------ the document
    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Design:
        """A design from its DB document; DesignError naming the design and the key on anything wrong."""
        if not isinstance(doc, Mapping):
            raise DesignError(f"design document must be a mapping, got {type(doc).__name__}")
        name = doc.get("name")
        if not isinstance(name, str) or not name.strip():
            raise DesignError(f"design {name!r}: name must be a non-empty string")
        who = f"design {name!r}"
        kind = doc.get("kind")
        if kind not in _SPECS:
            raise DesignError(f"{who}: kind must be one of {list(KINDS)}, got {kind!r}")
        who = f"design {name!r} ({kind})"
        spec = _SPECS[kind]
        for key in doc:
            if key not in spec and key not in _TOP:
                raise DesignError(f"{who}: unknown key {key!r} (a {kind} has {sorted([*_TOP, *spec])})")
        frame = doc.get("frame", FRAME)
        if frame != FRAME:
            raise DesignError(f"{who}: frame must be {FRAME!r}, got {frame!r}")
        params: dict[str, Any] = {}
        for key, (what, lo, hi, default) in spec.items():
            if key not in doc or doc[key] is None:
                if default is _REQUIRED:
                    raise DesignError(f"{who}: missing key {key!r}")
                if default is not None:
                    params[key] = default
                continue
            params[key] = _point(doc[key], who, key) if what == "point" else _number(doc[key], who, key, lo, hi)
        _check_kind(who, kind, params)
        area = _area_from(doc["area"], who) if doc.get("area") is not None else _default_area(kind, params)
        return cls(name=name, kind=kind, params=params, area=area, frame=FRAME, _line=_crest_line(kind, params))

    def to_dict(self) -> dict[str, Any]:
        """The DB document: every key of the kind (defaults filled in) and the area polygon; plain lists/floats."""
        doc: dict[str, Any] = {"name": self.name, "kind": self.kind, "frame": self.frame}
        for key, value in self.params.items():
            doc[key] = list(value) if isinstance(value, tuple) else value
        doc["area"] = [list(p) for p in self.area]
        return doc

    # ------------------------------------------------------------------ the surface
    def height(self, x: Any, y: Any) -> np.ndarray:
        """Target height [m] at map points ``(x, y)`` (arrays of one shape, or scalars)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        p = self.params
        if self.kind == "trench":
            start, end = np.array(p["start"]), np.array(p["end"])
            u, n, length = _frame(start, end)
            dx, dy = x - start[0], y - start[1]
            t = dx * u[0] + dy * u[1]
            s = dx * n[0] + dy * n[1]
            out = np.hypot(np.maximum(np.abs(s) - p["width"] / 2.0, 0.0), np.maximum(np.maximum(-t, t - length), 0.0))
            ground, bottom = p["ground_z"], _bottom(p)
            if p["side_slope"] > 0:
                return np.minimum(ground, bottom + out / p["side_slope"])
            return np.where(out <= 0.0, bottom, ground)
        line = self._line if self._line is not None else _crest_line(self.kind, p)
        assert line is not None
        dist, left = _polyline_distance(x, y, line)
        run = np.maximum(dist - p["crest_width"] / 2.0, 0.0)
        slope = np.where(left, p["slope_left"], p["slope_right"])
        return p["base_z"] + np.maximum(p["height"] - run / slope, 0.0)

    def contains(self, x: Any, y: Any) -> np.ndarray:
        """True where map points lie inside the design area."""
        return _in_polygon(np.asarray(x, dtype=float), np.asarray(y, dtype=float), np.array(self.area))

    def sample(self, grid: GridLike) -> Sampled:
        """The design on the cell centres of ``grid`` (the heightmaps' convention); DesignError when the area
        holds no cell centre of the grid."""
        rows, cols, cx, cy = _geometry(grid)
        xc, yc = cell_centres(grid)
        inside = self.contains(xc, yc)
        if not inside.any():
            raise DesignError(f"design {self.name!r}: its area holds no cell of the grid x [{grid.x_min:g}, "
                              f"{grid.x_max:g}] y [{grid.y_min:g}, {grid.y_max:g}]")
        return Sampled(target=self.height(xc, yc), inside=inside, cell_area=cx * cy)


def _bottom(p: Mapping[str, Any]) -> float:
    return p["ground_z"] - p["depth"] if "depth" in p else p["bottom_z"]


def _check_kind(who: str, kind: str, p: dict[str, Any]) -> None:
    if kind in ("trench", "embankment") and math.dist(p["start"], p["end"]) < 0.1:
        raise DesignError(f"{who}: start and end are {math.dist(p['start'], p['end']):.3f} m apart, need >= 0.1 m")
    if kind == "trench":
        if ("depth" in p) == ("bottom_z" in p):
            raise DesignError(f"{who}: give exactly one of 'depth' and 'bottom_z'")
        if "bottom_z" in p and not 0.01 <= p["ground_z"] - p["bottom_z"] <= 20.0:
            raise DesignError(f"{who}: bottom_z = {p['bottom_z']:g} must lie 0.01..20 m below ground_z = "
                              f"{p['ground_z']:g}")
    if kind == "s_curve" and p["amplitude"] > p["length"] / 2.0:
        raise DesignError(f"{who}: amplitude = {p['amplitude']:g} is out of range [0, length / 2 = "
                          f"{p['length'] / 2.0:g}]")


def _area_from(value: Any, who: str) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, (list, tuple)) or len(value) < 3:
        raise DesignError(f"{who}: area must be a polygon of at least 3 points [x, y], got {value!r}")
    pts = tuple(_point(v, who, f"area[{k}]") for k, v in enumerate(value))
    if abs(_polygon_area(np.array(pts))) < 1e-6:
        raise DesignError(f"{who}: area polygon has no area")
    return pts


def _rectangle(origin: np.ndarray, u: np.ndarray, n: np.ndarray, t0: float, t1: float, s0: float,
               s1: float) -> tuple[tuple[float, float], ...]:
    corners = [origin + t * u + s * n for t, s in ((t0, s0), (t1, s0), (t1, s1), (t0, s1))]
    return tuple((float(c[0]), float(c[1])) for c in corners)


def _default_area(kind: str, p: Mapping[str, Any]) -> tuple[tuple[float, float], ...]:
    """The footprint (where the target differs from the surrounding ground) grown by ``margin``."""
    m = p["margin"]
    if kind == "trench":
        start, end = np.array(p["start"]), np.array(p["end"])
        u, n, length = _frame(start, end)
        g = p["side_slope"] * (p["ground_z"] - _bottom(p)) + m
        w = p["width"] / 2.0 + g
        return _rectangle(start, u, n, -g, length + g, -w, w)
    left = p["crest_width"] / 2.0 + p["height"] * p["slope_left"] + m
    right = p["crest_width"] / 2.0 + p["height"] * p["slope_right"] + m
    ends = max(left, right)
    if kind == "embankment":
        start, end = np.array(p["start"]), np.array(p["end"])
        u, n, length = _frame(start, end)
        return _rectangle(start, u, n, -ends, length + ends, -right, left)
    u = np.array([math.cos(p["heading"]), math.sin(p["heading"])])
    n = np.array([-u[1], u[0]])
    a = p["amplitude"]
    return _rectangle(np.array(p["start"]), u, n, -ends, p["length"] + ends, -a - right, a + left)


def _crest_line(kind: str, p: Mapping[str, Any]) -> np.ndarray | None:
    if kind == "embankment":
        return np.array([p["start"], p["end"]], dtype=float)
    if kind == "s_curve":
        t = np.linspace(0.0, p["length"], S_SEGMENTS + 1)
        u = np.array([math.cos(p["heading"]), math.sin(p["heading"])])
        n = np.array([-u[1], u[0]])
        off = p["amplitude"] * np.sin(2.0 * math.pi * t / p["length"])
        return np.array(p["start"])[None, :] + t[:, None] * u[None, :] + off[:, None] * n[None, :]
    return None


# ---- constructors from parameters ----------------------------------------------------------------------------------
def _build(name: str, kind: str, area: Any, **params: Any) -> Design:
    doc = {"name": name, "kind": kind, **{k: v for k, v in params.items() if v is not None}}
    if area is not None:
        doc["area"] = area
    return Design.from_dict(doc)


def trench(name: str, *, start: Any, end: Any, width: float, ground_z: float, depth: float | None = None,
           bottom_z: float | None = None, side_slope: float = 0.0, margin: float = 0.0, area: Any = None) -> Design:
    """A straight trench (see the module docstring); exactly one of ``depth`` and ``bottom_z``."""
    return _build(name, "trench", area, start=start, end=end, width=width, ground_z=ground_z, depth=depth,
                  bottom_z=bottom_z, side_slope=side_slope, margin=margin)


def embankment(name: str, *, start: Any, end: Any, crest_width: float, height: float, base_z: float,
               slope_left: float, slope_right: float, margin: float = 0.0, area: Any = None) -> Design:
    """A two-faced embankment on the crest line ``start`` -> ``end``."""
    return _build(name, "embankment", area, start=start, end=end, crest_width=crest_width, height=height,
                  base_z=base_z, slope_left=slope_left, slope_right=slope_right, margin=margin)


def s_curve(name: str, *, start: Any, heading: float, length: float, amplitude: float, crest_width: float,
            height: float, base_z: float, slope_left: float, slope_right: float, margin: float = 0.0,
            area: Any = None) -> Design:
    """An embankment whose crest follows an S (one sine period of ``amplitude`` over ``length``)."""
    return _build(name, "s_curve", area, start=start, heading=heading, length=length, amplitude=amplitude,
                  crest_width=crest_width, height=height, base_z=base_z, slope_left=slope_left,
                  slope_right=slope_right, margin=margin)


# ---- error metrics -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SurfaceError:
    """The sensed surface against the design over the design area (error = sensed - design, + = material above).

    ``mae``, ``p95`` (of the absolute error), ``max_abs``, ``signed_mean`` [m]; ``cut_volume`` (material above the
    design still to remove) and ``fill_volume`` (missing below it) [m^3]; ``cells`` in the area; ``error`` the
    per-cell map ``(rows, cols)`` in image order, NaN outside the area."""

    mae: float
    p95: float
    max_abs: float
    signed_mean: float
    cut_volume: float
    fill_volume: float
    cells: int
    error: np.ndarray = field(repr=False, compare=False)

    def summary(self) -> str:
        return (f"MAE {self.mae * 100:.2f} cm, p95 {self.p95 * 100:.2f} cm, max {self.max_abs * 100:.2f} cm, "
                f"signed mean {self.signed_mean * 100:+.2f} cm, cut left {self.cut_volume:.3f} m3, "
                f"fill left {self.fill_volume:.3f} m3 over {self.cells} cells")


def surface_error(design: Design, terrain_grid: GridLike, *, sampled: Sampled | None = None) -> SurfaceError:
    """Error metrics of ``terrain_grid`` against ``design`` over the design area only (``sampled``: the design
    already sampled on this grid, to save the work)."""
    s = sampled if sampled is not None else design.sample(terrain_grid)
    z = np.asarray(terrain_grid.z, dtype=float)
    if z.shape != s.target.shape:
        raise DesignError(f"design {design.name!r}: sampled on a {s.target.shape} grid, terrain is {z.shape}")
    err = np.where(s.inside, z - s.target, np.nan)
    e = err[s.inside]
    if not np.all(np.isfinite(e)):
        raise DesignError(f"design {design.name!r}: the terrain has {int(np.sum(~np.isfinite(e)))} non-finite "
                          "heights in the design area")
    a = np.abs(e)
    return SurfaceError(mae=float(a.mean()), p95=float(np.percentile(a, 95)), max_abs=float(a.max()),
                        signed_mean=float(e.mean()), cut_volume=float(np.sum(np.maximum(e, 0.0)) * s.cell_area),
                        fill_volume=float(np.sum(np.maximum(-e, 0.0)) * s.cell_area), cells=int(e.size), error=err)
