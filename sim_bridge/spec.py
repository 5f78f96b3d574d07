"""What the plant is built from: its machines placed on the site, the soil grid and the sensor noise.

Frozen data only, built by :func:`sim_bridge.config.load_plant`. A machine of the plant is its tms_model
description (:class:`tms_model.machines.Machine`: geometry, hydraulics, soil handling, read once for every
package; the DBC of its bus too) plus what the plant alone decides for that one machine: its name on the site and
where it starts. Nothing of the description is copied, so the plant and the rest of the stack read the same
figures.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from sim_bridge.physics import PhysicsSpec
from sim_bridge.soil_force import SoilParams
from tms_common.schema import setting
from tms_model.machines import Machine
from tms_model.site import Site

__all__ = ["PlantMachine", "FineGrid", "SoilSpec", "SensorSpec", "PlantSpec", "fine_grid_problem"]


@dataclass(frozen=True)
class PlantMachine:
    """One machine of the plant.

    ``description`` is tms_model's, named ``name``; ``pose`` the initial base pose in map (x, y, yaw);
    ``start_joints`` the joint angles at start (the description's ``home_pose``, for the digging excavator with the
    plant YAML's ``initial_front`` over it).
    """

    name: str
    description: Machine
    pose: tuple[float, float, float]
    start_joints: Mapping[str, float]
    physics: PhysicsSpec  # the plant's model of its drives (``physics:`` of its YAML)

    @property
    def type(self) -> str:
        """The machine type (the plant profile that serves it, :mod:`sim_bridge.profiles`)."""
        return self.description.type


@dataclass(frozen=True)
class Pile:
    """A soil pile on the flat ground at the start (the plant YAML's ``soil.piles``): a truncated cone, as the
    site's mound, for scenarios that shape soil already there (an embankment cut from a pile)."""

    x: float
    y: float
    base_radius: float = setting(lo=0.05, doc="[m] at ground level")
    top_radius: float = setting(lo=0.0, doc="[m] flat top; 0 = a cone")
    height: float = setting(lo=0.0, doc="[m] above the ground")

    def __post_init__(self) -> None:
        if self.top_radius >= self.base_radius:
            raise ValueError(f"top_radius {self.top_radius} must be below base_radius {self.base_radius}")


@dataclass(frozen=True)
class FineGrid:
    """A finer patch of the soil grid where the tool works (the plant YAML's ``soil.grid.fine``).

    A rectangle of whole coarse cells (its edges on the coarse cell boundaries) at ``resolution``, which divides the
    coarse resolution a whole number of times: :func:`fine_grid_problem` says what is wrong otherwise.
    """

    x_min: float
    y_min: float
    size_x: float = setting(lo=0.0)
    size_y: float = setting(lo=0.0)
    resolution: float = setting(lo=0.005, hi=2.0, doc="[m] cell size inside the patch")


def _multiple(value: float, step: float, least: int) -> bool:
    """``value`` is ``k * step`` (to 1e-6 of a step) for a whole ``k >= least``."""
    k = round(value / step)
    return k >= least and abs(value - k * step) <= 1e-6 * step


def fine_grid_problem(x_min: float, y_min: float, size_x: float, size_y: float, resolution: float,
                      fine: FineGrid) -> str | None:
    """What is wrong with the patch ``fine`` on the grid (``x_min`` ... ``resolution``), as ``fine.<field>: problem``;
    None when it fits: inside the grid, edges on coarse cell boundaries, the coarse resolution a whole multiple of its
    own."""
    if not _multiple(resolution, fine.resolution, 1):
        return (f"fine.resolution: the grid's resolution {resolution} m must be a whole multiple of it, "
                f"got {fine.resolution} m")
    for axis, lo, size, g_lo, g_size in (("x", fine.x_min, fine.size_x, x_min, size_x),
                                         ("y", fine.y_min, fine.size_y, y_min, size_y)):
        g_hi = g_lo + round(g_size / resolution) * resolution
        if lo < g_lo - 1e-9:
            return f"fine.{axis}_min: the patch must lie inside the grid [{g_lo}, {g_hi}] m, got {lo} m"
        if lo + size > g_hi + 1e-9:
            return f"fine.size_{axis}: the patch [{lo}, {lo + size}] m must lie inside the grid [{g_lo}, {g_hi}] m"
        if not _multiple(lo - g_lo, resolution, 0):
            return f"fine.{axis}_min: on a cell boundary of the grid ({g_lo} + k * {resolution} m), got {lo} m"
        if not _multiple(size, resolution, 1):
            return f"fine.size_{axis}: a whole number (>= 1) of the grid's {resolution} m cells, got {size} m"
    return None


@dataclass(frozen=True)
class SoilSpec:
    """Height-field site with one mound (a truncated cone on flat ground, from ``site.yaml``'s ``mound``), optionally
    with a finer patch of the grid where the tool works (``fine``: :class:`sim_bridge.soil.HeightField`)."""

    x_min: float
    y_min: float
    size_x: float
    size_y: float
    resolution: float
    mound_center: tuple[float, float]
    mound_base_radius: float
    mound_top_radius: float  # truncated cone; 0 = cone
    mound_height: float
    ground_z: float
    deposit_radius: float  # [m] disc over which released soil lands on the ground
    dump_radius: float  # [m] disc of a vessel dump pile
    mound_region_margin: float  # [m] beyond the base radius still counted as the mound (spills at its foot)
    loose_density: float = 1450.0  # [kg/m^3] of the soil in buckets, vessels and piles (its weight on the machines)
    cutting: SoilParams | None = None  # the soil the tools cut (sim_bridge.soil_force); None: no cutting force
    fine: FineGrid | None = None  # a finer patch of the grid where the tool works; None: one grid
    #: the digging bucket pressed into the ground meets the soil's bearing resistance (soil_force.penetration_force;
    #: the plant YAML's ``soil.penetration``, off in the shipped plants); needs ``cutting`` with a subgrade modulus
    penetration: bool = False
    #: [m] the pressed bucket's contact along its motion (breadth B of the bearing capacity; its length is the
    #: cutting edge's width): the edge plate and the front of the floor behind it
    penetration_breadth: float = 0.3
    #: soil piles on the ground at the start besides the mound (the plant YAML's ``soil.piles``)
    piles: tuple[Pile, ...] = ()


@dataclass(frozen=True)
class SensorSpec:
    """Sensor noise (1 sigma) and seed: RTK-fix GNSS, IMU, encoders (the plant YAML's ``sensors:``, read as is)."""

    gnss_sigma_h: float = setting(lo=0.0, doc="[m] horizontal GNSS noise")
    gnss_sigma_v: float = setting(lo=0.0, doc="[m] vertical GNSS noise")
    imu_sigma: float = setting(lo=0.0, doc="[rad] roll/pitch noise")
    seed: int = setting(lo=0, doc="seed of every noise source of the plant")


@dataclass(frozen=True)
class PlantSpec:
    """Everything the plant needs, with where it came from.

    ``machines`` holds the plant YAML's machines by name, in its order. The paper's soil experiment (``experiment:
    dig_and_carry``, the default) digs with ``excavator`` and carries with ``carrier``: the names of the first
    excavator and the first crawler dump of the plant YAML; a plant YAML with ``experiment: none`` may hold any
    machines (then ``excavator`` / ``carrier`` may be "").
    """

    machines: Mapping[str, PlantMachine]
    site: Site  # tms_model: points, mound, CRS, map origin and the one projector
    soil: SoilSpec
    sensors: SensorSpec
    dt: float
    watchdog_s: float
    files: tuple[str, ...]
    excavator: str = ""
    carrier: str = ""
    substeps: int = 5  # MuJoCo steps per plant step (``dt``): the drives' oil springs need ~2 ms
    experiment: str = "dig_and_carry"

    def description(self, name: str) -> Machine:
        """The tms_model description of machine ``name``."""
        return self.machines[name].description

    @property
    def types(self) -> dict[str, str]:
        """Machine name -> type."""
        return {name: m.type for name, m in self.machines.items()}

    @property
    def initial_poses(self) -> dict[str, tuple[float, float, float]]:
        """Machine name -> initial (x, y, yaw) in map."""
        return {name: m.pose for name, m in self.machines.items()}

    @property
    def dbcs(self) -> dict[str, str]:
        """Machine name -> the DBC file of its bus."""
        return {name: m.description.dbc for name, m in self.machines.items()}

