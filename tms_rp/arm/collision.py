"""Excavator arm collision model of the ``_plan`` actions: collision objects from the DB and the padded arm.

The objects are read from the records the original's planning servers read (irvs/tms_if_for_opera,
``zx200_change_pose_plan`` / ``zx200_excavate_simple_plan``): the ``parameter`` document named by the planner's
``collision_object_record_name`` holds an array ``collision_objects``, one element per object::

    {"id": "ic120_vessel", "primitive_type": 1, "dimensions": [6.05, 3.37, 2.0],
     "pose": {"position": {"x": ..., "y": ..., "z": ...}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}}}

``primitive_type`` and ``dimensions`` are shape_msgs/SolidPrimitive's (BOX 1: [x, y, z] full lengths; SPHERE 2:
[radius]; CYLINDER 3: [height, radius], axis z), the pose is the shape's centre in the planning frame,
the excavator's ``base_link`` (the frame the position_with_angle targets are in; the original's later scene manager,
tms_ts_primitive ``excavator_scene_manager``, defaults its ``planning_frame`` to ``base_link`` too). The
record may carry ``link_padding`` ``{link_name: metres}``, the field that scene manager reads; links it does
not name keep the configured default (the original's 0.25 m on boom_link, arm_link, bucket_link and
bucket_end_link). Ours beyond the original: an element may carry ``padding`` [m] (default 0), kept around that
object as well.

The arm is the union of per-link shapes placed by the kinematics: each link's box, the one the plant's link is
(``link_boxes`` of ``config/machines/<kind>.yaml``), and the capsules and spheres of
``config/tms_rp/<kind>_collision.yaml``
(:class:`tms_model.excavator.kinematics.ExcavatorKinematics`). The distance of a link to an object is coal's
(signed: negative inside); the link is in collision when that distance is below link padding + object padding.
Pure Python (numpy, pinocchio, coal); no ROS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from tms_common.config import config_path
from tms_common.schema import load_schema, setting
from tms_model.excavator.codes import FAILURE, PlanningError
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics

__all__ = ["ARM_LINKS", "PRIMITIVES", "CollisionConfig", "CollisionError", "CollisionObject", "CollisionRecordError",
           "Contact", "ArmCollisionModel", "collision_config_path", "load_collision_config",
           "objects_from_record"]

#: the arm links the model places, base to tip (OPERA's zx200_description names)
ARM_LINKS = ("body_link", "boom_link", "arm_link", "bucket_link", "bucket_end_link")
_LINK_JOINT = {"body_link": JOINTS[0], "boom_link": JOINTS[1], "arm_link": JOINTS[2], "bucket_link": JOINTS[3]}
#: shape_msgs/SolidPrimitive type -> (name, number of dimensions, meaning)
PRIMITIVES = {1: ("BOX", 3, "[x, y, z]"), 2: ("SPHERE", 1, "[radius]"), 3: ("CYLINDER", 2, "[height, radius]")}
_UNSUPPORTED = {4: "CONE", 5: "PRISM"}


class CollisionError(PlanningError):
    """A target or every path to it is in collision (the message names the object, its record and the link):
    the original's ``TmsRpErrorCodes.FAILURE``."""

    code = FAILURE


class CollisionRecordError(PlanningError):
    """The collision-object record is missing or malformed (the message names the record and the field)."""

    code = FAILURE

    def __init__(self, record: str, field_: str | None, problem: str) -> None:
        where = f"collision object record '{record}'" + (f": field '{field_}'" if field_ else "")
        super().__init__(f"{where}: {problem}")
        self.record, self.field = record, field_


