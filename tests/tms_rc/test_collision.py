"""Self-collision between link primitives (tms_rc.excavator.collision) and its rows in the ID hierarchy (ZX200).

(a) distances against hand-computed values: the bucket box's corners built by hand from the description's
bucket_link box (size, offset) in the bucket_link frame (the kinematics' pin, the joints' pitches), against the
faces of the description's body box and of the track footprint; (b) the rows (d_dot = row @ qd) against finite
differences of coal's distance, and the drift (d_ddot at qdd = 0) where the normal cannot turn; (c) the sphere
prefilter skips nothing within d_i; (d) the pairs left out of the default never come within d_i, or (bucket/boom)
overlap at poses the machine reaches; (e) in the ID hierarchy a reference that drives the bucket, swung over a
track end, into the undercarriage: with the pair rows the distance stays >= d_s while the tip position task gives
way, without them the bucket goes into the tracks.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.collision import CollisionSettings, SelfCollision
from tms_rc.excavator.dynamics import FrontDynamics
from tms_rc.excavator.id_hqp import IdReference, IdSettings, InverseDynamicsHQP

PAIRS = ("bucket/undercarriage", "bucket/cab")
#: every pair of the bucket with the body and the boom (the distance checks of pairs left out of the default)
ALL_BUCKET = (("bucket", "undercarriage"), ("bucket", "upper"), ("bucket", "cab"), ("bucket", "boom"))


@pytest.fixture(scope="module")
def kin():
    return load_kinematics("zx200")


@pytest.fixture(scope="module")
def col(kin):
    return SelfCollision(kin.model, kin.machine)


@pytest.fixture(scope="module")
def col_all(kin):
    return SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=ALL_BUCKET))


def _bucket_box(kin, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bucket box's centre, axes and half lengths in base_link, by hand from the description: bucket_link's box
    (full lengths, centre in the link frame); the link frame at the bucket pin, turned by the swing about z and
    pitched about y by the joints' origin pitches plus boom + arm + bucket."""
    machine = kin.machine
    box = machine.link_boxes["bucket_link"]
    _, _, pin_p, _ = kin.jacobians(q)
    pitch = sum(j.origin_rpy[1] for j in machine.joints[1:]) + float(q[1] + q[2] + q[3])
    cs, ss, cp, sp = math.cos(q[0]), math.sin(q[0]), math.cos(pitch), math.sin(pitch)
    rot = np.array([[cs, -ss, 0.0], [ss, cs, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return pin_p + rot @ np.array(box.offset), rot, 0.5 * np.array(box.size)


def _bucket_corners(kin, q: np.ndarray) -> np.ndarray:
    """The bucket box's 8 corners in base_link (:func:`_bucket_box`)."""
    centre, rot, half = _bucket_box(kin, q)
    return np.array([centre + rot @ (np.array(signs) * half) for signs in itertools.product((-1, 1), repeat=3)])


def test_distance_to_the_upper_structure_front_by_hand(kin, col_all):
    """Curled bucket in front of the deck: d = nearest corner's x - the front face of the description's body box
    (its centre 0.9 m behind the swing axis, 2.8 m long: the face 0.5 m ahead of the axis); the swing turns both.
    Even curled in close, the bucket stays beyond d_i of it: why bucket/upper is not a default pair."""
    body = kin.machine.link_boxes["body_link"]
    q = np.array([0.0, -0.15, 2.6, 0.8])
    corners = _bucket_corners(kin, q)
    near = corners[np.argmin(corners[:, 0])]
    front = kin.swing_origin[0] + body.offset[0] + 0.5 * body.size[0]
    assert front - kin.swing_origin[0] == pytest.approx(0.5)
    z0 = kin.swing_origin[2] + body.offset[2] - 0.5 * body.size[2]
    assert z0 < near[2] < z0 + body.size[2]  # the corner faces the front face (not its edge)
    assert abs(near[1] - kin.swing_origin[1]) < 0.5 * body.size[1]
    expected = float(near[0] - front)
    assert expected > 1.4  # a gap beyond any d_i
    k = col_all.names.index("bucket/upper")
    assert col_all.distances(q)[k] == pytest.approx(expected, abs=1e-6)
    col_all.evaluate(q)
    col = col_all
    # the corner is an edge along y: its x and z are the closest point's
    assert col.point_a[k][[0, 2]] == pytest.approx(near[[0, 2]], abs=1e-6)
    assert col.point_b[k][0] == pytest.approx(front, abs=1e-6)
    np.testing.assert_allclose(col.normal[k], [-1.0, 0.0, 0.0], atol=1e-9)  # bucket -> body: towards -x
    # the upper structure turns with the swing: the same distance at any swing
    for swing in (0.7, -2.0):
        assert col.distances(np.array([swing, *q[1:]]))[k] == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize("swing", [0.0, math.pi / 2])
def test_distance_to_the_undercarriage_by_hand(kin, col, swing):
    """Bucket down by the tracks: ahead of them (swing 0: front face x = length/2) and beside them (swing 90 deg:
    side face y = width/2); the undercarriage is centred on base_link and does not turn with the swing."""
    s = col.settings
    fp = kin.machine.footprint
    q = np.array([swing, -0.1, 2.68, -0.07])
    corners = _bucket_corners(kin, q)
    axis = 0 if swing == 0.0 else 1
    face = 0.5 * (fp.length if axis == 0 else fp.width)
    near = corners[np.argmin(corners[:, axis])]
    assert 0.0 < near[2] < s.undercarriage_height  # the corner faces the face
    assert abs(near[1 - axis]) < 0.5 * (fp.width if axis == 0 else fp.length)
    expected = float(near[axis] - face)
    assert expected > 0.05
    k = PAIRS.index("bucket/undercarriage")
    assert col.distances(q)[k] == pytest.approx(expected, abs=1e-6)


def test_overlap_is_a_negative_distance(kin, col):
    """Bucket swung 43 deg over the front end of the left track, boom down, arm in (all within the joint limits):
    by hand, the undercarriage box's front-left vertical edge (x = length/2, y = width/2 of the footprint) runs
    inside the bucket box at 0.8 m; coal's signed distance is negative, and the normal points from the bucket
    into the undercarriage (horizontal, towards -x and -y)."""
    q = np.array([0.75, -0.12, 2.65, 0.4])
    lim = kin.limits
    assert np.all(q[1:] >= lim.lower[1:]) and np.all(q[1:] <= lim.upper[1:])
    fp = kin.machine.footprint
    centre, rot, half = _bucket_box(kin, q)
    edge = np.array([0.5 * fp.length, 0.5 * fp.width, 0.8])
    assert edge[2] < col.settings.undercarriage_height
    assert np.all(np.abs(rot.T @ (edge - centre)) < half)  # inside the bucket box
    k = PAIRS.index("bucket/undercarriage")
    assert col.distances(q)[k] < -0.05
    col.evaluate(q)
    n = col.normal[k]
    assert col.active[k] and n[0] < -0.5 and n[1] < -0.5 and abs(n[2]) < 1e-6


def _fd_rows(col, q, h=1e-6):
    """Central differences of every pair's distance per joint, and whether forward and backward agree."""
    n = len(q)
    grad = np.zeros((len(col.names), n))
    smooth = np.ones((len(col.names), n), dtype=bool)
    d0 = col.distances(q)
    for i in range(n):
        e = np.zeros(n)
        e[i] = h
        dp, dm = col.distances(q + e), col.distances(q - e)
        grad[:, i] = (dp - dm) / (2 * h)
        smooth[:, i] = np.abs((dp - d0) - (d0 - dm)) < 1e-3 * h + 1e-9  # no kink of the distance here
    return grad, smooth


def test_rows_match_finite_differences(kin, col):
    """d_dot = row @ qd: each column of the row against the central difference of coal's distance."""
    rng = np.random.default_rng(7)
    lo, hi = kin.limits.lower.copy(), kin.limits.upper.copy()
    lo[0], hi[0] = -math.pi, math.pi
    compared = 0
    for _ in range(40):
        q = rng.uniform(lo, hi)
        col.evaluate(q)
        rows, dist = col.rows.copy(), col.distance.copy()
        grad, smooth = _fd_rows(col, q)
        for k in range(len(col.names)):
            if dist[k] <= 0.01:
                continue
            ok = smooth[k]
            np.testing.assert_allclose(rows[k][ok], grad[k][ok], atol=2e-5, err_msg=f"{col.names[k]} at {q}")
            compared += int(ok.sum())
        # the bucket and the body parts on the swing turn together: the swing never changes their distance
        assert abs(rows[col.names.index("bucket/cab")][0]) < 1e-9
    assert compared > 300  # most samples are smooth: the comparison really ran


def test_drift_matches_second_difference(kin, col):
    """Along q(t) = q + t qd (qdd = 0) the distance to the undercarriage's front face (a face of a body that does
    not turn: n constant) has d_ddot = drift; against the second central difference of coal's distance."""
    k = PAIRS.index("bucket/undercarriage")
    q = np.array([0.0, -0.1, 2.68, -0.07])
    for qd in (np.array([0.0, -0.3, 0.4, 0.8]), np.array([0.0, 0.2, -0.5, -0.6])):
        col.evaluate(q, qd)
        drift, row = float(col.drift[k]), col.rows[k].copy()
        assert abs(col.normal[k][0] + 1.0) < 1e-9  # the front face: n along -x
        h = 1e-3
        dp, d0, dm = (col.distances(q + t * qd)[k] for t in (h, 0.0, -h))
        assert row @ qd == pytest.approx((dp - dm) / (2 * h), abs=1e-6)
        assert abs(drift) > 0.05  # a real centripetal term, not zero
        assert drift == pytest.approx((dp - 2 * d0 + dm) / h**2, rel=1e-3, abs=1e-4)


def test_prefilter_skips_only_far_pairs(kin, col):
    """Over random poses the sphere prefilter finds the same active pairs and distances as coal on every pair."""
    rng = np.random.default_rng(3)
    lo, hi = kin.limits.lower.copy(), kin.limits.upper.copy()
    lo[0], hi[0] = -math.pi, math.pi
    lo[1], lo[2] = -0.5, 2.0  # boom down and arm in: the bucket near the body on many poses
    influence = 0.5
    near = 0
    for _ in range(300):
        q = rng.uniform(lo, hi)
        full = col.distances(q)
        col.update(col.data, influence, rows=False, drift=False)  # same data, prefilter on
        expected = full < influence
        np.testing.assert_array_equal(col.active, expected)
        np.testing.assert_allclose(col.distance[expected], full[expected], atol=1e-12)
        assert np.all(full[~np.isfinite(col.distance)] >= influence)
        near += int(expected.sum())
    assert near > 5  # some poses do come within d_i


def test_pairs_left_out_never_come_near(kin):
    """The claims behind the default pair list, over the joint range (the undercarriage does not turn: swung to the
    front, over a track end and to the side): arm/body and boom/undercarriage stay > 0.7 m apart and bucket/upper
    beyond d_i (> 1 m); bucket/boom overlaps at legal poses (its boxes cannot tell a reachable pose from a
    collision); the default pairs do come within d_i, bucket/undercarriage into an overlap."""
    pairs = (("arm", "upper"), ("arm", "cab"), ("arm", "undercarriage"), ("boom", "undercarriage"),
             ("bucket", "upper"), ("bucket", "boom"), *((a, b) for a, b in ALL_BUCKET if f"{a}/{b}" in PAIRS))
    col = SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=pairs))
    lim = kin.limits
    grids = [np.linspace(lim.lower[i], lim.upper[i], 11) for i in (1, 2, 3)]
    least = np.full(len(pairs), np.inf)
    for swing, qb, qa, qk in itertools.product((0.0, math.pi / 4, math.pi / 2), *grids):
        least = np.minimum(least, col.distances(np.array([swing, qb, qa, qk])))
    got = dict(zip(col.names, least, strict=True))
    assert all(got[n] > 0.7 for n in ("arm/upper", "arm/cab", "arm/undercarriage", "boom/undercarriage")), got
    assert got["bucket/upper"] > 1.0, got
    assert got["bucket/boom"] < -0.5, got  # arm crowded, bucket curled: within the limits, the boxes overlap
    assert set(col.names[6:]) == set(PAIRS)
    # and the default pairs do come near (so a check that passes everything would fail above or here)
    assert all(got[n] < 0.5 for n in PAIRS) and got["bucket/undercarriage"] < 0.0, got


def test_bad_pair_names_are_refused(kin):
    with pytest.raises(ConfigError, match="bucket, cabin"):
        SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=(("bucket", "cabin"),)))
    with pytest.raises(ConfigError, match="bucket, bucket"):
        SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=(("bucket", "bucket"),)))


