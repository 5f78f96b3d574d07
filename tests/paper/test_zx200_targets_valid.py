"""Every ZX200 target the paper experiment can send passes the ZX200 planner's own validation.

The seed's ZX200 records and what tms_sp writes live (excavation targets over a mound being dug, release
points over the IC120 vessel at P1 with its arrival tolerances and any load shape) go through the same
path as in the stack: record -> ``tms_ts.subtask_specs`` goal data -> ``tms_rp.arm.planner``
(change_pose / excavate / release), so a target the planner would reject (JOINT_LIMIT, OUT_OF_REACH,
INVALID_GOAL) fails here instead of stalling the experiment. No ROS.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from tests.tms_sp.treeutil import ROOT, load_seed
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import JOINTS, load_kinematics
from tms_model.geometry import Pose2D
from tms_rc.excavator.controller import load_controller_config
from tms_rp.arm.planner import ArmPlanner, load_planner_config
from tms_sp import synthetic as syn
from tms_sp.config import load_sensing_config
from tms_sp.heightgrid import rasterize
from tms_sp.mound import assess_mound
from tms_sp.vessel import assess_vessel, release_in_excavator

KIN = load_kinematics()
PLANNER = ArmPlanner(KIN, load_planner_config(KIN.machine.kind),
                       ground_min_z=load_controller_config(KIN.machine).ground_min_z)
CFG = load_sensing_config()
SPILL_ANGLE = 1.2  # config/machines/zx200.yaml hydraulics.bucket.release_tip_angle: spills below this


def _seed_zx200() -> dict[str, dict]:
    return {d["record_name"]: d for d in load_seed()["parameters"] if d.get("model_name") == "zx200"}


def _validate(record: str, doc: dict) -> None:
    """Plan the record as the ZX200 subtask servers + planner would (raises the planner's error)."""
    q_home = np.asarray(KIN.home, dtype=float)
    if "trajectory" in doc:
        names = [j for j in (*JOINTS, "bucket_end_joint") if j in doc]
        PLANNER.change_pose(joint_names=names, joint_points=[[float(doc[j]) for j in names]], current_q=q_home)
    elif record == CFG.excavation_record:
        PLANNER.excavate([doc["x"], doc["y"], doc["z"]], doc["theta_w"], doc.get("offset", 0.0))
    elif "position_with_angle" in doc:
        PLANNER.change_pose(positions_with_angle=[([doc["x"], doc["y"], doc["z"]], doc["theta_w"])],
                            theta_w_tolerance=doc.get("theta_w_tolerance", 0.0))
    elif "target_angle" in doc:
        PLANNER.release(doc["target_angle"], q_home)
    else:
        raise AssertionError(f"{record}: unknown ZX200 record shape {sorted(doc)}")


@pytest.mark.parametrize("record", sorted(_seed_zx200()))
def test_every_seeded_zx200_record_passes_planner_validation(record):
    _validate(record, _seed_zx200()[record])


def test_carry_angle_holds_the_soil():
    assert CFG.vessel.carry_theta_w > SPILL_ANGLE + 0.2, "carry angle would spill the bucket (theta_w convention)"


def _vessel_grid(volume: float, cx: float, rng: np.random.Generator):
    g = CFG.vessel_geom
    spec = g.grid_spec(CFG.resolution)
    surface = syn.vessel_heap(volume, g.inner_length, g.inner_width, cx=cx) if volume > 0 else (lambda x, y: 0 * x)
    pts = syn.scan(surface, (spec.x_min, spec.x_max), (spec.y_min, spec.y_max), 6000, rng, noise=0.02)
    return rasterize(pts, spec, sensor="vessel")


def test_every_sensed_release_target_passes_planner_validation():
    """IC120 anywhere tms_sp accepts as arrived at P1 (+-0.6 m, +-10 deg) x load shapes up to the target fill."""
    rng = np.random.default_rng(11)
    p1 = CFG.points["P1"]
    tol, yaw_tol = CFG.arrival.position_tolerance, CFG.arrival.yaw_tolerance
    cap = CFG.vessel_geom.capacity
    checked = 0
    for volume in (0.0, 0.3 * cap, 0.6 * cap, CFG.vessel.target_fill * cap):
        for cx in (-1.0, 0.0, 1.0):
            va = assess_vessel(_vessel_grid(volume, cx, rng), CFG.vessel_geom, CFG.vessel)
            for dx, dy, dyaw in ((0, 0, 0), (tol, 0, 0), (-tol, 0, 0), (0, tol, yaw_tol), (0, -tol, -yaw_tol)):
                ic = Pose2D(x=p1.x + dx, y=p1.y + dy, yaw=p1.yaw + dyaw)
                pose, angle = release_in_excavator(va.release_xyz, ic, CFG.excavator_base, CFG.vessel_geom,
                                               CFG.swing_axis_in_base, CFG.vessel.carry_theta_w)
                _validate(CFG.release_record, pose)
                _validate(CFG.angle_record, angle)
                checked += 1
    assert checked == 60


def test_every_sensed_excavation_target_passes_planner_validation():
    """Excavation targets over the seeded mound while it is dug down pass by pass."""
    rng = np.random.default_rng(12)
    m = CFG.mound
    surface = syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height, m.ground_z)
    xg, yg = CFG.mound_grid.centres()
    seen = 0
    for _ in range(12):
        z = surface(xg, yg) + rng.normal(0.0, 0.02, xg.shape)
        grid = rasterize(np.column_stack([xg.ravel(), yg.ravel(), z.ravel()]), CFG.mound_grid)
        a = assess_mound(grid, CFG.swing_axis_map(), CFG.excavation)
        if a.target is None:
            break
        fields = a.target.record_fields(CFG.excavator_base)
        _validate(CFG.excavation_record, fields)
        approach = {**a.target.approach_record_fields(CFG.excavator_base, CFG.approach_height),
                    "theta_w_tolerance": _seed_zx200()[CFG.approach_record]["theta_w_tolerance"]}
        _validate(CFG.approach_record, approach)
        # The tree's return_over_mound (a pass-through change_pose from over the vessel) ends at the
        # excavate's first point but for a bucket trim: it does the swing, the approach the rest. Also at
        # the attack angle's bounds (a 20 deg target failed the task in the plant with a 0.5 rad tolerance).
        carry = _seed_zx200()[CFG.release_record]
        q_over_vessel = KIN.ik_position_with_angle(np.array([carry["x"], carry["y"], carry["z"]]), carry["theta_w"])
        back = PLANNER.change_pose(
            positions_with_angle=[([approach["x"], approach["y"], approach["z"]], approach["theta_w"])],
            current_q=q_over_vessel,
            pass_through=True,
            theta_w_tolerance=approach["theta_w_tolerance"],
        )
        q_above = PLANNER.excavate([fields["x"], fields["y"], fields["z"]], fields["theta_w"], fields["offset"])[0].q
        end = PLANNER.pass_through_end(back)
        assert abs(end[0] - q_above[0]) < 1e-9, (end, q_above)
        # same tip point: the approach record is the target the planner's approach_height higher
        np.testing.assert_allclose(KIN.tip_position(end), KIN.tip_position(q_above), atol=1e-6)
        for bound in (CFG.excavation.theta_w_min, CFG.excavation.theta_w_max):
            _validate(CFG.approach_record, {**approach, "theta_w": bound})
        seen += 1
        surface = syn.dig_pit(surface, a.target.x, a.target.y, radius=0.7, depth=0.5)
    assert seen >= 5


