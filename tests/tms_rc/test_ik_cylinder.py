"""The cylinder-space IK hierarchy (tms_rc.excavator.ik_cylinder) and its references (tms_rc.excavator.hermite).

No ROS, pure core, on the ZX200 description. (a) All limits slack: the tip and theta_w tasks are met and the
actuator velocities are the cylinders' length rates (checked against finite differences of the pin geometry);
(b) each limit task made active in turn (pump flow, cylinder velocity for the swing and for the cylinders, stroke,
ground and swing-axis clearance, the hook's extra collision row): the limit holds, the orientation task above the
position task is still met, only the position task gives way; the stroke and ground limits also over a kinematic
integration pushed into them; (c) the position task tracks a cubic Hermite reference on a kinematic integration of
the solution (tip error figures), and converges from an initial offset; with the pumps binding, the PID integral
holds while the hierarchy gives way; (d) the Hermite spline hits its knots with the given velocities and matches
the Hermite basis; (e) the PID's anti-windup (clamp, hold) against an unclamped integral.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.cylinders import cylinder_length
from tms_model.excavator.kinematics import load_kinematics
from tms_rc.excavator.collision import SelfCollision
from tms_rc.excavator.hermite import HermiteReference, Pid
from tms_rc.excavator.ik_cylinder import CylinderIkHQP, IkReference, IkSettings

#: relative tolerance of a binding limit (OSQP eps 1e-6 on rows scaled to O(1), fix tolerance 1e-5)
LIMIT_TOL = 1e-4
#: [m/s], [rad/s] a task counted as met
TASK_TOL = 1e-5
#: [m/s], [rad/s] absolute slack of a velocity or stroke row (unscaled rows: the hierarchy's fix tolerance 1e-5, x2)
ROW_TOL = 2e-5


@pytest.fixture(scope="module")
def kin():
    return load_kinematics("zx200")


def _plane(kin, i):
    joint = kin.machine.joints[i]
    return (joint.origin_xyz[0], joint.origin_xyz[2]), joint.origin_rpy[1]


def _length(kin, i, qi):
    return cylinder_length(kin.machine.cylinders.all[i - 1], *_plane(kin, i), qi)


def _flow_by_hand(kin, q, qd) -> float:
    """[m^3/s] main pumps' flow: each function on them (the description's flow_at_limit > 0) at its cylinder's
    length rate (finite difference of the pin geometry), cap area (count x pi bore^2 / 4) extending, annulus
    retracting."""
    total = 0.0
    for i in range(1, 4):
        joint = kin.machine.joints[i]
        if kin.machine.drives[joint.name].flow_at_limit <= 0.0:
            continue
        c = kin.machine.cylinders.all[i - 1]
        rate = (_length(kin, i, q[i] + 1e-6 * qd[i]) - _length(kin, i, q[i] - 1e-6 * qd[i])) / 2e-6
        bore_area = c.count * math.pi * c.bore**2 / 4
        area = bore_area if rate > 0 else bore_area - c.count * math.pi * c.rod**2 / 4
        total += area * abs(rate)
    return total


def _q_max(kin) -> float:
    return kin.machine.pump_flow / 60000.0


def _hold_at(kin, q, velocity, theta_w_rate=0.0) -> IkReference:
    """Reference at the present tip and theta_w, moving at ``velocity``: the command is the feed-forward alone."""
    return IkReference(position=kin.tip_position(q), velocity=np.asarray(velocity, dtype=float),
                       theta_w=kin.theta_w(q), theta_w_rate=theta_w_rate)


def _orientation_met_position_gave_way(res, min_gap=0.05):
    assert res.theta_w_rate == pytest.approx(res.theta_w_rate_cmd, abs=TASK_TOL), "orientation (above) gave way"
    assert np.linalg.norm(res.tip_velocity - res.tip_velocity_cmd) > min_gap, "position did not give way"
    assert res.gave_way
    assert not res.hqp.failed


def test_slack_limits_tasks_met_and_cylinder_rates(kin):
    ctl = CylinderIkHQP(kin)
    s = ctl.settings
    q = kin.home.copy()
    qd_meas = np.array([0.02, 0.0, 0.05, -0.05])
    err = np.array([0.01, -0.005, 0.015])  # inside the integral's zone
    ref = IkReference(position=kin.tip_position(q) + err, velocity=np.array([0.2, 0.1, -0.1]),
                      theta_w=kin.theta_w(q) + 0.01, theta_w_rate=0.05)
    res = ctl.solve(q, ref, qd=qd_meas)
    for name in ("pump_flow", "velocity_limits", "stroke_limits", "collision"):
        assert res.hqp.slack[name] == 0.0, (name, res.hqp.slack)
    # eq. 36 on the first step: v_ref + kp e + ki (dt e) + kd (v_ref - J qd)
    jac = kin.jacobians(q)[1]
    expected = ref.velocity + s.kp_position * err + s.ki_position * ctl.dt * err
    expected += s.kd_position * (ref.velocity - jac @ qd_meas)
    np.testing.assert_allclose(res.tip_velocity_cmd, expected, atol=1e-12)
    np.testing.assert_allclose(res.tip_velocity, res.tip_velocity_cmd, atol=TASK_TOL)
    np.testing.assert_allclose(jac @ res.qd, res.tip_velocity, atol=1e-12)
    assert res.theta_w_rate == pytest.approx(0.05 + s.kp_theta_w * 0.01, abs=TASK_TOL)
    # the decision vector is the swing speed and the cylinders' length rates
    assert res.v[0] == res.qd[0]
    for i in range(1, 4):
        rate = (_length(kin, i, q[i] + 1e-6 * res.qd[i]) - _length(kin, i, q[i] - 1e-6 * res.qd[i])) / 2e-6
        assert res.v[i] == pytest.approx(rate, rel=1e-6, abs=1e-9)
    assert res.pump_flow == pytest.approx(_flow_by_hand(kin, q, res.qd), rel=1e-6)


@pytest.mark.parametrize("velocity", [(-1.5, 0.0, 0.0), (0.0, 0.0, 1.5), (1.5, 0.0, 0.0)])
def test_pump_flow_limit(kin, velocity):
    ctl = CylinderIkHQP(kin)
    q = kin.home.copy()
    res = ctl.solve(q, _hold_at(kin, q, velocity))
    flow = _flow_by_hand(kin, q, res.qd)
    assert flow <= _q_max(kin) * (1 + LIMIT_TOL), flow
    assert flow >= _q_max(kin) * (1 - LIMIT_TOL), flow  # it binds: the demand would have gone beyond
    assert np.all(np.abs(res.v) <= ctl.speed_limits + ROW_TOL)  # the lower limits are kept as well
    _orientation_met_position_gave_way(res)


def test_swing_velocity_limit(kin):
    ctl = CylinderIkHQP(kin)
    q = kin.home.copy()
    tip = kin.tip_position(q)
    radial = math.hypot(*(tip[:2] - kin.swing_origin[:2]))
    tangential = np.array([-(tip[1] - kin.swing_origin[1]), tip[0] - kin.swing_origin[0], 0.0]) / radial
    w_max = kin.limits.velocity[0]  # the swing's "cylinder velocity" is its joint speed
    res = ctl.solve(q, _hold_at(kin, q, 1.5 * w_max * radial * tangential))  # swing 1.5x too fast
    assert abs(res.qd[0]) <= w_max * (1 + LIMIT_TOL)
    assert abs(res.qd[0]) >= w_max * (1 - LIMIT_TOL)  # it binds
    assert _flow_by_hand(kin, q, res.qd) <= _q_max(kin) * (1 + LIMIT_TOL)
    _orientation_met_position_gave_way(res)


def test_cylinder_velocity_limit(kin):
    v_max = 0.05  # [m/s] every cylinder: well inside the pumps
    ctl = CylinderIkHQP(kin, IkSettings(speed_limits=(1.1, v_max, v_max, v_max)))
    q = kin.home.copy()
    res = ctl.solve(q, _hold_at(kin, q, (0.0, 0.0, -0.5)))
    for i in range(1, 4):
        rate = (_length(kin, i, q[i] + 1e-6 * res.qd[i]) - _length(kin, i, q[i] - 1e-6 * res.qd[i])) / 2e-6
        assert abs(rate) <= v_max + ROW_TOL, (i, rate)
    assert np.abs(res.v[1:]).max() >= v_max - ROW_TOL  # one binds
    assert _flow_by_hand(kin, q, res.qd) <= 0.5 * _q_max(kin)  # the pumps are not what binds
    _orientation_met_position_gave_way(res)


def _arm_at_length(kin, target: float) -> float:
    """Arm joint angle whose cylinder length is ``target`` (bisection over the joint range; length monotonic)."""
    lo, hi = float(kin.limits.lower[2]), float(kin.limits.upper[2])
    rising = _length(kin, 2, hi) > _length(kin, 2, lo)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if (_length(kin, 2, mid) < target) == rising:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_stroke_limit(kin):
    ctl = CylinderIkHQP(kin)
    s = ctl.settings
    lengths = [_length(kin, 2, kin.limits.lower[2]), _length(kin, 2, kin.limits.upper[2])]
    l_end = min(lengths) + s.stroke_margin  # the arm cylinder's retracted end (arm reaching out)
    q = kin.home.copy()
    q[2] = _arm_at_length(kin, l_end + 0.01)  # 10 mm from its stroke end
    rising = lengths[1] > lengths[0]
    qd_des = np.array([0.0, 0.0, -0.5 if rising else 0.5, 0.0])  # the arm driven into the end at 0.5 rad/s
    jac = kin.jacobians(q)[1]
    res = ctl.solve(q, _hold_at(kin, q, jac @ qd_des, float(qd_des[1:].sum())))
    pred = _length(kin, 2, q[2]) + s.stroke_horizon_s * res.v[2]
    assert pred >= l_end - ROW_TOL * ctl.settings.stroke_horizon_s
    assert pred <= l_end + 1e-4  # it binds
    assert res.hqp.slack["collision"] == 0.0 and not res.hqp.solved["collision"]
    assert _flow_by_hand(kin, q, res.qd) <= _q_max(kin) * (1 + LIMIT_TOL)
    assert np.all(np.abs(res.v) <= ctl.speed_limits + ROW_TOL)
    _orientation_met_position_gave_way(res)

    # kinematic integration pushed into the end for 2 s: the stroke end (and the joint limit) is never passed
    ctl.reset()
    ref = _hold_at(kin, q, jac @ qd_des, float(qd_des[1:].sum()))
    worst = math.inf
    for _ in range(200):
        r = ctl.solve(q, ref)
        q = q + ctl.dt * r.qd
        ref.position = ref.position + ctl.dt * ref.velocity
        ref.theta_w += ctl.dt * ref.theta_w_rate
        worst = min(worst, _length(kin, 2, q[2]) - l_end)
    assert worst >= -1e-4, worst
    assert worst <= 1e-3  # it went to the end
    assert kin.limits.lower[2] <= q[2] <= kin.limits.upper[2]


def test_ground_damper(kin):
    q = kin.home.copy()
    tip = kin.tip_position(q)
    settings = IkSettings(ground_min_z=float(tip[2]) - 0.1)  # the tip 0.1 m above the ground limit
    ctl = CylinderIkHQP(kin, settings)
    res = ctl.solve(q, _hold_at(kin, q, (0.3, 0.0, -0.5)))  # out and down at 0.5 m/s
    s = settings
    bound = -s.damper_xi * (0.1 - s.damper_safety) / (s.damper_influence - s.damper_safety)
    assert res.tip_velocity[2] >= bound - ROW_TOL
    assert res.tip_velocity[2] <= bound + 1e-3  # it binds
    # only the direction the damper holds gives way: the tip still goes out as commanded
    np.testing.assert_allclose(res.tip_velocity[:2], res.tip_velocity_cmd[:2], atol=1e-3)
    _orientation_met_position_gave_way(res)

    # pushed down for 3 s: the tip approaches the ground limit and never passes it
    ctl.reset()
    ref = _hold_at(kin, q, (0.0, 0.0, -0.5))
    lowest = math.inf
    for _ in range(300):
        r = ctl.solve(q, ref)
        q = q + ctl.dt * r.qd
        ref.position = ref.position + ctl.dt * ref.velocity
        lowest = min(lowest, float(kin.tip_position(q)[2]) - s.ground_min_z)
    assert lowest >= -1e-4, lowest
    assert lowest <= 0.01


def test_swing_axis_damper(kin):
    q = kin.home.copy()
    tip = kin.tip_position(q)
    rel = tip[:2] - kin.swing_origin[:2]
    radial = float(np.linalg.norm(rel))
    settings = IkSettings(body_min_radius=radial - 0.1, damper_safety=0.02)  # 0.1 m from the body limit
    ctl = CylinderIkHQP(kin, settings)
    n = np.array([rel[0], rel[1], 0.0]) / radial
    res = ctl.solve(q, _hold_at(kin, q, -0.6 * n))  # straight at the swing axis
    s = settings
    bound = -s.damper_xi * (0.1 - s.damper_safety) / (s.damper_influence - s.damper_safety)
    rho_dot = float(n @ res.tip_velocity)
    assert rho_dot >= bound - ROW_TOL
    assert rho_dot <= bound + 1e-3  # it binds
    _orientation_met_position_gave_way(res)


def test_collision_hook_rows(kin):
    """An extra collision row in joint velocities (as a link-primitive damper gives) binds like the others."""
    ctl = CylinderIkHQP(kin, IkSettings(extra_collision_rows=2))
    q = kin.home.copy()
    pin_jac = kin.jacobians(q)[3]
    limit = 0.05  # [m/s] the bucket pin may come in at most this fast
    rows = (-pin_jac[0:1], np.array([limit]))  # -v_pin,x <= limit
    res = ctl.solve(q, _hold_at(kin, q, (-0.5, 0.0, 0.0)), collision_rows=rows)
    v_pin = pin_jac @ res.qd
    assert v_pin[0] >= -limit - ROW_TOL
    assert v_pin[0] <= -limit + 1e-3  # it binds
    _orientation_met_position_gave_way(res)
    free = ctl.solve(q, _hold_at(kin, q, (-0.5, 0.0, 0.0)))  # without the row: the task is met
    np.testing.assert_allclose(free.tip_velocity, free.tip_velocity_cmd, atol=TASK_TOL)
    with pytest.raises(ValueError, match="room for 2"):
        ctl.solve(q, _hold_at(kin, q, (0.0, 0.0, 0.0)), collision_rows=(np.zeros((3, 4)), np.zeros(3)))
    with pytest.raises(ValueError, match="extra_collision_rows is 0"):
        CylinderIkHQP(kin).solve(q, _hold_at(kin, q, (0.0, 0.0, 0.0)), collision_rows=rows)


#: swung 43 deg: bucket out in front, clear of everything / into the front end of the left track (as
#: tests/tms_rc/test_collision.py's ID run)
Q_START = np.array([0.75, -0.6, 1.6, 0.8])
Q_GOAL = np.array([0.75, -0.12, 2.65, 0.4])
PAIRS = ("bucket/undercarriage", "bucket/cab")


def _approach(kin, settings: IkSettings, duration: float = 3.0, total: float = 5.0):
    """Kinematic loop (q += dt qd of the solution) on minimum-jerk tip and theta_w references from Q_START's to
    Q_GOAL's. Returns per step every pair's distance (an independent SelfCollision), the tip position error and
    the theta_w error; and the controller."""
    ctl = CylinderIkHQP(kin, settings)
    check = SelfCollision(kin.model, kin.machine)
    p0, p1 = kin.tip_position(Q_START), kin.tip_position(Q_GOAL)
    t0, t1 = kin.theta_w(Q_START), kin.theta_w(Q_GOAL)
    q, qd, dt = Q_START.copy(), np.zeros(4), ctl.dt
    dist, pos_err, th_err = [], [], []
    for k in range(round(total / dt)):
        s = min(k * dt / duration, 1.0)
        p = 10 * s**3 - 15 * s**4 + 6 * s**5
        v = (30 * s**2 - 60 * s**3 + 30 * s**4) / duration
        ref = IkReference(position=p0 + p * (p1 - p0), velocity=v * (p1 - p0), theta_w=t0 + p * (t1 - t0),
                          theta_w_rate=v * (t1 - t0))
        res = ctl.solve(q, ref, qd=qd)
        assert not res.hqp.failed, res.hqp.failed
        qd = res.qd
        q = q + dt * qd
        dist.append(check.distances(q))
        pos_err.append(float(np.linalg.norm(kin.tip_position(q) - ref.position)))
        th_err.append(kin.theta_w(q) - ref.theta_w)
    return np.array(dist), np.array(pos_err), np.array(th_err), ctl


def test_self_collision_keeps_the_bucket_off_the_body(kin):
    """The reference ends with the bucket 0.1 m inside the track box. The swing-axis rows are set out of the way
    (body_min_radius 0.5 m) so only the link-primitive pair rows can stop it: every pair stays at the safety
    distance (less 1 cm), the bucket angle (above) is kept, the tip task (below) gives way. Without the pair
    rows the same run goes into the tracks."""
    on = IkSettings(body_min_radius=0.5)
    k = PAIRS.index("bucket/undercarriage")
    check = SelfCollision(kin.model, kin.machine)
    assert check.distances(Q_GOAL)[k] < -0.09 and check.distances(Q_START).min() > 2.0
    dist, pos_err, th_err, ctl = _approach(kin, on)
    assert ctl.collision is not None and ctl.collision.names == PAIRS
    ds, di = on.self_collision_safety, on.self_collision_influence
    assert dist.min() >= ds - 0.01, dist.min(axis=0)
    assert dist[:, k].min() < di  # the deck's row did act
    assert dist[-1, k] < ds + 0.1  # pressed against the safety distance, not held far off
    assert pos_err[-1] > 0.2  # the position task gave way ...
    dist_off, pos_err_off, th_err_off, ctl_off = _approach(kin, IkSettings(body_min_radius=0.5,
                                                                           self_collision=False))
    # ... theta_w (above it) did not: at the end it is met, and on the way it lags the reference (up to 8 mrad:
    # the loop's Euler step at 0.9 rad/s, no limit binds) exactly as much as without the pair rows
    assert abs(th_err[-1]) < 1e-4
    np.testing.assert_allclose(th_err, th_err_off, atol=1e-5)
    assert ctl_off.collision is None
    assert ctl_off.levels[3].rows == 4 and ctl.levels[3].rows == 4 + len(PAIRS)
    assert dist_off[:, k].min() < -0.05  # into the tracks
    assert pos_err_off[-1] < 0.05
    assert pos_err[-1] > pos_err_off[-1] + 0.15


def test_pair_rows_free_when_far_and_hook_after_them(kin):
    """At home every pair is beyond d_i: its rows are free and the collision level costs nothing; the hook's
    rows come after the pairs' and still bind (with the pair rows present)."""
    ctl = CylinderIkHQP(kin, IkSettings(extra_collision_rows=1))
    q = kin.home.copy()
    res = ctl.solve(q, _hold_at(kin, q, (0.0, 0.0, 0.0)))
    assert not ctl.collision.active.any()
    assert np.all(ctl._b[3][4:4 + len(PAIRS)] >= 1e8)
    assert res.hqp.slack["collision"] == 0.0
    assert ctl.levels[3].rows == 4 + len(PAIRS) + 1
    with pytest.raises(ValueError, match="d_s < d_i"):
        CylinderIkHQP(kin, IkSettings(self_collision_safety=0.5, self_collision_influence=0.5))


