"""The site's transform tree from the machines' state topics (ROS-free core of ``tms_sp_tf``).

As an RViz user expects it (REP 105, frames named as OPERA names them, :mod:`tms_model.urdf`)::

    world -> map                                  static: the map origin in the site CRS (config/site.yaml)
    map -> <p>odom -> <p>base_link                per machine, from odometry and localisation
    <p>base_link -> ... -> bucket_end_link        fixed joints static, moving joints from joint_states

One tree per machine *name* (config/site.yaml ``machines``): two machines of one kind are two trees, each with its
own frames. ``<p>`` is the machine's ``tf_prefix`` with a slash: its description's, with the kind replaced by the
machine's name (:meth:`tms_model.machines.Machine.named`: ``<name>_tf/``); none when the description has none.
Inputs, per machine:

* ``joint_states``: every moving joint of the tree whose driving state is in the message;
* ``odom_pose`` (nav_msgs/Odometry): in frame ``odom`` it is ``odom -> base_link``; in frame ``map`` the
  machine has no separate odometry (the excavator's pose comes from RTK GNSS), so ``map -> odom`` is the
  identity and ``odom -> base_link`` is that pose;
* ``map_to_odom`` (the localisation's REP 105 correction): ``map -> odom``.

The point an odometry message places is the machine type's reference point: ``base_link`` for the crawler
dump, the swing centre (``body_link`` origin) for an excavator, whose COM3 state reports
``Swing_Center_Position`` (com3_can's excavator profile forwards it as the pose).

Every transform carries the stamp of the message it comes from. An edge is given once per stamp: a second message
at a stamp already given (a converter publishing every CAN state between two /clock ticks) gives nothing for the
edges it repeats, as tf2's buffer keeps the first and warns TF_REPEATED_DATA for the rest.

Bad input raises ``ValueError`` naming the machine, the field and the value; nothing is published for it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from tms_common.errors import ConfigError
from tms_model.machines import EXCAVATOR
from tms_model.site import Site
from tms_model.transform import Transform
from tms_model.urdf import MachineTree

__all__ = ["MAP", "WORLD", "SiteTf", "StampedTransform"]

WORLD, MAP = "world", "map"


@dataclass(frozen=True)
class StampedTransform:
    """One edge of the tree: ``parent_T_child`` at ``stamp`` [s]."""

    parent: str
    child: str
    stamp: float
    transform: Transform


def _finite(machine: str, what: str, values: Sequence[float]) -> None:
    if not all(math.isfinite(float(v)) for v in values):
        raise ValueError(f"{machine}: {what} is not finite: {list(values)}")


class SiteTf:
    """Transforms of the site and its machines; one :class:`MachineTree` per machine name
    (``tree.machine.model_name``).

    Raises:
        ConfigError: a machine is given twice, or two machines would publish the same frame (give one a
            ``tf_prefix``).
    """

    def __init__(self, trees: Sequence[MachineTree], site: Site) -> None:
        self.trees: dict[str, MachineTree] = {}
        for t in trees:
            name = t.machine.model_name
            if name in self.trees:
                raise ConfigError(f"machine {name!r} is given twice")
            self.trees[name] = t
        self.site = site
        owner: dict[str, str] = {WORLD: "the site", MAP: "the site"}
        for name, t in self.trees.items():
            for link in ("odom", *t.links):
                frame = t.frame(link)
                if frame in owner:
                    raise ConfigError(
                        f"{t.machine.source}: frame {frame!r} of {name} is also a frame of {owner[frame]}; "
                        f"give one of them a tf_prefix in its machine description"
                    )
                owner[frame] = name
        self._reference = {name: self._reference_offset(t) for name, t in self.trees.items()}
        self._given: dict[tuple[str, str], float] = {}  # (parent, child) -> stamp last given

    def _once_per_stamp(self, transforms: list[StampedTransform]) -> list[StampedTransform]:
        out = [t for t in transforms if self._given.get((t.parent, t.child)) != t.stamp]
        for t in out:
            self._given[(t.parent, t.child)] = t.stamp
        return out

    @staticmethod
    def _reference_offset(tree: MachineTree) -> Transform:
        """``reference_T_base_link``: from the point odometry reports to base_link (axes aligned)."""
        if tree.machine.type == EXCAVATOR:
            x, y, z = tree.joint(tree.machine.joints[0].name).xyz  # the swing joint's origin in base_link
            return Transform((-x, -y, -z))
        return Transform()

    def tree(self, machine: str) -> MachineTree:
        try:
            return self.trees[machine]
        except KeyError:
            raise KeyError(f"no machine {machine!r} in the site tree (machines: {sorted(self.trees)})") from None

    # ------------------------------------------------------------------ static
    def static(self, stamp: float) -> list[StampedTransform]:
        """``world -> map`` and every machine's fixed joints: all of /tf_static."""
        e, n, a = self.site.origin_plane
        out = [StampedTransform(WORLD, MAP, stamp, Transform((e, n, a)))]
        for t in self.trees.values():
            out += [StampedTransform(t.frame(j.parent), t.frame(j.child), stamp, j.transform()) for j in t.fixed]
        return out

    # ------------------------------------------------------------------ dynamic
    def joint_states(self, machine: str, names: Sequence[str], positions: Sequence[float],
                     stamp: float) -> list[StampedTransform]:
        """The moving joints driven by this ``joint_states`` message (states of no joint of the tree are ignored)."""
        t = self.tree(machine)
        if len(names) != len(positions):
            raise ValueError(f"{machine}: joint_states has {len(names)} names but {len(positions)} positions")
        states: Mapping[str, float] = dict(zip(names, positions, strict=True))
        out = []
        for j in t.moving:
            if j.state not in states:
                continue
            q = float(states[j.state])
            if not math.isfinite(q):
                raise ValueError(f"{machine}: joint_states {j.state} position is not finite: {q}")
            out.append(StampedTransform(t.frame(j.parent), t.frame(j.child), stamp, j.transform(q)))
        return self._once_per_stamp(out)

    def odometry(self, machine: str, frame_id: str, position: Sequence[float], orientation: Sequence[float],
                 stamp: float) -> list[StampedTransform]:
        """``odom -> base_link`` (and ``map -> odom`` = identity when the pose is in ``map``) from an odometry pose.

        ``orientation`` is a quaternion (x, y, z, w).
        """
        t = self.tree(machine)
        _finite(machine, "odometry position", position)
        _finite(machine, "odometry orientation", orientation)
        norm = math.sqrt(sum(float(c) * float(c) for c in orientation))
        if abs(norm - 1.0) > 0.01:
            raise ValueError(f"{machine}: odometry orientation quaternion has norm {norm:.4f}, expected 1")
        q = tuple(float(c) / norm for c in orientation)
        pose = Transform(tuple(float(v) for v in position), q) * self._reference[machine]  # type: ignore[arg-type]
        odom, base = t.frame("odom"), t.frame("base_link")
        if frame_id in ("odom", odom):
            return self._once_per_stamp([StampedTransform(odom, base, stamp, pose)])
        if frame_id == MAP:
            return self._once_per_stamp(
                [StampedTransform(MAP, odom, stamp, Transform()), StampedTransform(odom, base, stamp, pose)])
        raise ValueError(f"{machine}: odometry frame {frame_id!r} is neither 'odom', {odom!r} nor 'map'")

    def map_to_odom(self, machine: str, frame_id: str, translation: Sequence[float], rotation: Sequence[float],
                    stamp: float) -> list[StampedTransform]:
        """``map -> odom`` from the localisation's correction (a transform whose parent ``frame_id`` is ``map``)."""
        t = self.tree(machine)
        if frame_id != MAP:
            raise ValueError(f"{machine}: map_to_odom parent frame {frame_id!r} is not 'map'")
        _finite(machine, "map_to_odom translation", translation)
        _finite(machine, "map_to_odom rotation", rotation)
        norm = math.sqrt(sum(float(c) * float(c) for c in rotation))
        if abs(norm - 1.0) > 0.01:
            raise ValueError(f"{machine}: map_to_odom rotation quaternion has norm {norm:.4f}, expected 1")
        rot = tuple(float(c) / norm for c in rotation)
        tr = Transform(tuple(float(v) for v in translation), rot)  # type: ignore[arg-type]
        return self._once_per_stamp([StampedTransform(MAP, t.frame("odom"), stamp, tr)])
