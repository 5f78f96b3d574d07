"""The carrier's axes: vessel limits from the description, a vessel swing from its joint (no ROS)."""

from __future__ import annotations

import math

import pytest

from tms_model.machines import Joint, load_machine
from tms_rc.carrier.vessel import VesselController, VesselError, VesselParams, VesselTuning

TUNING = VesselTuning(tolerance=0.02, settle_time=0.3, timeout_margin=5.0)


def _run(ctl: VesselController, q: float, target: float, rate: float) -> tuple[str, float]:
    ctl.start(target, q, 0.0)
    t = 0.0
    while True:
        step = ctl.step(q, 0.0, t)
        if step.status != "RUNNING":
            return step.status, q
        err = step.error
        q += max(-rate * 0.05, min(rate * 0.05, err))
        t += 0.05


def test_continuous_swing_takes_the_short_way_and_names_its_joint() -> None:
    joint = Joint(
        "rotate_joint", "body_link", "vessel_base_link", (0, 0, 0), (0, 0, 0), (0.0, 0.0, 1.0), None, None, 0.3, 0.3
    )
    params = VesselParams.for_swing(joint, TUNING, "mst.yaml joints.rotate_joint")
    assert params.continuous and params.what == "rotate_joint"
    ctl = VesselController(params)
    status, q = _run(ctl, 3.0, -3.0, 0.3)  # 0.28 rad the short way, not 6 rad back
    assert status == "SUCCEEDED" and abs(math.remainder(q - (-3.0), 2 * math.pi)) < 0.02
    assert ctl.target == pytest.approx(3.0 + math.remainder(-6.0, 2 * math.pi))


def test_limited_swing_and_the_vessel_refuse_targets_outside_their_limits() -> None:
    joint = Joint("rotate_joint", "body_link", "v", (0, 0, 0), (0, 0, 0), (0.0, 0.0, 1.0), -1.57, 1.57, 0.3, 0.3)
    ctl = VesselController(VesselParams.for_swing(joint, TUNING, "mst.yaml joints.rotate_joint"))
    with pytest.raises(VesselError, match=r"outside \[-1.57, 1.5700\] rad \(mst.yaml joints.rotate_joint\)"):
        ctl.start(2.0, 0.0, 0.0)
    assert _run(ctl, 0.0, -1.0, 0.3)[0] == "SUCCEEDED"
    ic = load_machine("ic120")
    vessel = VesselController(VesselParams.from_config(ic.vessel, TUNING, f"{ic.source} vessel.max_angle"))
    with pytest.raises(VesselError, match=r"0 = lowered, \+ = raised; .*ic120.yaml vessel.max_angle"):
        vessel.start(-0.1, 0.0, 0.0)
