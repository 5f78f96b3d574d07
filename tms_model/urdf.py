"""Each machine's kinematic tree with OPERA's link and joint names: its URDF and the transform of each joint.

One geometry, the machine's description (:mod:`tms_model.machines`); this module only names it as OPERA's
description packages do, so an RViz or MoveIt user sees the frames they know:

* excavator (zx200_ros2 ``zx200_description/urdf/zx200.xacro``): ``base_link -base_joint(fixed)-> track_link
  -swing_joint-> body_link -boom_joint-> boom_link -arm_joint-> arm_link -bucket_joint-> bucket_link
  -bucket_end_joint(fixed)-> bucket_end_link`` (the bucket tip). OPERA makes ``bucket_end_joint`` a revolute
  joint about x that nothing drives; here it is fixed, so the tip is on ``/tf_static`` and no joint state
  is missing for it.
* crawler dump (ic120_ros2 ``ic120_description/urdf/ic120_sim.xacro``): ``base_link -base_joint(fixed)->
  body_link -dump_joint-> vessel_pin_link``. ``dump_joint`` turns about +y, negative = raised, limits
  [-max_angle, 0], as the xacro has it; on our interfaces (``joint_states`` ``vessel_joint``) raised is
  positive, so the URDF position is minus the joint state. The xacro's sprocket joints are left out: no
  description gives a sprocket radius, so nothing could turn them. A carrier with a swing (the MSTs) is
  ``base_link -base_joint(fixed)-> track_link -rotate_joint-> body_link -dump_joint-> vessel_pin_link``.
* dozer (d37pxi_ros2 ``d37pxi_description/urdf/d37pxi24.xacro``): ``base_link -> body_link -lift_joint->
  blade_arm_link -> blade_link`` (the cutting edge).

Link names carry the machine's ``tf_prefix`` (``ic120_tf/base_link``), as ic120_ros2's xacro writes them.
Visuals are schematic (boxes and pin-to-pin cylinders from the description, the plant's shapes); OPERA's
meshes are theirs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from tms_model.fleet import load_named
from tms_model.machines import (
    CRAWLER_DUMP,
    DOZER,
    EXCAVATOR,
    LIFT_JOINT,
    ROTATE_JOINT,
    VESSEL_JOINT,
    Machine,
)
from tms_model.transform import Transform, quaternion_from_axis_angle, quaternion_multiply

__all__ = ["MachineTree", "TreeJoint", "Visual", "load_tree", "machine_tree"]

FIXED, REVOLUTE, CONTINUOUS = "fixed", "revolute", "continuous"
#: Height of the schematic track box [m] (the plant draws the same box).
TRACK_BOX_HEIGHT = 0.9


@dataclass(frozen=True)
class TreeJoint:
    """One URDF joint. ``state``: the ``joint_states`` name that drives it (None for a fixed joint);
    the URDF position is ``sign`` times that state."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    state: str | None = None
    sign: float = 1.0

    def transform(self, state: float = 0.0) -> Transform:
        """``parent_T_child`` with the driving joint state ``state`` (ignored for a fixed joint)."""
        origin = Transform.from_xyz_rpy(self.xyz, self.rpy)
        if self.kind == FIXED:
            return origin
        turn = quaternion_from_axis_angle(self.axis, self.sign * float(state))
        return Transform(origin.translation, quaternion_multiply(origin.rotation, turn))