def test_pair_row_is_the_distance_rate_in_piston_velocities(kin):
    """Near the tracks the active pair's row over v (scaled back) is the rate of coal's distance along the joint
    motion qd = v / J_p (the swing too: the undercarriage does not turn): a finite difference of the distance
    along q + h qd."""
    q = np.array([1.0, -0.15, 2.6, 0.3])  # bucket swung over the left track's front end, 0.1-0.5 m above it
    ctl = CylinderIkHQP(kin, IkSettings(body_min_radius=0.5))
    ctl.solve(q, _hold_at(kin, q, (0.0, 0.0, 0.0)))
    k = PAIRS.index("bucket/undercarriage")
    assert ctl.collision.active[k]
    row_v = -ctl._a[3][4 + k]  # d_dot = row_v @ v
    g = ctl.actuator_state(q)[0].copy()
    check = SelfCollision(kin.model, kin.machine)
    v = np.array([0.1, 0.05, -0.03, 0.04])
    qd = v / g
    h = 1e-6
    rate = (check.distances(q + h * qd)[k] - check.distances(q - h * qd)[k]) / (2 * h)
    assert row_v @ v == pytest.approx(rate, rel=1e-4, abs=1e-7)
    s = ctl.settings
    d = check.distances(q)[k]
    bound = s.self_collision_xi * (d - s.self_collision_safety) / (s.self_collision_influence
                                                                    - s.self_collision_safety)
    assert ctl._b[3][4 + k] == pytest.approx(bound, rel=1e-9)


