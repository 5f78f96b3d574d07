"""Self-collision of an excavator: box primitives of the front links and the machine body, closest points by coal.

HEAP keeps its links apart with a velocity damper on the distance between collision primitives (Jud et al. 2021,
"HEAP - The autonomous walking excavator", sec. 4.3.1-4.3.2: boxes, closest points from Bullet; the damper of
Faverjon & Tournassoud, ICRA 1987, "A local based approach for path planning of manipulators with a high number of
degrees of freedom", doi:10.1109/ROBOT.1987.1087982). Here the closest points come from coal (the maintained fork
of hpp-fcl: GJK/EPA on convex primitives, signed distance when they overlap), never from a routine of our own.

Primitives (boxes):

- ``boom``, ``arm``, ``bucket``: the machine description's link boxes (``link_boxes:`` of
  ``config/machines/<kind>.yaml``, :class:`tms_model.machines.LinkBox`: full lengths and centre in the link's URDF
  frame, axes along the link frame's), the boxes the plant's links are and the arm planner checks;
- ``upper`` (upper structure: deck, engine hood, counterweight): the description's ``body_link`` box, the upper
  structure the plant and the planner use (it turns with the swing);
- ``cab``: a box turning with the swing, and ``undercarriage``: a box fixed in base_link over the description's
  track footprint; the description has no cab or undercarriage box, so their sizes are :class:`CollisionSettings`'.

Pairs (``CollisionSettings.pairs``): the ones that can meet (any two primitives may be named; the default is the
bucket vs the undercarriage and the cab: with the description's boxes nothing else on the ZX200 comes within d_i
without also overlapping at poses the machine reaches, see :attr:`CollisionSettings.pairs`).
Never checked: neighbours on a joint (boom/upper, boom/arm, arm/bucket: they touch at their pin by construction)
and boom/cab (the boom pivots beside the cab at a lateral
clearance fixed by the design, which no joint changes).

Per pair, with ``p_a``, ``p_b`` the closest points on a and b and ``n = (p_b - p_a)/|p_b - p_a|`` (coal's normal,
a -> b; also defined when the boxes overlap, then d < 0):

    d_dot  = n^T (J_b(p_b) - J_a(p_a)) qd                       = ``row @ qd``   (the task's n^T (J_a - J_b) qd
                                                                                  with n = (p_a - p_b)/d)
    d_ddot = row @ qdd + n^T (a_b(p_b) - a_a(p_a))|_{qdd = 0}    = ``row @ qdd + drift``

J(p) is the Jacobian of the material point of the link at p (pinocchio joint Jacobians, LOCAL_WORLD_ALIGNED);
``drift`` is those points' acceleration at qdd = 0 (centripetal and Coriolis). Left out: the normal's rotation,
``n_dot . (v_b - v_a)``, second order in the relative speed and zero when the closest feature of the other body is
a face of a body that does not turn (the undercarriage); the damper's safety distance absorbs it. A hierarchy then
adds, for the active pairs (d < d_i), the first-order damper ``row @ qd >= -xi (d - d_s)/(d_i - d_s)`` (an IK over
joint velocities: :meth:`SelfCollision.first_order`) or the second-order one of the ID
(``row @ qdd + drift >= -(xi/T)(d - d_s)/(d_i - d_s) - d_dot/T``, :mod:`tms_rc.excavator.id_hqp`).

Cost: a pair whose bounding spheres are farther apart than d_i costs a subtraction and a norm; coal only sees the
others (one box-box GJK: ~1-2 us), and the Jacobians of a link are only read for an active pair.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import JOINTS
from tms_model.machines import EXCAVATOR, Machine

__all__ = ["PRIMITIVES", "CollisionSettings", "SelfCollision"]

#: primitive names and the joint that carries them ("" = none: fixed in base_link)
PRIMITIVES = {"undercarriage": "", "upper": JOINTS[0], "cab": JOINTS[0], "boom": JOINTS[1], "arm": JOINTS[2],
              "bucket": JOINTS[3]}
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class CollisionSettings:
    """Sizes of the primitives the description gives no box for (cab, undercarriage), and the pairs checked.

    The boom, arm, bucket and upper structure boxes are the description's ``link_boxes``; the undercarriage's
    length and width its track footprint. Every figure here is ours, for a 20 t class machine (ZX200), and says why.
    """

    #: [m] cab (length x, width y, height z) and centre in body_link: a ~0.9 m wide, 1.7 m long cab on the left
    #: (+y) front of the deck, beside the boom, its roof 1.8 m above the body frame (ZX200 class: ~2.95 m overall
    #: height); its inner side 0.35 m left of the swing axis leaves the boom box (the description's, 0.6 m wide
    #: on the front's plane) clear of it, as on the machine
    cab_size: tuple[float, float, float] = (1.7, 0.9, 1.8)
    cab_center: tuple[float, float, float] = (0.45, 0.8, 0.9)
    #: [m] height of the undercarriage box (tracks and car body) from the ground (base_link z = 0); its length and
    #: width are the description's track footprint. 0.9 m: a 20 t crawler's track height (~0.9 m class)
    undercarriage_height: float = 0.9
    #: the pairs checked, (a, b): names of :data:`PRIMITIVES`. On the ZX200 with the description's boxes only the
    #: bucket comes near the body, over the joint range: bucket/undercarriage to -0.15 m (overlap, swung ~45 deg
    #: over a track end), bucket/cab to 0.44 m (within d_i). Left out (tests/tms_rc/test_collision.py checks each
    #: claim): bucket/upper (the body box ends 0.5 m ahead of the swing axis: never closer than 1.4 m, beyond any
    #: d_i); bucket/boom (the boxes overlap, to -0.79 m, over a fifth of the legal joint range, e.g. arm crowded
    #: and bucket curled: the boom box is the boom's pin-to-pin envelope, not its underside, so the pair would
    #: forbid poses the machine reaches; name it with boxes that follow the boom); arm/upper, arm/cab,
    #: arm/undercarriage and boom/undercarriage (never closer than 0.8 m)
    pairs: tuple[tuple[str, str], ...] = (("bucket", "undercarriage"), ("bucket", "cab"))


@dataclass(eq=False)
class _Primitive:
    name: str
    joint: int  # pinocchio joint id (0 = fixed in base_link)
    shape: coal.Box
    local: np.ndarray  # 4 x 4 pose of the box (axes, centre) in the joint frame
    half: np.ndarray  # half extents
    index: int  # row in the per-step pose arrays


class SelfCollision:
    """Distances, closest points and damper rows of the collision pairs, on a pinocchio model of the front.

    Args:
        model: a pinocchio model whose joints are named :data:`JOINTS` (the kinematics' or the dynamics' model).
        machine: the description it was built from (link boxes, track footprint).
        settings: sizes and pairs.

    Call :meth:`update` after forward kinematics (and, for rows and drift, joint Jacobians and velocities) on a
    ``data`` of ``model``; read the arrays (one entry per pair; valid where ``active``).
    """

    def __init__(self, model: pin.Model, machine: Machine, settings: CollisionSettings | None = None) -> None:
        machine.require(EXCAVATOR)
        # the primitive on each joint's child link is that link's box: body_link's is the upper structure
        links = {name: machine.joint(PRIMITIVES[name]).child for name in ("upper", "boom", "arm", "bucket")}
        missing = [link for link in links.values() if link not in machine.link_boxes]
        if missing:
            raise ConfigError(f"{machine.source}: self-collision needs link_boxes of {missing}")
        s = settings or CollisionSettings()
        self.settings = s
        self.model = model
        self.data = model.createData()
        fp = machine.footprint
        boxes = {  # (centre, size) in the joint frame, axes along it
            "undercarriage": ((0.0, 0.0, 0.5 * s.undercarriage_height), (fp.length, fp.width, s.undercarriage_height)),
            "cab": (s.cab_center, s.cab_size),
        }
        for name, link in links.items():  # the description's boxes (config/machines/<kind>.yaml link_boxes)
            box = machine.link_boxes[link]
            boxes[name] = (box.offset, box.size)
        prims: dict[str, _Primitive] = {}
        for name, joint in PRIMITIVES.items():
            pos, size = boxes[name]
            if min(size) <= 0.0:
                raise ConfigError(f"self-collision primitive {name}: size {size} must be positive")
            jid = model.getJointId(joint) if joint else 0
            if joint and jid >= model.njoints:
                raise ConfigError(f"self-collision: the model has no joint {joint!r}")
            local = np.eye(4)
            local[:3, 3] = pos
            prims[name] = _Primitive(name, jid, coal.Box(*size), local, 0.5 * np.array(size, dtype=float), len(prims))
        for a, b in s.pairs:
            bad = [x for x in (a, b) if x not in prims]
            if bad or a == b:
                raise ConfigError(f"self-collision pair ({a}, {b}): names must be two of {sorted(prims)}")
        self.primitives = prims
        self.names = tuple(f"{a}/{b}" for a, b in s.pairs)
        self._pairs = [(prims[a], prims[b]) for a, b in s.pairs]
        plist = list(prims.values())
        # per step: the joints' placements (row 0: base_link, identity), gathered per primitive and composed with
        # the primitives' local poses in one matmul
        self._joints = sorted({p.joint for p in plist if p.joint})
        self._h = np.tile(np.eye(4), (len(self._joints) + 1, 1, 1))
        self._h_of = np.array([0 if p.joint == 0 else 1 + self._joints.index(p.joint) for p in plist])
        self._local = np.array([p.local for p in plist])
        self._world = np.zeros((len(plist), 4, 4))
        half = np.array([p.half for p in plist])
        self._ia = np.array([a.index for a, _ in self._pairs])
        self._ib = np.array([b.index for _, b in self._pairs])
        radius = np.sqrt((half**2).sum(axis=1))  # bounding spheres (half diagonals)
        self._rsum = (radius[self._ia] + radius[self._ib]).tolist()
        self._tf = [coal.Transform3s() for _ in plist]
        self._placed = [False] * len(plist)  # coal transform set at this update
        n_pairs, nv = len(s.pairs), model.nv
        self.distance = np.full(n_pairs, np.inf)  # [m] inf where the prefilter skipped the pair
        self.active = np.zeros(n_pairs, dtype=bool)
        self.rows = np.zeros((n_pairs, nv))  # d_dot = rows[k] @ qd
        self.drift = np.zeros(n_pairs)  # [m/s^2] d_ddot at qdd = 0 (without the normal's rotation)
        self.point_a = np.zeros((n_pairs, 3))
        self.point_b = np.zeros((n_pairs, 3))
        self.normal = np.zeros((n_pairs, 3))  # a -> b
        self._req = coal.DistanceRequest()
        self._res = coal.DistanceResult()
        self._jac: dict[int, np.ndarray] = {}

    def pose(self, name: str) -> np.ndarray:
        """4 x 4 pose in base_link of primitive ``name``'s box (axes, centre) at the last update (a copy)."""
        return self._world[self.primitives[name].index].copy()

    # ------------------------------------------------------------------ per step
    def update(self, data: pin.Data, influence: float, *, rows: bool = True, drift: bool = True,
               prefilter: bool = True) -> int:
        """Distances of the pairs at the state in ``data``; rows and drift of those closer than ``influence``.

        ``data`` needs ``oMi`` (forward kinematics); ``rows`` needs the joint Jacobians
        (``pin.computeJointJacobians``), ``drift`` the joint velocities and accelerations at qdd = 0
        (``pin.forwardKinematics(model, data, q, qd, 0)``). ``prefilter=False`` asks coal for every pair.
        Returns the number of active pairs (d < influence).
        """
        h = self._h
        for i, joint in enumerate(self._joints, start=1):
            h[i] = data.oMi[joint].homogeneous
        world = np.matmul(h[self._h_of], self._local, out=self._world)
        pos = world[:, :3, 3].tolist()  # plain floats: the sphere test of a pair costs no numpy call
        self._jac.clear()
        self.active[:] = False
        self.distance.fill(np.inf)
        res, req, tfs, placed = self._res, self._req, self._tf, self._placed
        for i in range(len(placed)):
            placed[i] = False
        count = 0
        for k, (pa, pb) in enumerate(self._pairs):
            if prefilter:  # bounding spheres (half diagonals) farther apart than d_i: d > d_i, skip coal
                (xa, ya, za), (xb, yb, zb) = pos[pa.index], pos[pb.index]
                gap = math.sqrt((xa - xb) ** 2 + (ya - yb) ** 2 + (za - zb) ** 2) - self._rsum[k]
                if gap >= influence:
                    continue
            for p in (pa, pb):
                if not placed[p.index]:
                    tfs[p.index].setTransform(world[p.index, :3, :3], world[p.index, :3, 3])
                    placed[p.index] = True
            res.clear()
            d = coal.distance(pa.shape, tfs[pa.index], pb.shape, tfs[pb.index], req, res)
            self.distance[k] = d
            if d >= influence:
                continue
            self.active[k] = True
            count += 1
            p1, p2, n = res.getNearestPoint1(), res.getNearestPoint2(), res.normal
            self.point_a[k], self.point_b[k], self.normal[k] = p1, p2, n
            if rows:
                self.rows[k] = self._point_row(data, pb.joint, p2, n) - self._point_row(data, pa.joint, p1, n)
            if drift:
                self.drift[k] = float(n @ (self._point_accel(data, pb.joint, p2)
                                           - self._point_accel(data, pa.joint, p1)))
        return count

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Signed distance [m] of every pair at ``q`` (no prefilter; this object's own pinocchio data; a copy)."""
        pin.forwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        self.update(self.data, math.inf, rows=False, drift=False, prefilter=False)
        return self.distance.copy()

    def evaluate(self, q: np.ndarray, qd: np.ndarray | None = None, influence: float = math.inf) -> int:
        """:meth:`update` at (q, qd) on this object's own data (tools and tests; the ID reuses its model's data)."""
        q = np.asarray(q, dtype=float)
        qd = np.zeros(self.model.nv) if qd is None else np.asarray(qd, dtype=float)
        pin.forwardKinematics(self.model, self.data, q, qd, np.zeros(self.model.nv))
        pin.computeJointJacobians(self.model, self.data, q)
        return self.update(self.data, influence, prefilter=False)

    def first_order(self, xi: float, safety: float, influence: float) -> tuple[np.ndarray, np.ndarray]:
        """The active pairs' first-order damper ``rows @ qd >= lower``, ``lower = -xi (d - d_s)/(d_i - d_s)``
        (Faverjon & Tournassoud), for an IK over joint velocities; call after :meth:`update`."""
        k = self.active
        return self.rows[k], -xi * (self.distance[k] - safety) / (influence - safety)

    # ------------------------------------------------------------------ helpers
    def _joint_jacobian(self, data: pin.Data, joint: int) -> np.ndarray:
        jac = self._jac.get(joint)
        if jac is None:
            jac = self._jac[joint] = pin.getJointJacobian(self.model, data, joint, _LWA)
        return jac

    def _point_row(self, data: pin.Data, joint: int, p: np.ndarray, n: np.ndarray) -> np.ndarray:
        """n^T J(p) for the material point at p of the link on ``joint`` (zero row when fixed)."""
        if joint == 0:
            return np.zeros(self.model.nv)
        jac = self._joint_jacobian(data, joint)
        r = p - data.oMi[joint].translation
        return n @ jac[:3] + np.cross(r, n) @ jac[3:]  # n.(v + w x r) = n.v + (r x n).w

    @staticmethod
    def _point_accel(data: pin.Data, joint: int, p: np.ndarray) -> np.ndarray:
        """Classical acceleration [m/s^2] of the material point at p of the link on ``joint``, from data.v/a."""
        if joint == 0:
            return np.zeros(3)
        omi = data.oMi[joint]
        rot = omi.rotation
        v, a = data.v[joint], data.a[joint]
        w = rot @ v.angular
        a0 = rot @ (a.linear + np.cross(v.angular, v.linear))
        r = p - omi.translation
        return a0 + np.cross(rot @ a.angular, r) + np.cross(w, np.cross(w, r))
