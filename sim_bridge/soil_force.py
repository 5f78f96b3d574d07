"""Soil-tool cutting force: Reece's fundamental earthmoving equation with McKyes' wedge factors, vectorised.

The plant calls :func:`tool_force` (or :func:`fee_force`) once per physics step for every tool that cuts the
height field (excavator buckets, dozer blades); each argument is a scalar or an array over the tools, so one call
serves every machine. Pure numpy, no state.

Model
-----
Reece's fundamental earthmoving equation (Reece 1964, "The fundamental equation of earth-moving mechanics",
Proc. Inst. Mech. Eng. 179(3F)) gives the passive force P of a flat tool of width w cutting at depth d::

    P = (gamma d^2 N_gamma + c d N_c + q d N_q + c_a d N_a + rho v^2 d N_v) * w

with gamma = rho g the soil's unit weight, c its cohesion, q a surcharge pressure on the soil surface in front of
the tool, c_a the soil-tool adhesion, v the tool speed. The factors come from the force balance of a rigid soil
wedge between the tool (rake alpha from the horizontal) and a planar failure surface at angle beta from the
horizontal, with internal friction phi and soil-tool friction delta (McKyes 1985, "Soil Cutting and Tillage",
Elsevier, ch. 4)::

    D       = cos(alpha + delta) + sin(alpha + delta) cot(beta + phi)
    N_gamma = (cot alpha + cot beta) / (2 D)
    N_c     = (1 + cot beta cot(beta + phi)) / D
    N_q     = (cot alpha + cot beta) / D
    N_a     = (1 - cot alpha cot(beta + phi)) / D
    N_v     = sin alpha cos phi / (sin(alpha + beta) sin(beta + phi) D)   (soil accelerated to v across the failure
                                                                           plane; McKyes' inertia term)

(N_v is McKyes' inertia term as the McKyesModel of senhoi/Lunar-Excavactor-Simulation ``excavation_force.py``
writes it, in another algebraic form.) The failure angle is the one the soil picks under passive failure: beta*
minimises P over beta in (0, 90 deg) where D > 0. P is evaluated on a 1-degree grid of beta for all tools at once
(matrix products over a cached basis), and beta* and P are the vertex of the parabola through the grid minimum
and its neighbours (the tests agree with a 0.01-degree scalar search to 1e-4 of P). The cost is a fixed number
of numpy calls, about the same for 1 and 10 tools (``python -m tests.bench soil_force``).
A wedge exists only for 0 < alpha < 180 deg - phi - delta; :func:`fee_force` refuses a rake outside
:func:`rake_range` (that interval less 2 degrees, where P diverges anyway).

P acts on the tool at delta from the tool's normal; the adhesion acts along the tool's contact length d/sin alpha.
The force the tool exerts on the soil is therefore, in the plane of motion (McKyes 1985)::

    H = P sin(alpha + delta) + c_a d w cot alpha      (along the motion)
    V = P cos(alpha + delta) - c_a d w                (upwards)

and the soil pushes back on the tool with -H (against the motion) and -V: for alpha + delta < 90 deg the soil
pulls the tool down into the cut, as a ripper tine is drawn in.

Luengo, Singh & Cannon 1998 ("Modeling and identification of soil-tool interaction in automated excavation",
IEEE/RSJ IROS 1998) use the same equation for an excavator bucket: the cutting edge as the tool, the bucket's
width as w, and the soil already in the bucket or heaped in front of it as surcharge. :func:`surcharge_pressure`
turns such a heap's height into q.

Penetration (:func:`penetration_force`, :func:`bearing_capacity`): a tool pressed down into the soil meets the
soil's bearing resistance, as a strip footing does. The ultimate bearing pressure of a footing of breadth B (along
the tool's motion) and length L (the cutting edge's width) with its base at depth D below the surrounding surface is
Terzaghi's superposition (Terzaghi 1943, "Theoretical Soil Mechanics", Wiley, ch. XVIII) with Meyerhof's factors
(Meyerhof 1951, "The ultimate bearing capacity of foundations", Geotechnique 2(4); Meyerhof 1963, "Some recent
research on the bearing capacity of foundations", Canadian Geotechnical Journal 1(1))::

    q_ult   = c N_c s_c + gamma D N_q s_q + 0.5 gamma B N_gamma s_gamma
    N_q     = exp(pi tan phi) tan^2(45 deg + phi / 2)        (Prandtl 1921, Reissner 1924)
    N_c     = (N_q - 1) cot phi
    N_gamma = (N_q - 1) tan(1.4 phi)                         (Meyerhof 1963)
    s_c     = 1 + 0.2 K_p B / L,  s_q = s_gamma = 1 + 0.1 K_p B / L,  K_p = tan^2(45 deg + phi / 2)

(Meyerhof's shape factors; his s_q = s_gamma = 1 for phi = 0 and the form above for phi >= 10 deg, linear in phi
between.) Meyerhof's depth factors (>= 1) are left out: the overburden term gamma D N_q already carries the depth,
and leaving them out keeps q_ult on the low side. Before the soil yields it is a Winkler spring: the pressure under
the tool is k_s times its penetration, k_s the modulus of subgrade reaction (Winkler 1867; values per soil from
Bowles 1996, "Foundation Analysis and Design", 5th ed., McGraw-Hill, table 9-1, in ``soil_types.yaml``). The
force on the tool is ``min(k_s delta, q_ult) B L`` upwards: a tool resting on the ground is held up to the bearing
capacity; pushed harder it sinks, and :func:`penetration_force` says by how much (``excess``: the plant removes that
soil from under the tool and displaces it beside, so volume stays conserved).

What is not modelled: side-wall friction and the three-dimensional side crescents of narrow tools, tooth geometry,
the weight of soil carried (the plant adds that mass separately), the inclination and eccentricity of the load on a
pressed tool (its bearing force is vertical), and consolidation or rate effects of the soil under a pressed tool.
Numbers are per unit: N, m, Pa, rad, m/s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import NamedTuple

import numpy as np

from sim_bridge.errors import SimConfigError
from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_common.schema import load_schema, setting

__all__ = [
    "GRAVITY", "FeeForce", "Penetration", "SoilParams", "bearing_capacity", "bearing_factors", "bearing_terms",
    "fee_force", "load_soil_types", "penetration_force", "rake_range", "surcharge_pressure", "tool_force",
]

GRAVITY = 9.81  # [m/s^2]

# The beta grid: 1 degree is fine enough that the parabola through the three points at the minimum lands within
# a few hundredths of a degree of beta*, and coarse enough that ten tools cost one (10, 89) array per term.
_BETA_STEP = math.radians(1.0)
_BETA_GRID = np.arange(1, 90) * _BETA_STEP
_OUT = 1e300  # P where there is no wedge: finite, so the parabola below needs no inf arithmetic


@dataclass(frozen=True)
class SoilParams:
    """A soil for the earthmoving equation (SI units, angles in radians).

    ``unit_weight`` is gamma = rho g [N/m^3]; ``cohesion`` c [Pa]; ``phi`` the internal friction angle;
    ``delta`` the soil-tool friction angle; ``adhesion`` c_a [Pa]; ``surcharge`` a standing surface pressure q
    [Pa] added to each tool's own; ``subgrade_modulus`` k_s [N/m^3] of the soil under a pressed tool (None: not
    known, :func:`penetration_force` refuses the soil); ``source`` where the figures come from.
    """

    unit_weight: float
    cohesion: float
    phi: float
    delta: float
    adhesion: float = 0.0
    surcharge: float = 0.0
    name: str = ""
    source: str = ""
    subgrade_modulus: float | None = None

    def __post_init__(self) -> None:
        checks = (
            ("unit_weight", self.unit_weight > 0.0, "must be > 0 N/m^3"),
            ("cohesion", self.cohesion >= 0.0, "must be >= 0 Pa"),
            ("phi", 0.0 < self.phi < math.pi / 2, "must be in (0, pi/2) rad"),
            ("delta", 0.0 <= self.delta < math.pi / 2, "must be in [0, pi/2) rad"),
            ("adhesion", self.adhesion >= 0.0, "must be >= 0 Pa"),
            ("surcharge", self.surcharge >= 0.0, "must be >= 0 Pa"),
            ("subgrade_modulus", self.subgrade_modulus is None or self.subgrade_modulus > 0.0, "must be > 0 N/m^3"),
        )
        for field, ok, problem in checks:
            if not (ok and math.isfinite(getattr(self, field) or 0.0)):
                raise ValueError(f"soil {self.name or '<unnamed>'}: {field} {problem}, got {getattr(self, field)!r}")

    @property
    def density(self) -> float:
        """Bulk density rho [kg/m^3] (unit weight / g)."""
        return self.unit_weight / GRAVITY


class FeeForce(NamedTuple):
    """Per tool (arrays of the broadcast shape of the inputs): the soil's force on the tool in its plane of motion.

    ``horizontal`` [N] acts against the motion (>= 0 for a cutting tool); ``vertical`` [N] is upward positive
    (negative: the soil pulls the tool down); ``passive`` is P [N]; ``beta`` the failure angle [rad]. Tools not
    in the soil (depth <= 0) get zeros everywhere.
    """

    horizontal: np.ndarray
    vertical: np.ndarray
    passive: np.ndarray
    beta: np.ndarray


def rake_range(soil: SoilParams) -> tuple[float, float]:
    """The open interval of rakes [rad] fee_force accepts: (0, pi - phi - delta - 2 deg).

    A wedge needs beta < pi - alpha - delta - phi; near that limit it flattens and P diverges, and the 2 degrees
    keep at least one point of the 1-degree beta grid inside.
    """
    return 0.0, math.pi - soil.phi - soil.delta - 2.0 * _BETA_STEP


def surcharge_pressure(soil: SoilParams, height: np.ndarray | float) -> np.ndarray:
    """q [Pa] of a soil heap ``height`` [m] standing on the surface in front of the tool (negative heights: 0)."""
    return soil.unit_weight * np.maximum(np.asarray(height, dtype=float), 0.0)


class _Grid(NamedTuple):
    """Trigonometry of the beta grid for one soil, as rows the per-tool coefficients multiply (matrix products)."""

    offsets: np.ndarray  # (4, 1): sin(alpha + these) = cos a, sin a, cos(a + delta), sin(a + delta)
    linear: np.ndarray  # (4, M): 1, cot beta, 1 + cot beta cot(beta + phi), cot(beta + phi)
    denominator: np.ndarray  # (2, M): 1, cot(beta + phi) -> D = [cos(a + d), sin(a + d)] @ this


@functools.lru_cache(maxsize=32)
def _grid(phi: float, delta: float) -> _Grid:
    b = _BETA_GRID
    cot_b, cot_bp = 1.0 / np.tan(b), 1.0 / np.tan(b + phi)
    ones = np.ones_like(b)
    offsets = np.array([[math.pi / 2], [0.0], [delta + math.pi / 2], [delta]])
    return _Grid(offsets, np.stack([ones, cot_b, 1.0 + cot_b * cot_bp, cot_bp]), np.stack([ones, cot_bp]))


def _bad_input(alpha, d, w, q, v, cut, soil: SoilParams) -> str:
    """The one-line reason fee_force refuses its input (called only once a quick check failed)."""
    for name, arr, lo in (("rake", alpha, -np.inf), ("depth", d, -np.inf), ("width", w, 0.0), ("surcharge", q, 0.0),
                          ("speed", v, 0.0)):
        bad = np.flatnonzero(~(np.isfinite(arr) & (arr >= lo)))
        if bad.size:
            need = "finite" if lo < 0.0 else "finite and >= 0"
            return f"fee_force: tool {int(bad[0])}: {name} must be {need}, got {float(arr[bad[0]])!r}"
    lo, hi = rake_range(soil)
    i = int(np.flatnonzero(cut & ~((alpha > lo) & (alpha < hi)))[0])
    return (f"fee_force: tool {i}: rake {math.degrees(alpha[i]):.1f} deg has no failure wedge in soil "
            f"{soil.name or '<unnamed>'}; expected 0 < rake < {math.degrees(hi):.1f} deg")


def fee_force(soil: SoilParams, rake, depth, width, *, surcharge=0.0, speed=0.0) -> FeeForce:
    """The earthmoving equation for every tool (see the module docstring).

    Args:
        soil: the soil cut.
        rake: alpha [rad], the tool's angle from the horizontal on the side of the uncut soil.
        depth: d [m], how deep the cutting edge is below the soil surface; <= 0 gives zero force.
        width: w [m].
        surcharge: q [Pa] on the surface in front of the tool, added to ``soil.surcharge``
            (:func:`surcharge_pressure` converts a heap height).
        speed: v [m/s] of the tool along its motion (the inertia term).

    All but ``soil`` broadcast against each other (scalars or 1-D arrays over the tools).

    Raises:
        ValueError: a cutting tool's rake is outside :func:`rake_range` (one line naming the tool's index), or a
            width, surcharge or speed is negative or not finite.
    """
    # Written for few numpy calls (each costs about a microsecond whatever the tool count): the inputs in one
    # (5, n) array, the four sines in one call, P(beta) as matrix products over the cached beta basis.
    args = [a if isinstance(a, (float, int)) else np.asarray(a, dtype=float)
            for a in (rake, depth, width, surcharge, speed)]
    lengths = {a.shape[0] if a.ndim else 1 for a in args if isinstance(a, np.ndarray) and a.ndim <= 1}
    n = max(lengths, default=1)
    if len(lengths - {1}) > 1 or any(isinstance(a, np.ndarray) and a.ndim > 1 for a in args):
        shapes = [np.shape(a) for a in args]
        raise ValueError(f"fee_force: rake, depth, width, surcharge and speed must be scalars or 1-D arrays of one "
                         f"length, got shapes {shapes}")
    x = np.empty((5, n))
    for row, a in zip(x, args, strict=True):
        row[...] = a
    alpha, d, w, q, v = x
    cut = d > 0.0
    # every term of P is proportional to d: tools out of the soil take the same path with d = 0 and a harmless
    # rake, and come out as exactly zero
    alpha = np.where(cut, alpha, 1.0)
    _, hi = rake_range(soil)
    if not (math.isfinite(x.sum()) and x[2:].min() >= 0.0 and (alpha * (hi - alpha)).min() > 0.0):
        raise ValueError(_bad_input(x[0], d, w, q, v, cut, soil))
    d = np.maximum(d, 0.0)
    g = _grid(soil.phi, soil.delta)
    trig = np.sin(alpha + g.offsets)  # rows: cos a, sin a, cos(a + delta), sin(a + delta)
    cos_a, sin_a, cos_ad, sin_ad = trig
    cot_a = cos_a / sin_a
    # P(beta) per unit width = (coefficients @ basis) / D, the factors of the module docstring multiplied out
    a_term = (0.5 * soil.unit_weight * d + (q + soil.surcharge)) * d
    ca_term = soil.adhesion * d
    coef = np.empty((n, 4))
    coef[:, 0] = a_term * cot_a + ca_term
    coef[:, 1] = a_term
    coef[:, 2] = soil.cohesion * d
    coef[:, 3] = -ca_term * cot_a
    num = coef @ g.linear
    if v.any():
        # sin(alpha + beta) = sin alpha sin beta (cot alpha + cot beta), so N_v D = N_c D / (cot alpha + cot beta);
        # where that sum is <= 0, alpha + beta >= pi, D <= 0 as well and the entry is dropped below
        u = np.maximum(cot_a[:, None] + g.linear[1], 1e-12)
        num += (soil.density * v * v * d)[:, None] * g.linear[2] / u
    den = trig[2:].T @ g.denominator  # D of the docstring
    # D > 0 exactly for beta < pi - alpha - delta - phi, a prefix of the grid that rake_range keeps non-empty;
    # the rest, and a column on either side, hold _OUT so the neighbours of any minimum exist
    m = _BETA_GRID.size
    p = np.empty((n, m + 2))
    p[:, 0] = p[:, -1] = _OUT
    inner = p[:, 1:-1]
    np.divide(num, np.maximum(den, 1e-9), out=inner)
    inner[den <= 1e-9] = _OUT
    i = np.argmin(p, axis=1)
    k = np.arange(0, n * (m + 2), m + 2) + i
    flat = p.ravel()
    f0, fl, fr = flat[k], flat[k - 1], flat[k + 1]
    # a parabola through the grid minimum and its neighbours (a neighbour without a wedge keeps the grid point);
    # f0 <= fl, fr keeps the vertex within half a step
    curv = fl - 2.0 * f0 + fr
    ok = (np.maximum(fl, fr) < _OUT) & (curv > 0.0)
    slope = np.where(ok, fl - fr, 0.0)
    shift = 0.5 * slope / np.where(ok, curv, 1.0)
    beta = ((i - 1 + shift) * _BETA_STEP + _BETA_GRID[0]) * cut
    passive = (f0 - 0.25 * slope * shift) * w
    adhesion = ca_term * w
    return FeeForce(passive * sin_ad + adhesion * cot_a, adhesion - passive * cos_ad, passive, beta)


def tool_force(soil: SoilParams, velocity, rake, depth, width, *, surcharge=0.0, v_eps: float = 0.02) -> np.ndarray:
    """World-frame force [N] of the soil on each tool moving with ``velocity`` (shape (3,) or (n, 3), z up).

    The horizontal part opposes the velocity's horizontal direction with :func:`fee_force`'s ``horizontal``; the
    vertical part is its ``vertical``; the speed term uses the horizontal speed. ``rake``, ``depth``, ``width``
    and ``surcharge`` are as in :func:`fee_force` (the rake measured in the vertical plane of the motion).

    Below ``v_eps`` [m/s] of horizontal speed the force scales down linearly to zero at rest: a stationary tool
    has no direction to resist, and the ramp keeps an explicit 10 ms step from reversing a slow tool (a resisting
    force larger than what stops it in one step). A stalled tool therefore creeps at most at v_eps times the
    ratio of its drive force to the soil's resistance. Returns shape (n, 3).
    """
    vel = np.asarray(velocity, dtype=float)
    vel = vel.reshape(1, 3) if vel.shape == (3,) else vel
    if vel.ndim != 2 or vel.shape[1] != 3 or not math.isfinite(vel.sum()):
        raise ValueError(f"tool_force: velocity must be finite with shape (3,) or (n, 3), got shape {vel.shape}")
    if not v_eps > 0.0:
        raise ValueError(f"tool_force: v_eps must be > 0, got {v_eps!r}")
    speed = np.hypot(vel[:, 0], vel[:, 1])
    f = fee_force(soil, rake, depth, width, surcharge=surcharge, speed=speed)
    n = f.horizontal.shape[0]
    scale = np.minimum(speed * (1.0 / v_eps), 1.0)
    # -H along the unit horizontal direction; a tool at rest has vel = 0 there, so the floor only avoids 0/0
    along = (f.horizontal * scale / np.maximum(speed, 1e-300))[:, None]
    out = np.empty((n, 3))
    out[:, :2] = vel[:, :2] * -along
    out[:, 2] = f.vertical * scale
    return out


# --- penetration: bearing capacity (Terzaghi / Meyerhof) with a Winkler ramp -----------------------------------


class Penetration(NamedTuple):
    """Per tool (arrays of the broadcast shape of the inputs): the soil's resistance to a tool pressed into it.

    ``force`` [N] upwards on the tool, ``min(k_s delta, q_ult) B L`` (0 out of the soil); ``capacity`` [N] is
    q_ult B L at the tool's depth; ``excess`` [m] how far the tool is below the penetration at which the soil yields
    (``capacity / (k_s B L)``): the soil under it has failed by that much, and the plant lowers the surface under the
    tool by it (0 while the soil holds).
    """

    force: np.ndarray
    capacity: np.ndarray
    excess: np.ndarray


def bearing_factors(phi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N_c, N_q, N_gamma) for internal friction ``phi`` [rad] (scalar or array): Prandtl/Reissner's N_q and N_c,
    Meyerhof's (1963) N_gamma (see the module docstring). At phi -> 0 N_c tends to 2 + pi (Prandtl), N_q to 1 and
    N_gamma to 0.

    Raises:
        ValueError: phi outside (0, 60 deg] (tan(1.4 phi) leaves the range the factors were fitted for).
    """
    phi = np.asarray(phi, dtype=float)
    if not (np.all(np.isfinite(phi)) and np.all(phi > 0.0) and np.all(phi <= math.radians(60.0) + 1e-12)):
        raise ValueError(f"bearing_factors: phi must be in (0, 60 deg], got {np.degrees(phi)!r} deg")
    t = np.tan(phi)
    n_q = np.exp(math.pi * t) * np.tan(math.pi / 4 + phi / 2) ** 2
    n_c = (n_q - 1.0) / t
    n_gamma = (n_q - 1.0) * np.tan(1.4 * phi)
    return n_c, n_q, n_gamma