#: (time [s], tip x, z [m], theta_w [rad]) knots of a dig-like motion in the front's plane
KNOTS = ((0.0, 7.5, 0.8, 1.0), (2.0, 7.2, -0.4, 1.1), (4.0, 6.6, -0.9, 1.3), (7.0, 4.8, -0.9, 1.7),
         (10.0, 4.6, 0.6, 2.4))


def _track(kin, ctl, ref: HermiteReference, y: float, offset=(0.0, 0.0, 0.0), seconds=None):
    """Kinematic loop: q += dt * qd of the solution; returns per-step tip errors [m] and the results."""
    p0 = ref.sample(0.0)[0]
    q = kin.ik_position_with_angle(np.array([p0[0], y, p0[1]]) + np.asarray(offset), p0[2])
    errs, results, integrals = [], [], []
    qd = np.zeros(4)
    steps = round((seconds if seconds is not None else ref.end + 1.0) / ctl.dt)
    for k in range(steps):
        pos, vel = ref.sample(k * ctl.dt)
        r = ctl.solve(q, IkReference(position=np.array([pos[0], y, pos[1]]), velocity=np.array([vel[0], 0.0, vel[1]]),
                                     theta_w=float(pos[2]), theta_w_rate=float(vel[2])), qd=qd)
        errs.append(float(np.linalg.norm(kin.tip_position(q) - [pos[0], y, pos[1]])))
        results.append(r)
        integrals.append(ctl.pid.integral.copy())
        qd = r.qd
        q = q + ctl.dt * qd
    return np.array(errs), results, integrals, q


