"""Self-collision between link primitives (tms_rc.excavator.collision) and its rows in the ID hierarchy (ZX200).

(a) distances against hand-computed values: the bucket box's corners built by hand from the kinematics' pin and
tip and the settings' sizes, against the body boxes' faces; (b) the rows (d_dot = row @ qd) against finite
differences of coal's distance, and the drift (d_ddot at qdd = 0) where the normal cannot turn; (c) the sphere
prefilter skips nothing within d_i; (d) the pairs left out of the default never come near; (e) in the ID
hierarchy a reference that drives the curled bucket into the upper structure: with the pair rows the distance
stays >= d_s while the tip position task gives way, without them the bucket goes into the body.
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

PAIRS = ("bucket/undercarriage", "bucket/upper", "bucket/cab", "bucket/boom")


@pytest.fixture(scope="module")
def kin():
    return load_kinematics("zx200")


@pytest.fixture(scope="module")
def col(kin):
    return SelfCollision(kin.model, kin.machine)


def _bucket_corners(kin, settings: CollisionSettings, q: np.ndarray) -> np.ndarray:
    """The bucket box's 8 corners in base_link, by hand: pin -> tip axis, the front's lateral axis, their normal."""
    _, _, pin_p, _ = kin.jacobians(q)
    tip = kin.tip_position(q)
    length = float(np.linalg.norm(tip - pin_p))
    x = (tip - pin_p) / length
    y = np.array([-math.sin(q[0]), math.cos(q[0]), 0.0])  # the front's pitch axis turns with the swing
    z = np.cross(x, y)
    half = (0.5 * length, 0.5 * kin.machine.bucket.width, 0.5 * settings.bucket_height)
    centre = 0.5 * (pin_p + tip)
    return np.array([centre + a * half[0] * x + b * half[1] * y + c * half[2] * z
                     for a, b, c in itertools.product((-1, 1), repeat=3)])


def test_distance_to_the_upper_structure_front_by_hand(kin, col):
    """Curled bucket in front of the deck: d = nearest corner's x - the deck's front face; the swing turns both."""
    s = col.settings
    q = np.array([0.0, -0.4, 2.46, 0.98])
    corners = _bucket_corners(kin, s, q)
    near = corners[np.argmin(corners[:, 0])]
    front = kin.swing_origin[0] + s.upper_center[0] + 0.5 * s.upper_size[0]
    z0 = kin.swing_origin[2] + s.upper_center[2] - 0.5 * s.upper_size[2]
    assert z0 < near[2] < z0 + s.upper_size[2]  # the corner faces the front face (not its edge)
    expected = float(near[0] - front)
    assert 0.05 < expected < 0.5  # a gap, not an overlap, within d_i
    d = col.distances(q)
    assert d[PAIRS.index("bucket/upper")] == pytest.approx(expected, abs=1e-6)
    col.evaluate(q)
    k = PAIRS.index("bucket/upper")
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
    corners = _bucket_corners(kin, s, q)
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
    """Bucket curled into the deck (boom down, arm in): coal's signed distance, and the normal still points from
    the bucket to the deck (towards -x)."""
    q = np.array([0.0, -0.1, 2.68, 0.87])
    k = PAIRS.index("bucket/upper")
    assert col.distances(q)[k] < -0.1
    col.evaluate(q)
    assert col.active[k] and col.normal[k][0] < -0.5


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
        for name in ("bucket/upper", "bucket/cab", "bucket/boom"):
            assert abs(rows[col.names.index(name)][0]) < 1e-9
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
    """The claim behind the default pair list: arm/body and boom/undercarriage stay > 0.7 m apart over the joint
    range (the undercarriage does not turn: at the front and at the side)."""
    pairs = (("arm", "upper"), ("arm", "cab"), ("arm", "undercarriage"), ("boom", "undercarriage"))
    col = SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=pairs))
    lim = kin.limits
    grids = [np.linspace(lim.lower[i], lim.upper[i], 11) for i in (1, 2, 3)]
    least = np.full(len(pairs), np.inf)
    for swing, qb, qa, qk in itertools.product((0.0, math.pi / 2), *grids):
        least = np.minimum(least, col.distances(np.array([swing, qb, qa, qk])))
    assert np.all(least > 0.7), dict(zip(col.names, least, strict=True))
    # and the default pairs do come near (so a check that passes everything would fail above or here)
    default = SelfCollision(kin.model, kin.machine)
    least = np.full(len(PAIRS), np.inf)
    for qb, qa, qk in itertools.product(*grids):
        least = np.minimum(least, default.distances(np.array([0.0, qb, qa, qk])))
    assert np.all(least < 0.5), dict(zip(PAIRS, least, strict=True))


def test_bad_pair_names_are_refused(kin):
    with pytest.raises(ConfigError, match="bucket, cabin"):
        SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=(("bucket", "cabin"),)))
    with pytest.raises(ConfigError, match="bucket, bucket"):
        SelfCollision(kin.model, kin.machine, CollisionSettings(pairs=(("bucket", "bucket"),)))


# ---------------------------------------------------------------------------- in the ID hierarchy
Q_START = np.array([0.0, -0.6, 1.6, 0.8])  # bucket out in front, clear of everything
Q_GOAL = np.array([0.0, -0.15, 2.6, 0.8])  # within the joint limits, bucket curled into the deck


def _approach(dyn, kin, settings: IdSettings, duration: float = 3.0, total: float = 5.0):
    """Closed loop on the rigid-body model: minimum-jerk tip and theta_w references from Q_START's to Q_GOAL's,
    the ID's accelerations integrated (semi-implicit Euler). Returns per step the pairs' distances, the tip
    position error, the theta_w error; and the controller."""
    ctl = InverseDynamicsHQP(dyn, kin, settings)
    check = SelfCollision(kin.model, kin.machine)
    p0, p1 = kin.tip_position(Q_START), kin.tip_position(Q_GOAL)
    t0, t1 = kin.theta_w(Q_START), kin.theta_w(Q_GOAL)
    q, qd, dt = Q_START.copy(), np.zeros(4), ctl.dt
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
    """The reference ends with the bucket 0.2 m inside the deck. The swing-axis rows (the old stand-in) are set
    out of the way (body_min_radius 0.5 m) so only the pair rows can stop it."""
    dyn = FrontDynamics(kin.machine)
    on = IdSettings(body_min_radius=0.5)
    k = PAIRS.index("bucket/upper")
    check = SelfCollision(kin.model, kin.machine)
    assert check.distances(Q_GOAL)[k] < -0.1 and check.distances(Q_START).min() > 2.0
    dist, pos_err, th_err, ctl = _approach(dyn, kin, on)
    ds, di = on.self_collision_safety, on.self_collision_influence
    assert dist.min() >= ds - 0.01, dist.min(axis=0)  # every pair stays at the safety distance
    assert dist[:, k].min() < di  # and the deck's row did act
    assert dist[-1, k] < ds + 0.1  # the bucket ends pressed against the safety distance, not held far off
    # the position task gave way (it is below the collision level); theta_w (above position) did not
    assert pos_err[-1] > 0.2
    assert abs(th_err[-1]) < 1e-3
    # without the pair rows the same reference goes into the deck, and the tip reaches its reference
    dist_off, pos_err_off, _, ctl_off = _approach(dyn, kin, IdSettings(body_min_radius=0.5, self_collision=False))
    assert ctl_off.collision is None and ctl.collision is not None
    assert dist_off[:, k].min() < -0.1
    assert pos_err_off[-1] < 0.05
    assert pos_err[-1] > pos_err_off[-1] + 0.15


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