@dataclass(frozen=True)
class CollisionObject:
    """One object of the scene: ``name`` (the record's ``id``), a coal shape at ``position`` / ``rotation``
    (base_link), ``padding`` kept around it, and the DB record it came from."""

    name: str
    record: str
    kind: str
    dimensions: tuple[float, ...]
    position: np.ndarray
    rotation: np.ndarray
    padding: float = 0.0
    shape: Any = field(default=None, compare=False, repr=False)
    tf: Any = field(default=None, compare=False, repr=False)
    bound: float = 0.0  # radius of the bounding sphere about ``position``

    @staticmethod
    def make(name: str, record: str, primitive_type: int, dimensions: list[float], position: Any,
             quaternion_xyzw: Any, padding: float = 0.0) -> CollisionObject:
        kind = PRIMITIVES[primitive_type][0]
        dims = tuple(float(d) for d in dimensions)
        if kind == "BOX":
            shape, bound = coal.Box(*dims), 0.5 * math.sqrt(sum(d * d for d in dims))
        elif kind == "SPHERE":
            shape, bound = coal.Sphere(dims[0]), dims[0]
        else:
            shape, bound = coal.Cylinder(dims[1], dims[0]), math.hypot(dims[1], dims[0] / 2)
        x, y, z, w = (float(v) for v in quaternion_xyzw)
        rot = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
        pos = np.asarray(position, dtype=float)
        return CollisionObject(
            name, record, kind, dims, pos, rot, float(padding), shape, coal.Transform3s(rot, pos), bound
        )

    def describe(self) -> str:
        return f"'{self.name}' (record '{self.record}')"