# ---------------------------------------------------------------------------- in the ID hierarchy
Q_START = np.array([0.75, -0.6, 1.6, 0.8])  # swung 43 deg, bucket out in front, clear of everything
Q_GOAL = np.array([0.75, -0.12, 2.65, 0.4])  # within the joint limits, bucket into the front end of the left track


def _approach(dyn, kin, settings: IdSettings, duration: float = 3.0, total: float = 5.0, start=Q_START, goal=Q_GOAL):
    """Closed loop on the rigid-body model: minimum-jerk tip and theta_w references from ``start``'s to ``goal``'s,
    the ID's accelerations integrated (semi-implicit Euler). Returns per step the distances of the settings'
    pairs, the tip position error, the theta_w error; and the controller."""
    ctl = InverseDynamicsHQP(dyn, kin, settings)
    check = SelfCollision(kin.model, kin.machine, settings.collision_primitives)
    p0, p1 = kin.tip_position(start), kin.tip_position(goal)
    t0, t1 = kin.theta_w(start), kin.theta_w(goal)
    q, qd, dt = start.copy(), np.zeros(4), ctl.dt
    dist, pos_err, th_err = [], [], []
    for k in range(round(total / dt)):
        s = min(k * dt / duration, 1.0)
        p = 10 * s**3 - 15 * s**4 + 6 * s**5
        v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
        a = (60 * s - 180 * s**2 + 120 * s**3) / duration**2
        ref = IdReference(position=p0 + p * (p1 - p0), velocity=v * (p1 - p0), acceleration=a * (p1 - p0),
                          theta_w=t0 + p * (t1 - t0), theta_w_rate=v * (t1 - t0), theta_w_accel=a * (t1 - t0))
        res = ctl.solve(q, qd, ref)
        assert not res.hqp.failed, res.hqp.failed
        qd = qd + dt * res.qdd
        q = q + dt * qd
        dist.append(check.distances(q))
        pos_err.append(float(np.linalg.norm(kin.tip_position(q) - ref.position)))
        th_err.append(kin.theta_w(q) - ref.theta_w)
    return np.array(dist), np.array(pos_err), np.array(th_err), ctl