@dataclass(frozen=True)
class Visual:
    """A schematic shape on ``link``: ``box`` (size x, y, z) or ``cylinder`` (radius, length; along its z)."""

    link: str
    shape: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MachineTree:
    """A machine's links and joints under its ``base_link``, as OPERA names them."""

    machine: Machine
    joints: tuple[TreeJoint, ...]
    visuals: tuple[Visual, ...]
    root: str = "base_link"

    @property
    def kind(self) -> str:
        return self.machine.kind

    def frame(self, link: str) -> str:
        """The /tf frame id of ``link`` (with the machine's ``tf_prefix``)."""
        return self.machine.frame(link)

    @property
    def fixed(self) -> tuple[TreeJoint, ...]:
        return tuple(j for j in self.joints if j.kind == FIXED)

    @property
    def moving(self) -> tuple[TreeJoint, ...]:
        return tuple(j for j in self.joints if j.kind != FIXED)

    @property
    def links(self) -> tuple[str, ...]:
        return (self.root, *(j.child for j in self.joints))

    def joint(self, name: str) -> TreeJoint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"{self.kind}: no joint {name!r} in its tree (joints: {[j.name for j in self.joints]})")

    def chain(self, link: str) -> tuple[TreeJoint, ...]:
        """The joints from the root down to ``link``."""
        by_child = {j.child: j for j in self.joints}
        out: list[TreeJoint] = []
        while link != self.root:
            if link not in by_child:
                raise KeyError(f"{self.kind}: no link {link!r} in its tree (links: {list(self.links)})")
            out.append(by_child[link])
            link = by_child[link].parent
        return tuple(reversed(out))

    def pose(self, link: str, states: Mapping[str, float]) -> Transform:
        """``base_link_T_link`` for the joint states ``states`` (name -> position, our interface's names)."""
        out = Transform()
        for j in self.chain(link):
            out = out * j.transform(0.0 if j.state is None else states[j.state])
        return out

    def urdf(self) -> str:
        """The URDF document (robot name = machine kind), parseable by urdfdom."""
        f = self.frame
        lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(self.kind)}>"]
        shapes: dict[str, list[Visual]] = {}
        for v in self.visuals:
            shapes.setdefault(v.link, []).append(v)
        for link in self.links:
            if link not in shapes:
                lines.append(f"  <link name={quoteattr(f(link))}/>")
                continue
            lines.append(f"  <link name={quoteattr(f(link))}>")
            for v in shapes[link]:
                geom = (f'<box size="{_v(v.size)}"/>' if v.shape == "box"
                        else f'<cylinder radius="{v.size[0]:.6g}" length="{v.size[1]:.6g}"/>')
                lines += ["    <visual>", f'      <origin xyz="{_v(v.xyz)}" rpy="{_v(v.rpy)}"/>',
                          f"      <geometry>{geom}</geometry>", "    </visual>"]
            lines.append("  </link>")
        for j in self.joints:
            lines += [f"  <joint name={quoteattr(j.name)} type={quoteattr(j.kind)}>",
                      f"    <parent link={quoteattr(f(j.parent))}/>", f"    <child link={quoteattr(f(j.child))}/>",
                      f'    <origin xyz="{_v(j.xyz)}" rpy="{_v(j.rpy)}"/>']
            if j.kind != FIXED:
                lines.append(f'    <axis xyz="{_v(j.axis)}"/>')
            if j.kind == REVOLUTE:
                lines.append(
                    f'    <limit lower="{j.lower:.9g}" upper="{j.upper:.9g}" effort="0" velocity="{j.velocity:.9g}"/>'
                )
            lines.append("  </joint>")
        lines.append("</robot>")
        return "\n".join(lines) + "\n"


def _v(values: tuple[float, ...]) -> str:
    return " ".join(f"{float(x):.9g}" for x in values)


def _cylinder(link: str, vector: tuple[float, float, float], radius: float) -> Visual:
    """A cylinder on ``link`` from its origin to ``vector`` (URDF cylinders lie along their z axis)."""
    x, y, z = vector
    length = math.sqrt(x * x + y * y + z * z)
    yaw, pitch = math.atan2(y, x), math.atan2(math.hypot(x, y), z)
    return Visual(link, "cylinder", (radius, length), (x / 2, y / 2, z / 2), (0.0, pitch, yaw))


def _excavator(m: Machine) -> MachineTree:
    assert m.bucket is not None
    joints = [TreeJoint("base_joint", FIXED, "base_link", "track_link", (0.0, 0.0, 0.0))]
    for j in m.joints:
        joints.append(TreeJoint(j.name, CONTINUOUS if j.lower is None else REVOLUTE, j.parent, j.child, j.origin_xyz,
                                j.origin_rpy, j.axis, j.lower, j.upper, j.velocity, state=j.name))
    joints.append(TreeJoint("bucket_end_joint", FIXED, m.joints[-1].child, "bucket_end_link", m.bucket.tip_xyz))
    fp = m.footprint
    visuals = [Visual("track_link", "box", (fp.length, fp.width, TRACK_BOX_HEIGHT), (0.0, 0.0, TRACK_BOX_HEIGHT / 2))]
    # boom, arm: pin to the next pin; bucket: pin to tip
    for j, nxt in zip(m.joints[1:], m.joints[2:], strict=False):
        visuals.append(_cylinder(j.child, nxt.origin_xyz, 0.25))
    visuals.append(_cylinder(m.joints[-1].child, m.bucket.tip_xyz, 0.2))
    return MachineTree(m, tuple(joints), tuple(visuals))