def bearing_terms(soil: SoilParams, breadth, length) -> tuple[np.ndarray, np.ndarray]:
    """(q0 [Pa], dq/dD [Pa/m]) of the ultimate bearing pressure ``q_ult = q0 + dq/dD * D`` of a footing of
    ``breadth`` B x ``length`` L [m] in ``soil`` (Terzaghi's superposition, Meyerhof's factors and shape factors,
    the module docstring): q0 = c N_c s_c + 0.5 gamma B N_gamma s_gamma, dq/dD = gamma N_q s_q. B and L broadcast;
    B / L is taken at most 1 (a footing's breadth is its shorter side)."""
    b = np.asarray(breadth, dtype=float)
    ratio = np.minimum(b / np.asarray(length, dtype=float), 1.0)
    n_c, n_q, n_gamma = bearing_factors(soil.phi)
    k_p = math.tan(math.pi / 4 + soil.phi / 2) ** 2
    s_c = 1.0 + 0.2 * k_p * ratio
    # Meyerhof: s_q = s_gamma = 1 for phi = 0, 1 + 0.1 K_p B/L for phi >= 10 deg; linear in phi between
    s_q = 1.0 + 0.1 * k_p * ratio * min(1.0, soil.phi / math.radians(10.0))
    q0 = soil.cohesion * n_c * s_c + 0.5 * soil.unit_weight * b * n_gamma * s_q
    return q0, soil.unit_weight * n_q * s_q