def test_id_keeps_the_bucket_off_the_body(kin):
    """The reference ends with the bucket 0.1 m inside the track box. The swing-axis rows (the old stand-in) are
    set out of the way (body_min_radius 0.5 m) so only the pair rows can stop it."""
    dyn = FrontDynamics(kin.machine)
    on = IdSettings(body_min_radius=0.5)
    k = PAIRS.index("bucket/undercarriage")
    check = SelfCollision(kin.model, kin.machine)
    assert check.distances(Q_GOAL)[k] < -0.09 and check.distances(Q_START).min() > 2.0
    dist, pos_err, th_err, ctl = _approach(dyn, kin, on)
    ds, di = on.self_collision_safety, on.self_collision_influence
    assert dist.min() >= ds - 0.01, dist.min(axis=0)  # every pair stays at the safety distance
    assert dist[:, k].min() < di  # and the deck's row did act
    assert dist[-1, k] < ds + 0.1  # the bucket ends pressed against the safety distance, not held far off
    # the position task gave way (it is below the collision level); theta_w (above position) did not
    assert pos_err[-1] > 0.2
    assert abs(th_err[-1]) < 1e-3
    # without the pair rows the same reference goes into the tracks, and the tip reaches its reference
    dist_off, pos_err_off, _, ctl_off = _approach(dyn, kin, IdSettings(body_min_radius=0.5, self_collision=False))
    assert ctl_off.collision is None and ctl.collision is not None
    assert dist_off[:, k].min() < -0.09
    assert pos_err_off[-1] < 0.05
    assert pos_err[-1] > pos_err_off[-1] + 0.15