# ---------------------------------------------------------------------------------------------- records
def _number(value: Any, record: str, where: str, *, positive: bool = False, non_negative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(float(value)):
        raise CollisionRecordError(record, where, f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise CollisionRecordError(record, where, f"must be > 0, got {value!r}")
    if non_negative and value < 0:
        raise CollisionRecordError(record, where, f"must be >= 0, got {value!r}")
    return float(value)


def _mapping(value: Any, record: str, where: str) -> dict:
    if not isinstance(value, dict):
        raise CollisionRecordError(record, where, f"must be a document, got {value!r}")
    return value


def _xyz(doc: dict, record: str, where: str, keys: str) -> list[float]:
    out = []
    for k in keys:
        if k not in doc:
            raise CollisionRecordError(record, f"{where}.{k}", "missing")
        out.append(_number(doc[k], record, f"{where}.{k}"))
    return out


def objects_from_record(doc: dict, record: str,
                        machine_kind: str = "") -> tuple[list[CollisionObject], dict[str, float]]:
    """The collision objects and the ``link_padding`` of one collision-object record (see the module docstring);
    ``machine_kind`` (the excavator's description, :attr:`tms_model.machines.Machine.kind`) names the machine in errors.

    Raises :class:`CollisionRecordError` naming the record and the field (``collision_objects[2].dimensions``).
    """
    if "collision_objects" not in doc:
        raise CollisionRecordError(record, "collision_objects", "missing (an array of collision objects)")
    items = doc["collision_objects"]
    if not isinstance(items, list):
        raise CollisionRecordError(record, "collision_objects", f"must be an array, got {items!r}")
    objects: list[CollisionObject] = []
    seen: set[str] = set()
    for i, raw in enumerate(items):
        at = f"collision_objects[{i}]"
        item = _mapping(raw, record, at)
        name = item.get("id")
        if not isinstance(name, str) or not name:
            raise CollisionRecordError(record, f"{at}.id", f"must be a non-empty string, got {name!r}")
        if name in seen:
            raise CollisionRecordError(record, f"{at}.id", f"'{name}' is used by an earlier object too")
        seen.add(name)
        ptype = item.get("primitive_type")
        if isinstance(ptype, float) and ptype.is_integer():
            ptype = int(ptype)
        if isinstance(ptype, bool) or not isinstance(ptype, int) or ptype not in PRIMITIVES:
            known = ", ".join(f"{k} {v[0]}" for k, v in PRIMITIVES.items())
            extra = f" ({_UNSUPPORTED[ptype]} is not supported)" if ptype in _UNSUPPORTED else ""
            raise CollisionRecordError(record, f"{at}.primitive_type",
                                       f"must be a shape_msgs/SolidPrimitive type ({known}), got {ptype!r}{extra}")
        kind, count, meaning = PRIMITIVES[ptype]
        dims = item.get("dimensions")
        if not isinstance(dims, list) or len(dims) != count:
            raise CollisionRecordError(record, f"{at}.dimensions",
                                       f"{kind} needs {count} number(s) {meaning} in metres, got {dims!r}")
        dims = [_number(d, record, f"{at}.dimensions[{k}]", positive=True) for k, d in enumerate(dims)]
        if "pose" not in item:
            raise CollisionRecordError(record, f"{at}.pose", "missing")
        pose = _mapping(item["pose"], record, f"{at}.pose")
        for part in ("position", "orientation"):
            if part not in pose:
                raise CollisionRecordError(record, f"{at}.pose.{part}", "missing")
        position = _xyz(_mapping(pose["position"], record, f"{at}.pose.position"), record, f"{at}.pose.position", "xyz")
        quat = _xyz(_mapping(pose["orientation"], record, f"{at}.pose.orientation"), record,
                    f"{at}.pose.orientation", "xyzw")
        if math.sqrt(sum(v * v for v in quat)) < 1e-6:
            raise CollisionRecordError(record, f"{at}.pose.orientation", "quaternion has zero length")
        padding = _number(item.get("padding", 0.0), record, f"{at}.padding", non_negative=True)
        objects.append(CollisionObject.make(name, record, ptype, dims, position, quat, padding))
    link_padding: dict[str, float] = {}
    if "link_padding" in doc:
        for link, value in _mapping(doc["link_padding"], record, "link_padding").items():
            if link not in ARM_LINKS:
                raise CollisionRecordError(record, f"link_padding.{link}",
                                           f"is not a link of the {machine_kind or 'excavator'} arm "
                                           f"(one of {', '.join(ARM_LINKS)})")
            link_padding[link] = _number(value, record, f"link_padding.{link}", non_negative=True)
    return objects, link_padding


# ---------------------------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class LinkShape:
    """One shape of a link in the link's frame: ``kind`` box (full ``size``) / capsule / sphere."""

    link: str
    kind: str
    size: tuple[float, ...]
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class LinkShapes:
    """A link's shapes besides its box (the description's ``link_boxes``, :class:`tms_model.machines.LinkBox`),
    their union: a capsule of ``capsule`` radius from the link's pin to the next (the bucket: to its tip), a sphere
    of ``sphere`` radius at the origin [m]."""

    capsule: float | None = setting(None, lo=0.0)
    sphere: float | None = setting(None, lo=0.0)


@dataclass(frozen=True)
class CollisionConfig:
    """``config/tms_rp/<kind>_collision.yaml``: an excavator kind's arm shapes and path checks (read through
    tms_common.schema: an unknown key, link or shape names the file and line)."""

    links: dict[str, LinkShapes]
    link_padding: dict[str, float] = setting(lo=0.0)
    path_step_rad: float = setting(0.005, lo=1e-4)
    detour_margin: float = setting(0.15, lo=0.0)
    lift_levels: int = setting(12, lo=1)
    carry_front: tuple[float, float, float] = (-1.08, 1.9, 1.9)

    def __post_init__(self) -> None:
        for key in ("links", "link_padding"):
            for link in getattr(self, key):
                if link not in ARM_LINKS:
                    raise ValueError(f"{key}.{link}: not an arm link (one of {', '.join(ARM_LINKS)})")


def collision_config_path(kind: str) -> Path:
    """``config/tms_rp/<kind>_collision.yaml``."""
    return Path(config_path("tms_rp", f"{kind}_collision.yaml"))


def load_collision_config(kind: str, path: str | Path | None = None) -> CollisionConfig:
    """Read the collision YAML of excavator ``kind`` (or ``path``); errors are ``file:line: key.path: problem``."""
    return load_schema(CollisionConfig, Path(path) if path is not None else collision_config_path(kind))


# ---------------------------------------------------------------------------------------------- the arm
@dataclass(frozen=True)
class Contact:
    """The smallest clearance of one configuration: ``clearance`` = distance - link padding - object padding
    (negative: the padded link is inside the padded object)."""

    clearance: float
    distance: float
    link: str
    obj: CollisionObject | None

    def describe(self) -> str:
        if self.obj is None:
            return "no collision object"
        inside = "inside" if self.distance < 0 else f"{self.distance:.3f} m from"
        return (f"{self.link} would be {inside} {self.obj.describe()}, closer than its padding by "
                f"{-self.clearance:.3f} m")


class ArmCollisionModel:
    """The excavator arm as padded shapes placed by the kinematics; distances to a list of objects.

    ``padding`` overrides the configured link padding per link (a record's ``link_padding``).
    """

    #: [m] clearances above this are not measured exactly (bounding spheres say the pair is further apart)
    FAR = 1.0

    def __init__(self, kin: ExcavatorKinematics, cfg: CollisionConfig | None = None) -> None:
        self.kin = kin
        self.cfg = cfg or load_collision_config(kin.machine.kind)
        machine = kin.machine
        next_pin = {j.parent: np.array(j.origin_xyz) for j in machine.joints}  # parent link -> child joint origin
        next_pin["bucket_link"] = np.array(machine.bucket.tip_xyz)
        self._joint_ids = {link: kin.model.getJointId(j) for link, j in _LINK_JOINT.items()}
        self.shapes: list[tuple[str, Any, np.ndarray, np.ndarray, float]] = []  # link, coal shape, R, t (link), bound
        for link, box in machine.link_boxes.items():  # the boxes the plant's links are (config/machines/<kind>.yaml)
            size = np.array(box.size, dtype=float)
            off = np.array(box.offset, dtype=float)
            self.shapes.append((link, coal.Box(*size), np.eye(3), off, float(np.linalg.norm(size) / 2)))
        for link, spec in self.cfg.links.items():
            if spec.capsule is not None:
                r = spec.capsule
                v = next_pin[link]
                length = float(np.linalg.norm(v))
                z = v / length
                x = np.cross([0.0, 1.0, 0.0], z)
                x = x / np.linalg.norm(x)
                rot = np.column_stack([x, np.cross(z, x), z])  # capsule axis (z) along the pin-to-pin vector
                self.shapes.append((link, coal.Capsule(r, length), rot, v / 2, length / 2 + r))
            if spec.sphere is not None:
                r = spec.sphere
                self.shapes.append((link, coal.Sphere(r), np.eye(3), np.zeros(3), r))
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()

    def padding_for(self, overrides: dict[str, float] | None = None) -> dict[str, float]:
        pad = {link: self.cfg.link_padding.get(link, 0.0) for link in ARM_LINKS}
        pad.update(overrides or {})
        return pad

    def link_frames(self, q: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """(rotation, translation) of every link frame in base_link at joint angles ``q``."""
        kin = self.kin
        pin.framesForwardKinematics(kin.model, kin.data, np.asarray(q, dtype=float))
        frames = {
            link: (kin.data.oMi[jid].rotation, kin.data.oMi[jid].translation) for link, jid in self._joint_ids.items()
        }
        tip = kin.data.oMf[kin.tip_frame]
        frames["bucket_end_link"] = (tip.rotation, tip.translation)
        return frames

    def placed(self, q: np.ndarray) -> list[tuple[str, Any, Any, np.ndarray, float]]:
        """Every shape at ``q``: (link, coal shape, coal transform, centre in base_link, bounding radius)."""
        frames = self.link_frames(q)
        out = []
        for link, shape, rot, off, bound in self.shapes:
            r, t = frames[link]
            centre = r @ off + t
            out.append((link, shape, coal.Transform3s(r @ rot, centre), centre, bound))
        return out

    def contact(self, q: np.ndarray, objects: list[CollisionObject], padding: dict[str, float],
                margin: float = 0.0) -> Contact:
        """The smallest clearance of the padded arm at ``q`` to the padded ``objects`` (minus ``margin``).

        Shape pairs whose bounding spheres leave more than :attr:`FAR` of clearance are not measured: a
        clearance of inf means every object is further than that."""
        best = Contact(math.inf, math.inf, "", None)
        if not objects:
            return best
        for link, shape, tf, centre, bound in self.placed(q):
            pad = padding.get(link, 0.0) + margin
            for obj in objects:
                gap = float(np.linalg.norm(centre - obj.position)) - bound - obj.bound
                if gap - pad - obj.padding >= min(best.clearance, self.FAR):
                    continue
                self._res.clear()
                dist = float(coal.distance(shape, tf, obj.shape, obj.tf, self._req, self._res))
                clearance = dist - pad - obj.padding
                if clearance < best.clearance:
                    best = Contact(clearance, dist, link, obj)
        return best