def test_the_approach_height_is_the_planners_one_value_used_by_sensing_and_planner(tmp_path):
    """Defined once (config/tms_rp/<kind>_planner.yaml): sensing's approach record reads it, sensing.yaml may not
    hold it, and the planner's file must give it (no silent default on either side)."""
    assert CFG.approach_height == PLANNER.cfg.approach_height == load_planner_config(KIN.machine.kind).approach_height
    assert CFG.approach_height > 0.0
    sensing = ROOT / "config" / "tms_sp" / "sensing.yaml"
    assert "approach_height" not in yaml.safe_load(sensing.read_text())["excavation"]
    text = sensing.read_text().replace("  roi_margin:", "  approach_height: 0.5\n  roi_margin:", 1)
    (tmp_path / "sensing.yaml").write_text(text)
    with pytest.raises(ConfigError, match=r"sensing.yaml:\d+: excavation.approach_height: unknown key"):
        load_sensing_config(tmp_path / "sensing.yaml")
    planner = ROOT / "config" / "tms_rp" / f"{KIN.machine.kind}_planner.yaml"
    lines = [line for line in planner.read_text().splitlines() if not line.startswith("approach_height:")]
    (tmp_path / "planner.yaml").write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=r"planner.yaml:\d+: approach_height: missing required key"):
        load_planner_config(KIN.machine.kind, tmp_path / "planner.yaml")


def _original_zx200() -> dict[str, dict]:
    seed = yaml.safe_load((ROOT / "config" / "seeds" / "original_202412.yaml").read_text())
    return {d["record_name"]: d for d in seed["parameters"] if d.get("model_name") == "zx200"}


@pytest.mark.parametrize("record", sorted(_original_zx200()))
def test_every_zx200_record_for_the_originals_2024_12_trees_passes_planner_validation(record):
    """The records the original's own 2024-12 trees name (config/seeds/original_202412.yaml)."""
    doc = _original_zx200()[record]
    _validate(record, doc)
    if record.startswith("hold_soil"):  # carried soil stays in the bucket on the way
        assert doc["theta_w"] > SPILL_ANGLE + 0.2