def test_id_completes_with_a_pair_overlapping_at_legal_poses(kin):
    """bucket/boom named (left out of the default: its boxes overlap at poses the machine reaches): driving the
    curled bucket towards the boom, its row binds; every level below must still be solved on every step (this run
    ended "maximum iterations reached" on the position level once the row bound, before the hierarchy relaxed the
    rows above to what they achieved and shortened unfinished OSQP iterates), and the pair is held at d_s."""
    settings = IdSettings(body_min_radius=0.5, collision_primitives=CollisionSettings(pairs=(("bucket", "boom"),)))
    start, goal = np.array([0.0, -0.6, 1.6, 0.8]), np.array([0.0, -0.15, 2.6, 0.8])
    dist, _, _, _ = _approach(FrontDynamics(kin.machine), kin, settings, total=3.0, start=start, goal=goal)
    assert dist[:, 0].min() >= settings.self_collision_safety - 0.01  # (_approach asserts no level failed)
    assert dist[:, 0].min() < settings.self_collision_influence


def test_id_pair_rows_free_when_far(kin):
    """At home every pair is beyond d_i: the collision level has no active pair row and costs no slack."""
    dyn = FrontDynamics(kin.machine)
    ctl = InverseDynamicsHQP(dyn, kin)
    q = kin.home.copy()
    res = ctl.solve(q, np.zeros(4), IdReference(position=kin.tip_position(q), theta_w=kin.theta_w(q)))
    assert not ctl.collision.active.any()
    assert np.all(ctl._b[5][4:] >= 1e8)
    assert res.hqp.slack["collision"] == 0.0
    assert ctl.levels[5].rows == 4 + len(PAIRS)