def _crawler_dump(m: Machine) -> MachineTree:
    assert m.vessel is not None
    v = m.vessel
    vessel = m.joint(VESSEL_JOINT)  # the vessel joint of our interfaces (+ = raised)
    fp = m.footprint
    joints: list[TreeJoint] = []
    if m.swing is None:
        joints.append(TreeJoint("base_joint", FIXED, "base_link", "body_link", (0.0, 0.0, 0.0)))
        tracks = "body_link"
    else:  # the rotating upper body: base_link -> track_link -rotate_joint-> body_link (carries the vessel)
        rot = m.joint(ROTATE_JOINT)
        joints.append(TreeJoint("base_joint", FIXED, "base_link", "track_link", (0.0, 0.0, 0.0)))
        joints.append(TreeJoint(rot.name, CONTINUOUS if rot.lower is None else REVOLUTE, rot.parent, rot.child,
                                rot.origin_xyz, axis=rot.axis, lower=rot.lower, upper=rot.upper, velocity=rot.velocity,
                                state=rot.name))
        tracks = "track_link"
    joints.append(TreeJoint("dump_joint", REVOLUTE, vessel.parent, "vessel_pin_link", vessel.origin_xyz,
                            axis=(0.0, 1.0, 0.0), lower=-v.max_angle, upper=0.0, velocity=v.velocity,
                            state=vessel.name, sign=-1.0))
    visuals = (
        Visual(tracks, "box", (fp.length, fp.width, TRACK_BOX_HEIGHT), (0.0, 0.0, TRACK_BOX_HEIGHT / 2)),
        Visual("vessel_pin_link", "box", (v.inner_length, v.inner_width, 0.1), (v.inner_length / 2, 0.0, 0.53)),
    )
    return MachineTree(m, tuple(joints), visuals)


def _dozer(m: Machine) -> MachineTree:
    """d37pxi_description: ``base_link -base_joint(fixed)-> body_link -lift_joint-> blade_arm_link
    -blade_joint(fixed)-> blade_link`` (OPERA's angle and tilt joints, which nothing here drives, are fixed at 0)."""
    assert m.blade is not None
    lift = m.joint(LIFT_JOINT)
    fp = m.footprint
    joints = (
        TreeJoint("base_joint", FIXED, "base_link", "body_link", (0.0, 0.0, 0.0)),
        TreeJoint(lift.name, REVOLUTE, lift.parent, lift.child, lift.origin_xyz, lift.origin_rpy, lift.axis,
                  lift.lower, lift.upper, lift.velocity, state=lift.name),
        TreeJoint("blade_joint", FIXED, lift.child, "blade_link", m.blade.edge_xyz),
    )
    visuals = (
        Visual(
            "body_link", "box", (fp.length * 0.7, fp.width * 0.8, TRACK_BOX_HEIGHT), (0.0, 0.0, TRACK_BOX_HEIGHT / 2)
        ),
        _cylinder(lift.child, m.blade.edge_xyz, 0.12),
        Visual("blade_link", "box", (0.2, m.blade.width, 0.9), (0.0, 0.0, 0.45)),
    )
    return MachineTree(m, joints, visuals)


_BUILDERS = {EXCAVATOR: _excavator, CRAWLER_DUMP: _crawler_dump, DOZER: _dozer}


def machine_tree(machine: Machine) -> MachineTree:
    """The kinematic tree of ``machine``, named as OPERA names that machine type."""
    return _BUILDERS[machine.type](machine)


def load_tree(name: str) -> MachineTree:
    """The tree of the machine called ``name`` on the site (its kind's, with its own /tf prefix)."""
    return machine_tree(load_named(name))