def bearing_capacity(soil: SoilParams, depth, breadth, length) -> np.ndarray:
    """q_ult [Pa] under a footing ``breadth`` x ``length`` [m] whose base is ``depth`` [m] below the surrounding
    surface (negative depths count as 0); all three broadcast (scalars or 1-D arrays over the tools)."""
    q0, per_depth = bearing_terms(soil, breadth, length)
    return q0 + per_depth * np.maximum(np.asarray(depth, dtype=float), 0.0)


def penetration_force(soil: SoilParams, penetration, depth, breadth, length) -> Penetration:
    """The soil's bearing resistance to each tool pressed into it (see the module docstring).

    Args:
        soil: the soil, with its ``subgrade_modulus``.
        penetration: delta [m], how far the tool's bottom is below the soil surface directly under it (the soil it
            compresses); <= 0: the tool is not in contact, no force.
        depth: D [m], its bottom below the surrounding surface (the overburden of the bearing capacity); taken at
            least ``penetration``.
        breadth: B [m], the contact's extent along the tool's motion (its thickness, or the floor it rests on).
        length: L [m], the contact's extent across (the cutting edge's width).

    All but ``soil`` broadcast (scalars or 1-D arrays over the tools).

    Raises:
        ValueError: the soil has no subgrade modulus, or a breadth or length is not finite and > 0.
    """
    if soil.subgrade_modulus is None:
        raise ValueError(f"penetration_force: soil {soil.name or '<unnamed>'} has no subgrade_modulus "
                         "(soil_types.yaml subgrade_modulus_mn_m3)")
    delta = np.asarray(penetration, dtype=float)
    b, w = np.asarray(breadth, dtype=float), np.asarray(length, dtype=float)
    if not (np.all(np.isfinite(b)) and np.all(b > 0.0) and np.all(np.isfinite(w)) and np.all(w > 0.0)):
        raise ValueError(f"penetration_force: breadth and length must be finite and > 0, got {b!r}, {w!r}")
    area = b * w
    capacity = bearing_capacity(soil, np.maximum(depth, delta), b, w) * area
    spring = soil.subgrade_modulus * area
    inside = delta > 0.0
    force = np.where(inside, np.minimum(spring * np.maximum(delta, 0.0), capacity), 0.0)
    excess = np.where(inside, np.maximum(delta - capacity / spring, 0.0), 0.0)
    return Penetration(force, capacity, excess)


