"""Plant configuration: the plant YAML (``config/sim/plant.yaml``) and the machines and site it names.

The machine descriptions (``config/machines/*.yaml``) and the site (``config/site.yaml``) are read by
:mod:`tms_model`; this module reads the plant YAML (through :mod:`tms_common.schema`) and places each machine it
names on the site (:class:`~sim_bridge.spec.PlantMachine`). A wrong value raises
:class:`~sim_bridge.errors.SimConfigError` with ``file:line: key.path: problem``, so a malformed machine YAML
names the key that is wrong; inside the plant YAML, unknown keys are errors (a typo must not silently fall back to
a default).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

from com3_can.codec import dbc_files
from sim_bridge.errors import SimConfigError
from sim_bridge.physics import PhysicsSpec
from sim_bridge.profiles import PLANT_PROFILES
from sim_bridge.soil_force import SoilParams, load_soil_types
from sim_bridge.spec import FineGrid, Pile, PlantMachine, PlantSpec, SensorSpec, SoilSpec, fine_grid_problem
from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader, load_schema, read_schema, setting
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR, Machine, load_machine, parse_machine
from tms_model.site import Site, load_site

__all__ = ["EXPERIMENTS", "load_description", "load_plant"]

#: plant YAML ``experiment``: the paper's dig-load-carry-dump soil experiment (needs an excavator and a crawler
#: carrier), or none (any machines, e.g. a test plant of one kind)
EXPERIMENTS = ("dig_and_carry", "none")


@dataclass(frozen=True)
class _Grid:
    x_min: float
    y_min: float
    size_x: float = setting(lo=1.0)
    size_y: float = setting(lo=1.0)
    resolution: float = setting(lo=0.02, hi=2.0)
    #: a finer patch where the tool works ({x_min, y_min, size_x, size_y, resolution}); absent: one grid
    fine: FineGrid | None = None

    def __post_init__(self) -> None:
        if self.fine is not None:
            problem = fine_grid_problem(self.x_min, self.y_min, self.size_x, self.size_y, self.resolution, self.fine)
            if problem is not None:
                raise ValueError(problem)


@dataclass(frozen=True)
class _Soil:
    grid: _Grid
    deposit_radius: float = setting(lo=0.0)
    dump_radius: float = setting(lo=0.0)
    mound_region_margin: float = setting(lo=0.0)
    #: bank 1.8 t/m^3 with 25 % swell (moist common earth: Peurifoy, Construction Planning, Equipment and Methods,
    #: Table 4-1; Caterpillar Performance Handbook load factors) -> 1.45 t/m^3 as buckets and vessels hold it
    density: float = setting(1450.0, lo=100.0, hi=3000.0, doc="[kg/m^3] of the soil as the plant moves it (loose)")
    #: the soil the tools cut (config/sim/soil_types.yaml): OperaSim-AGX's dirt_1 by default, what OPERA's own
    #: simulator digs
    type: str = "agx_dirt_1"
    #: the digging bucket pressed into the ground meets the soil's bearing resistance (Terzaghi/Meyerhof capacity
    #: after a Winkler ramp, sim_bridge.soil_force.penetration_force); off in the shipped plants until measured
    #: in the demo
    penetration: bool = False
    penetration_breadth_m: float = setting(0.3, lo=0.02, hi=2.0, doc="[m] the pressed bucket's contact along its "
                                           "motion (edge plate and front of the floor); its length is the edge's width")
    #: soil piles on the ground at the start besides the site's mound ([{x, y, base_radius, top_radius, height}])
    piles: tuple[Pile, ...] = ()


@dataclass(frozen=True)
class _PlantFile:
    """The plant YAML. ``initial_poses`` values are a site point name or ``[x, y, yaw]`` (read with a Reader)."""

    machines: dict[str, str]  # machine name on the site -> its machine YAML (relative to config/)
    site: str
    step_s: float = setting(lo=0.0005, hi=0.05)
    watchdog_s: float = setting(lo=0.01)
    initial_poses: dict[str, Any] = setting()
    soil: _Soil = setting()
    sensors: SensorSpec = setting()
    initial_front: dict[str, float] | None = None  # front joints of the digging excavator at start
    experiment: str = "dig_and_carry"
    substeps: int = setting(5, lo=1, hi=50, doc="MuJoCo steps per step_s (the hydraulic drives are stiff: ~2 ms)")


@contextlib.contextmanager
def _as_plant_error():
    """tms_model's and the schema's ``ConfigError`` (``file:line: key: problem``) re-raised as a plant error."""
    try:
        yield
    except SimConfigError:
        raise
    except ConfigError as exc:
        raise SimConfigError(str(exc)) from None


@_as_plant_error()
def load_description(path: str | Path) -> Machine:
    """The tms_model description of the machine YAML ``path``.

    Files under ``config/`` are read once (tms_model's cache); others (tests' broken copies) every time.
    """
    path = Path(path)
    if path.resolve().is_relative_to(config_path().resolve()):
        return load_machine(path.stem, path)
    return parse_machine(path)


#: what the plant's physics needs of a machine of each type (``physics:`` of its YAML)
_PHYSICS_NEEDS = {
    EXCAVATOR: ("oil_bulk_modulus_mpa", "hose_volume_l", "tank_pressure_mpa", "cylinder_viscous_ns_per_m",
                "pilot_crack_mpa", "pilot_full_mpa", "spool_overlap", "pump_power_kw", "ls_margin_mpa",
                "function_flow_lpm", "swing_brake_delay_s"),
}
_DRIVE_NEEDS = ("drive_frequency_hz", "drive_torque_limit_nm")


def _physics(d: Machine) -> PhysicsSpec:
    """The ``physics:`` section of ``d``'s YAML, with what its type needs."""
    phys = load_schema(PhysicsSpec, d.source, ("physics",))
    try:
        phys.need(d.source, *_PHYSICS_NEEDS.get(d.type, _DRIVE_NEEDS))
    except ValueError as exc:
        raise SimConfigError(str(exc)) from None
    flows = phys.function_flow_lpm
    if flows is not None and set(flows) != set(d.joint_names):
        raise SimConfigError(
            f"{d.source}: physics.function_flow_lpm: expected one flow per joint {list(d.joint_names)}"
        )
    limits = phys.drive_torque_limit_nm
    if limits is not None and set(limits) != set(d.joint_names):
        raise SimConfigError(f"{d.source}: physics.drive_torque_limit_nm: expected one limit per joint "
                             f"{list(d.joint_names)}")
    return phys


