"""Hydraulic cylinders of an excavator's front: their geometry (machine description) and kinematics.

A cylinder pushes between a pin on the parent link and a pin on the child link of its joint (boom, arm), or, for
the bucket, between a pin on the arm and the joint J of a four-bar linkage: the guide link turns about K on the arm,
the side link about L on the bucket, both meet at J where the rod is pinned (names after KennyVilella's
excavator_simulator_mujoco ``pose_calculation.py``). Pins are (x, z) in the link frames of the URDF (all front axes
are y, so the linkage is planar). The length ``l(q)`` and its derivative ``dl/dq`` (the moment arm: torque = force *
dl/dq, joint speed = cylinder speed / (dl/dq)) are what the plant, the ISO 6015 check and the arm controllers use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tms_common.schema import setting

__all__ = ["Cylinder", "Linkage", "Cylinders", "SwingMotor", "ry", "joint_point", "cylinder_length",
           "moment_arm", "linkage_pin"]


@dataclass(frozen=True)
class Linkage:
    """The bucket's four-bar: guide link pinned at ``guide_pin`` (K, arm frame), side link at ``link_pin``
    (L, bucket frame), meeting at J where the cylinder rod is pinned; ``branch`` picks J's side of K->L."""

    guide_pin: tuple[float, float]
    link_pin: tuple[float, float]
    guide_length: float = setting(lo=0.05)
    link_length: float = setting(lo=0.05)
    branch: int = setting(1, lo=-1, hi=1)


@dataclass(frozen=True)
class Cylinder:
    """One front function's cylinder(s): ``count`` equal cylinders in parallel, bore and rod diameters [m],
    the pin on the joint's parent link (``parent_pin``) and on the child link (``child_pin``) or a ``linkage``."""

    joint: str
    count: int = setting(lo=1, hi=4)
    bore: float = setting(lo=0.02, hi=0.5)
    rod: float = setting(lo=0.01, hi=0.4)
    parent_pin: tuple[float, float] = (0.0, 0.0)
    child_pin: tuple[float, float] | None = None
    linkage: Linkage | None = None

    @property
    def cap_area(self) -> float:
        """Piston (bottom, cap side) area of all ``count`` cylinders [m^2]."""
        return self.count * math.pi * self.bore**2 / 4

    @property
    def rod_area(self) -> float:
        """Annulus (rod side) area of all ``count`` cylinders [m^2]."""
        return self.count * math.pi * (self.bore**2 - self.rod**2) / 4


@dataclass(frozen=True)
class SwingMotor:
    """The swing drive: displacement per swing radian at the swing joint [m^3/rad] (motor displacement times the
    reduction), its relief (cross-port) pressure [Pa] and the parking brake's holding torque [N m]."""

    displacement_per_rad: float = setting(lo=1e-6, doc="[m^3/rad] at the swing joint")
    relief_mpa: float = setting(lo=0.1, hi=60.0)
    brake_torque: float = setting(lo=0.0, doc="[N m] parking brake")

    @property
    def relief_torque(self) -> float:
        """[N m] the torque the cross-port relief lets through (accelerating or braking the upper body)."""
        return self.relief_mpa * 1e6 * self.displacement_per_rad


@dataclass(frozen=True)
class Cylinders:
    """The cylinders of an excavator's front in bus order (boom, arm, bucket), the implement relief [MPa] and the
    swing motor."""

    boom: Cylinder
    arm: Cylinder
    bucket: Cylinder
    relief_mpa: float = setting(lo=1.0, hi=60.0)
    swing: SwingMotor | None = None
    source: str = ""

    @property
    def relief_pa(self) -> float:
        return self.relief_mpa * 1e6

    @property
    def all(self) -> tuple[Cylinder, Cylinder, Cylinder]:
        return (self.boom, self.arm, self.bucket)


def ry(phi: float, p: tuple[float, float]) -> tuple[float, float]:
    """(x, z) of ``p`` rotated by ``phi`` about +y (URDF/MuJoCo convention: x turns towards -z)."""
    c, s = math.cos(phi), math.sin(phi)
    return c * p[0] + s * p[1], -s * p[0] + c * p[1]


def joint_point(origin: tuple[float, float], pitch: float, q: float, p: tuple[float, float]) -> tuple[float, float]:
    """A point ``p`` of the child link in its parent's frame, the joint at ``origin`` (x, z) with fixed ``pitch``."""
    x, z = ry(pitch + q, p)
    return origin[0] + x, origin[1] + z


def linkage_pin(link: Linkage, origin: tuple[float, float], pitch: float, q: float) -> tuple[float, float] | None:
    """J, the rod pin of the four-bar, in the arm frame at bucket angle ``q`` (None: the linkage cannot close)."""
    kx, kz = link.guide_pin
    lx, lz = joint_point(origin, pitch, q, link.link_pin)
    vx, vz = lx - kx, lz - kz
    d = math.hypot(vx, vz)
    a_len, b_len = link.guide_length, link.link_length
    if d > a_len + b_len or d < abs(a_len - b_len) or d == 0.0:
        return None
    a = (a_len * a_len - b_len * b_len + d * d) / (2 * d)
    h = math.sqrt(max(a_len * a_len - a * a, 0.0))
    ux, uz = vx / d, vz / d
    return kx + a * ux - link.branch * h * uz, kz + a * uz + link.branch * h * ux


def cylinder_length(cyl: Cylinder, origin: tuple[float, float], pitch: float, q: float) -> float:
    """Pin-to-pin length [m] of ``cyl`` at joint angle ``q``; ``origin``/``pitch`` are the joint's (x, z) and pitch in
    the parent frame. Raises ValueError where a linkage cannot close (outside its joint range)."""
    if cyl.linkage is not None:
        j = linkage_pin(cyl.linkage, origin, pitch, q)
        if j is None:
            raise ValueError(f"{cyl.joint}: the bucket linkage cannot close at q = {q:.3f} rad")
        x, z = j
    else:
        assert cyl.child_pin is not None
        x, z = joint_point(origin, pitch, q, cyl.child_pin)
    return math.hypot(x - cyl.parent_pin[0], z - cyl.parent_pin[1])


def moment_arm(cyl: Cylinder, origin: tuple[float, float], pitch: float, q: float, h: float = 1e-6) -> float:
    """dl/dq [m/rad]: joint torque per cylinder force, cylinder speed per joint speed (central difference)."""
    return (cylinder_length(cyl, origin, pitch, q + h) - cylinder_length(cyl, origin, pitch, q - h)) / (2 * h)
