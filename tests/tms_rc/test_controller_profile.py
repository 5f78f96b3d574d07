"""Reference profiles and the Smith predictor of the arm controller (pure functions, no ROS)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from tms_model.excavator.kinematics import load_kinematics
from tms_model.excavator.targets import JointTarget
from tms_rc.excavator.controller import ArmController, TrapezoidSegment, load_controller_config
from tms_rc.excavator.plant import LagDeadTimePlant


def test_trapezoid_timing_is_triangular_below_top_speed_and_trapezoidal_above() -> None:
    # path fraction: top speed 2 /s never reached with 1 /s^2 over the whole path -> triangle, 2 s
    dur, t_a = TrapezoidSegment.timing(speed=2.0, accel=1.0)
    assert (dur, t_a) == pytest.approx((2.0, 1.0))
    # top speed 0.5 /s reached after 0.5 s -> 0.5 + 2 s
    dur, t_a = TrapezoidSegment.timing(speed=0.5, accel=1.0)
    assert (dur, t_a) == pytest.approx((2.5, 0.5))
    # slowed uniformly to a minimum duration: same shape, longer
    dur, t_a = TrapezoidSegment.timing(speed=10.0, accel=100.0, min_duration=0.5)  # 0.2 s triangle
    assert dur == pytest.approx(0.5) and t_a == pytest.approx(0.25)
    # a cubic at the same peak acceleration needs sqrt(6/4) times as long
    assert math.sqrt(6.0 / 1.0) / TrapezoidSegment.timing(10.0, 1.0)[0] == pytest.approx(math.sqrt(1.5))


def test_trapezoid_samples_start_end_peak_speed_and_symmetry() -> None:
    seg = TrapezoidSegment(np.array([0.0, 1.0]), np.array([2.0, -1.0]), duration=3.0, accel_time=1.0)
    p, v = seg.sample(0.0)
    assert np.allclose(p, [0.0, 1.0]) and np.allclose(v, 0.0)
    p, v = seg.sample(1.5)  # middle of the coast: half way, at the top speed 1 / (T - t_a) of the path
    assert np.allclose(p, [1.0, 0.0]) and np.allclose(v, np.array([2.0, -2.0]) / 2.0)
    p, v = seg.sample(3.0)
    assert np.allclose(p, [2.0, -1.0]) and np.allclose(v, 0.0)
    assert np.allclose(seg.sample(99.0)[0], [2.0, -1.0]) and np.allclose(seg.sample(-1.0)[0], [0.0, 1.0])
    # position is the integral of the velocity (no jump anywhere)
    ts = np.linspace(0.0, 3.0, 3001)
    vel = np.array([seg.sample(t)[1][0] for t in ts])
    assert np.trapezoid(vel, ts) == pytest.approx(2.0, abs=1e-4)
    with pytest.raises(ValueError, match="accel_time"):
        TrapezoidSegment(np.zeros(1), np.ones(1), duration=1.0, accel_time=0.6)


def test_predictor_with_velocities_knows_where_a_braking_swing_stops() -> None:
    # Mid-swing, the plant (the controller's own dead time + lag model) is left with zero commands: it
    # still moves by the commands in its dead time and by what its lag holds (lag x velocity). The
    # prediction with measured velocities says where it stops; without, the lag counts as dead time.
    kin = load_kinematics()
    cfg = load_controller_config(kin.machine)
    ctl = ArmController(kin, cfg)
    q0 = kin.home
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    ctl.start([JointTarget(q0 + np.array([1.6, 0.0, 0.0, 0.0]))])
    q, v = q0.copy(), np.zeros(4)
    errors = {"with": [], "without": []}
    for k in range(int(6.0 / cfg.dt)):
        u = ctl.step(q, v)
        if k in (int(2.5 / cfg.dt), int(3.5 / cfg.dt), int(4.5 / cfg.dt)):  # accelerating, braking
            with_v, without_v = ctl.predicted(q, v)[0], ctl.predicted(q)[0]
            coast = copy.deepcopy(plant)  # its dead-time queues and lag state as they are now
            coast.step(u)  # this step's command is in flight too (the swing's output is not delayed further)
            for _ in range(int(5.0 / cfg.dt)):
                rest_q, _ = coast.step(np.zeros(4))
            errors["with"].append(abs(with_v - rest_q[0]))
            errors["without"].append(abs(without_v - rest_q[0]))
        q, v = plant.step(u)
    assert max(errors["with"]) < 0.01, errors
    assert max(errors["without"]) > 3 * max(errors["with"]), errors