# --- soil types from config/sim/soil_types.yaml ------------------------------------------------------------------


@dataclass(frozen=True)
class _SoilEntry:
    """One soil of the YAML, in the units its sources quote; exactly one of unit weight and bulk density."""

    source: str
    cohesion_kpa: float = setting(lo=0.0, hi=1000.0)
    friction_deg: float = setting(lo=1.0, hi=60.0)
    tool_friction_deg: float = setting(lo=0.0, hi=60.0)
    unit_weight_kn_m3: float | None = setting(None, lo=5.0, hi=30.0)
    density_kg_m3: float | None = setting(None, lo=500.0, hi=3000.0)
    adhesion_kpa: float = setting(0.0, lo=0.0, hi=1000.0)
    surcharge_kpa: float = setting(0.0, lo=0.0, hi=1000.0)
    subgrade_modulus_mn_m3: float | None = setting(None, lo=1.0, hi=500.0, doc="k_s [MN/m^3] (Bowles table 9-1)")

    def __post_init__(self) -> None:
        if (self.unit_weight_kn_m3 is None) == (self.density_kg_m3 is None):
            raise ValueError("give exactly one of unit_weight_kn_m3 and density_kg_m3")


@dataclass(frozen=True)
class _SoilFile:
    soil_types: dict[str, _SoilEntry]