def test_tracks_hermite_reference(kin):
    ctl = CylinderIkHQP(kin)
    ref = HermiteReference.through([k[0] for k in KNOTS], [k[1:] for k in KNOTS])
    y = float(kin.tip_position(kin.home)[1])
    errs, results, _, q = _track(kin, ctl, ref, y)
    rms = math.sqrt(float(np.mean(errs**2)))
    assert rms < 1.2e-3, rms  # [m] (0.82 mm measured: the Euler step of the loop, 100 Hz)
    assert errs.max() < 2.5e-3, errs.max()
    assert errs[-1] < 3e-4, errs[-1]
    assert abs(kin.theta_w(q) - KNOTS[-1][3]) < 1e-3
    assert max(r.pump_flow for r in results) <= _q_max(kin) * (1 + LIMIT_TOL)
    assert not any(r.gave_way for r in results)  # this reference is within every limit

    # from 10 cm off the start, the PID closes the gap while the reference runs
    ctl.reset()
    errs, _, _, _ = _track(kin, ctl, ref, y, offset=(0.06, 0.0, -0.08), seconds=4.0)
    assert errs[0] == pytest.approx(0.1, abs=1e-9)
    assert errs[100] < 0.02, errs[100]  # kp 2/s: e^-2 of the offset after 1 s
    assert errs[-1] < 1.5e-3, errs[-1]
    assert errs[-1] < 0.05 * errs[0]