def _pose(poses: Reader, name: str, site: Site, site_path: Path) -> tuple[float, float, float]:
    if isinstance(poses.raw(name), str):  # a point name in site.yaml
        point = poses.string(name)
        if point not in site.points:
            raise poses.key_error(name, f"no point {point!r} in {site_path} (known: {sorted(site.points)})")
        p = site.points[point]
        return (p.x, p.y, p.yaw)
    return poses.vector(name, 3)  # type: ignore[return-value]


def _soil_type(name: str) -> SoilParams:
    soils = load_soil_types()
    if name not in soils:
        raise SimConfigError(f"{config_path('sim', 'soil_types.yaml')}: no soil {name!r} for soil.type "
                             f"(known: {sorted(soils)})")
    return soils[name]


def _soil(soil: _Soil, site: Site) -> SoilSpec:
    g, mound = soil.grid, site.mound
    cutting = _soil_type(soil.type)
    if soil.penetration and cutting.subgrade_modulus is None:
        raise SimConfigError(f"{config_path('sim', 'soil_types.yaml')}: soil_types.{soil.type}: "
                             "soil.penetration needs its subgrade_modulus_mn_m3")
    return SoilSpec(
        x_min=g.x_min, y_min=g.y_min, size_x=g.size_x, size_y=g.size_y, resolution=g.resolution,
        mound_center=(mound.cx, mound.cy), mound_base_radius=mound.base_radius, mound_top_radius=mound.top_radius,
        mound_height=mound.height, ground_z=mound.ground_z, deposit_radius=soil.deposit_radius,
        dump_radius=soil.dump_radius, mound_region_margin=soil.mound_region_margin,
        loose_density=soil.density,
        cutting=cutting, fine=g.fine, penetration=soil.penetration, penetration_breadth=soil.penetration_breadth_m,
        piles=soil.piles,
    )