def load_soil_types(path: str | Path | None = None) -> MappingProxyType:
    """The soils of ``path`` (default ``config/sim/soil_types.yaml``) as ``{name: SoilParams}``.

    Raises:
        SimConfigError: one line ``file:line: soil_types.<name>.<key>: problem`` for an unknown or missing key, a
            value out of its bounds, or both (or neither) of unit weight and density.
    """
    path = Path(path) if path else config_path("sim", "soil_types.yaml")
    try:
        data = load_schema(_SoilFile, path)
    except ConfigError as exc:
        raise SimConfigError(str(exc)) from None
    soils = {}
    for name, e in data.soil_types.items():
        gamma = e.unit_weight_kn_m3 * 1e3 if e.unit_weight_kn_m3 is not None else e.density_kg_m3 * GRAVITY
        try:
            soils[name] = SoilParams(
                unit_weight=gamma, cohesion=e.cohesion_kpa * 1e3, phi=math.radians(e.friction_deg),
                delta=math.radians(e.tool_friction_deg), adhesion=e.adhesion_kpa * 1e3,
                surcharge=e.surcharge_kpa * 1e3, name=name, source=" ".join(e.source.split()),
                subgrade_modulus=(e.subgrade_modulus_mn_m3 * 1e6 if e.subgrade_modulus_mn_m3 is not None else None),
            )
        except ValueError as exc:
            raise SimConfigError(f"{path}: soil_types.{name}: {exc}") from None
    return MappingProxyType(soils)