def test_integral_holds_while_the_pumps_bind(kin):
    """The same knots 3x faster: the pumps bind, the position task gives way, its PID integral does not wind up."""
    ctl = CylinderIkHQP(kin)
    ref = HermiteReference.through([k[0] / 3.0 for k in KNOTS], [k[1:] for k in KNOTS])
    y = float(kin.tip_position(kin.home)[1])
    errs, results, integrals, _ = _track(kin, ctl, ref, y, seconds=ref.end)
    held = [k for k in range(1, len(results)) if results[k - 1].gave_way]
    assert len(held) > 20, len(held)  # the pumps did bind
    assert max(r.pump_flow for r in results) <= _q_max(kin) * (1 + LIMIT_TOL)
    assert max(r.pump_flow for r in results) >= _q_max(kin) * (1 - LIMIT_TOL)
    for k in held:
        np.testing.assert_array_equal(integrals[k], integrals[k - 1])
    assert np.abs(np.array(integrals)).max() <= ctl.settings.i_limit_position
    assert errs.max() > 0.01  # it fell behind (so an integrating PID would have wound up)


def test_hermite_hits_knots_with_given_velocities():
    rng = np.random.default_rng(7)
    times = np.cumsum(rng.uniform(0.5, 2.0, 5))
    pos = rng.normal(size=(5, 3))
    vel = rng.normal(size=(5, 3))
    ref = HermiteReference(times, pos, vel)
    for t, p, v in zip(times, pos, vel, strict=True):
        got_p, got_v = ref.sample(float(t))
        np.testing.assert_allclose(got_p, p, atol=1e-12)
        np.testing.assert_allclose(got_v, v, atol=1e-10)
    # inside an interval: the standard Hermite basis, by hand
    k, s = 2, 0.3
    h = times[k + 1] - times[k]
    basis = (2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2)
    by_hand = basis[0] * pos[k] + basis[1] * h * vel[k] + basis[2] * pos[k + 1] + basis[3] * h * vel[k + 1]
    np.testing.assert_allclose(ref.sample(float(times[k] + s * h))[0], by_hand, atol=1e-12)
    # velocity = derivative of position (central difference)
    t, d = float(times[1] + 0.4), 1e-6
    fd = (ref.sample(t + d)[0] - ref.sample(t - d)[0]) / (2 * d)
    np.testing.assert_allclose(ref.sample(t)[1], fd, atol=1e-6)
    # outside the knots: the end knot held still
    p_out, v_out = ref.sample(float(times[-1] + 5.0))
    np.testing.assert_allclose(p_out, pos[-1])
    np.testing.assert_allclose(v_out, 0.0)
    p_before, _ = ref.sample(float(times[0] - 1.0))
    np.testing.assert_allclose(p_before, pos[0])