def _description_on_site(listed: Reader, name: str, path: Path, site: Site, site_path: Path) -> Machine:
    """Machine ``name``'s description, checked against the site (the name is on it, as a machine of that kind)."""
    description = load_description(path)
    entry = site.machines.get(name)
    if entry is None:
        raise listed.key_error(name, f"no machine {name!r} on the site {site_path} (known: {sorted(site.machines)})")
    if entry.kind != description.kind:
        raise listed.key_error(name, f"{path} describes a {description.kind}, but {name!r} is a {entry.kind} on the "
                               f"site {site_path}")
    try:
        PLANT_PROFILES.get(description.type)
    except ConfigError as exc:
        raise SimConfigError(f"{path}: type: {exc}") from None
    if description.dbc not in dbc_files():
        raise SimConfigError(f"{path}: can.dbc: the DBC of the machine's COM3 bus, one of {list(dbc_files())}; "
                             f"got {description.dbc!r}")
    return description.named(name)


@_as_plant_error()
def load_plant(path: str | Path | None = None, *, site: str | Path | None = None) -> PlantSpec:
    """Read the plant YAML (default ``config/sim/plant.yaml``) and the machine and site YAMLs it names.

    ``machines`` maps each machine's name on the site to its machine YAML (relative to ``config/``, or absolute);
    the description's ``type`` picks the plant profile that simulates it. ``site`` overrides the plant file's site.
    """
    path = Path(path) if path else config_path("sim", "plant.yaml")
    data, where = load_yaml(path)
    plant = read_schema(_PlantFile, data, where)
    top = Reader(data, where)
    if plant.experiment not in EXPERIMENTS:
        raise top.key_error("experiment", f"expected one of {list(EXPERIMENTS)}, got {plant.experiment!r}")
    base = config_path()
    site_path = Path(site) if site else base / plant.site
    site_model = load_site(site_path)
    listed = top.sub("machines")
    paths = {name: base / file for name, file in plant.machines.items()}
    descriptions = {name: _description_on_site(listed, name, p, site_model, site_path) for name, p in paths.items()}
    first = {t: next((n for n, d in descriptions.items() if d.type == t), "") for t in (EXCAVATOR, CRAWLER_DUMP)}
    if plant.experiment == "dig_and_carry" and (not first[EXCAVATOR] or not first[CRAWLER_DUMP]):
        types = {n: d.type for n, d in descriptions.items()}
        raise top.key_error("machines", "the site needs an excavator and a crawler carrier (soil is dug and carried); "
                            f"got types {types} (a plant without the soil experiment says experiment: none)")
    start = {name: dict(d.home_pose) for name, d in descriptions.items()}
    if plant.initial_front is not None:
        digger = first[EXCAVATOR]
        if not digger:
            raise top.key_error("initial_front", "front joints of the digging excavator, but the plant has none")
        start[digger].update(top.per_name("initial_front", list(descriptions[digger].home_pose)))
    poses = top.sub("initial_poses")
    poses.only(set(paths))
    machines = {
        name: PlantMachine(name=name, description=d, pose=_pose(poses, name, site_model, site_path),
                           start_joints=MappingProxyType(start[name]), physics=_physics(d))
        for name, d in descriptions.items()
    }
    return PlantSpec(
        machines=MappingProxyType(machines),
        site=site_model,
        soil=_soil(plant.soil, site_model),
        sensors=plant.sensors,
        dt=plant.step_s,
        watchdog_s=plant.watchdog_s,
        files=(str(path), *(str(p) for p in paths.values()), str(site_path)),
        excavator=first[EXCAVATOR],
        carrier=first[CRAWLER_DUMP],
        experiment=plant.experiment,
        substeps=plant.substeps,
    )