def test_hermite_through_and_invalid_knots():
    times = [0.0, 1.0, 3.0, 4.0]
    pos = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 3.0], [2.0, 3.0]])
    ref = HermiteReference.through(times, pos)
    np.testing.assert_allclose(ref.velocities[0], 0.0)
    np.testing.assert_allclose(ref.velocities[-1], 0.0)
    np.testing.assert_allclose(ref.velocities[1], (pos[2] - pos[0]) / 3.0)
    np.testing.assert_allclose(ref.velocities[2], (pos[3] - pos[1]) / 3.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        HermiteReference([0.0, 1.0, 1.0], np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="do not match"):
        HermiteReference([0.0, 1.0], np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="finite"):
        HermiteReference([0.0, 1.0], [0.0, math.nan], [0.0, 0.0])


def test_pid_terms_and_anti_windup():
    dt, kp, ki, kd, i_limit = 0.01, 2.0, 0.2, 0.1, 0.05
    pid = Pid(kp, ki, kd, dt, i_limit, dim=2)
    e, e_dot, ff = np.array([0.01, -0.02]), np.array([0.1, 0.0]), np.array([0.3, 0.0])
    np.testing.assert_allclose(pid.update(e, e_dot, ff), ff + kp * e + ki * dt * e + kd * e_dot, atol=1e-15)
    # a constant error for 10 s: the integral stops at its bound
    pid.reset()
    for _ in range(1000):
        out = pid.update(np.array([1.0, -1.0]), np.zeros(2), np.zeros(2)).copy()
    np.testing.assert_allclose(pid.integral, [i_limit, -i_limit])
    np.testing.assert_allclose(out, [kp + ki * i_limit, -kp - ki * i_limit])
    # hold: the integral does not move
    before = pid.integral.copy()
    pid.update(np.array([-5.0, 5.0]), np.zeros(2), np.zeros(2), hold=True)
    np.testing.assert_array_equal(pid.integral, before)
    # i_zone: an axis whose error is outside the zone does not integrate, the other does
    zoned = Pid(kp, ki, kd, dt, i_limit, dim=2, i_zone=0.02)
    zoned.update(np.array([0.01, 0.5]), np.zeros(2), np.zeros(2))
    np.testing.assert_allclose(zoned.integral, [dt * 0.01, 0.0])


def test_pid_anti_windup_recovers_where_an_unclamped_integral_does_not():
    """5 s of 1 m error (held back by a limit), then the error reverses to -1 cm: the clamped PID's output turns
    at once, an unclamped one pushes the wrong way for seconds."""
    dt = 0.01

    def steps_until_negative(pid: Pid) -> int:
        for _ in range(500):
            pid.update(np.array([1.0]), np.zeros(1), np.zeros(1))
        for k in range(5000):
            if pid.update(np.array([-0.01]), np.zeros(1), np.zeros(1))[0] < 0.0:
                return k
        return 5000

    clamped = steps_until_negative(Pid(2.0, 0.2, 0.0, dt, 0.05, dim=1))
    unclamped = steps_until_negative(Pid(2.0, 0.2, 0.0, dt, math.inf, dim=1))
    assert clamped <= 1, clamped
    assert unclamped > 100 * max(clamped, 1), unclamped
