"""The ZX200 collision core and the collision-aware planner (``_plan`` variants), without ROS."""

from __future__ import annotations

import math
import re

import coal
import numpy as np
import pytest

from tms_common.config import data_root
from tms_common.errors import ConfigError
from tms_model.excavator.codes import FAILURE
from tms_model.excavator.kinematics import ExcavatorKinematics, load_kinematics
from tms_model.excavator.targets import CartesianTarget, JointTarget
from tms_model.machines import load_machine
from tms_rp.arm.collision import (
    ArmCollisionModel,
    CollisionError,
    CollisionObject,
    CollisionRecordError,
    load_collision_config,
    objects_from_record,
)
from tms_rp.arm.collision_planner import CollisionPlanner, Scene
from tms_rp.arm.planner import ArmPlanner, load_planner_config

RECORD = "zx200_collision_objects"


def carrier_doc(x: float = 0.0, y: float = 7.5, yaw: float = math.pi / 2, height: float = 2.0) -> dict:
    """A carrier (IC120 footprint 6.05 x 3.37 m) parked beside the ZX200, as the original's record holds it."""
    return {"record_name": RECORD, "collision_objects": [{
        "id": "ic120", "primitive_type": 1, "dimensions": [6.05, 3.37, height],
        "pose": {"position": {"x": x, "y": y, "z": height / 2},
                 "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}}]}


@pytest.fixture(scope="module")
def kin():
    return load_kinematics()


@pytest.fixture(scope="module")
def model(kin):
    return ArmCollisionModel(kin)


@pytest.fixture(scope="module")
def cp(kin, model):
    return CollisionPlanner(ArmPlanner(kin, load_planner_config(kin.machine.kind)), model)


def scene_of(doc: dict, model: ArmCollisionModel) -> Scene:
    objects, padding = objects_from_record(doc, RECORD)
    return Scene(objects, model.padding_for(padding))


def tip_at(bearing: float, radius: float = 6.5, z: float = 0.5) -> list[float]:
    return [radius * math.cos(bearing), radius * math.sin(bearing), z]


# ------------------------------------------------------------------------------------------ records
def test_record_reads_the_originals_fields_and_link_padding(model: ArmCollisionModel) -> None:
    doc = carrier_doc()
    doc["link_padding"] = {"bucket_link": 0.4}
    objects, padding = objects_from_record(doc, RECORD)
    assert [o.name for o in objects] == ["ic120"] and objects[0].kind == "BOX"
    assert objects[0].dimensions == (6.05, 3.37, 2.0)
    np.testing.assert_allclose(objects[0].position, [0.0, 7.5, 1.0])
    assert padding == {"bucket_link": 0.4}
    merged = model.padding_for(padding)
    assert merged["bucket_link"] == 0.4 and merged["boom_link"] == 0.25 and merged["body_link"] == 0.0


@pytest.mark.parametrize(
    ("mutate", "field", "words"),
    [
        (lambda d: d.pop("collision_objects"), "collision_objects", "missing"),
        (
            lambda d: d["collision_objects"][0].__setitem__("primitive_type", 4),
            "collision_objects[0].primitive_type",
            "CONE",
        ),
        (
            lambda d: d["collision_objects"][0].__setitem__("dimensions", [1.0, 2.0]),
            "collision_objects[0].dimensions",
            "BOX needs 3",
        ),
        (
            lambda d: d["collision_objects"][0]["dimensions"].__setitem__(1, -3.0),
            "collision_objects[0].dimensions[1]",
            "> 0",
        ),
        (
            lambda d: d["collision_objects"][0]["pose"]["position"].pop("y"),
            "collision_objects[0].pose.position.y",
            "missing",
        ),
        (
            lambda d: d["collision_objects"][0]["pose"]["orientation"].update(x=0, y=0, z=0, w=0),
            "collision_objects[0].pose.orientation",
            "zero length",
        ),
        (lambda d: d["collision_objects"][0].__setitem__("id", ""), "collision_objects[0].id", "non-empty string"),
        (lambda d: d.__setitem__("link_padding", {"cab_link": 0.2}), "link_padding.cab_link",
         "not a link of the zx200 arm"),
        (lambda d: d.__setitem__("link_padding", {"arm_link": "wide"}), "link_padding.arm_link", "finite number"),
    ],
)
def test_bad_record_names_record_and_field(mutate, field: str, words: str) -> None:
    doc = carrier_doc()
    mutate(doc)
    with pytest.raises(CollisionRecordError) as err:
        objects_from_record(doc, RECORD, "zx200")
    assert err.value.code == FAILURE
    assert f"record '{RECORD}'" in str(err.value) and f"field '{field}'" in str(err.value) and words in str(err.value)


# ------------------------------------------------------------------------------------------ the padded arm
@pytest.mark.parametrize("kind", ["zx200", "zx120"])
def test_the_plant_and_the_planner_use_the_kinds_own_link_boxes(kind: str) -> None:
    """The link boxes are written once, in the description (config/machines/<kind>.yaml link_boxes): the plant's
    (MuJoCo) link bodies and the planner's arm are those boxes, each kind its own."""
    from types import SimpleNamespace

    from sim_bridge.profiles.excavator import ExcavatorPlantProfile

    machine = load_machine(kind)
    assert set(machine.link_boxes) == {j.child for j in machine.joints}
    mjcf = "\n".join(ExcavatorPlantProfile.mjcf(SimpleNamespace(name=kind, description=machine)))
    arm = ArmCollisionModel(ExcavatorKinematics(machine), load_collision_config("zx200"))
    boxes = {link: shape for link, shape, *_ in arm.shapes if isinstance(shape, coal.Box)}
    for link, box in machine.link_boxes.items():
        body = re.search(rf'<body name="{kind}_{link}"[^\n]*\n[^\n]*\n\s*<geom type="box" size="([^"]+)" pos="([^"]+)"',
                         mjcf)
        assert body is not None, link
        assert np.allclose([float(v) for v in body[1].split()], np.array(box.size) / 2), link
        assert np.allclose([float(v) for v in body[2].split()], box.offset), link
        assert np.allclose(2 * boxes[link].halfSide, box.size), link
    # the ZX120's are its own, smaller than the ZX200's
    if kind != "zx200":
        other = load_machine("zx200").link_boxes
        assert all(np.prod(machine.link_boxes[k].size) < np.prod(other[k].size) for k in other)


def test_distance_to_a_box_is_measured_with_the_padding(kin, model: ArmCollisionModel) -> None:
    q = kin.home.copy()  # front straight out along +x, tip ~6.3 m out, 0.46 m up
    tip = kin.tip_position(q)
    wall = CollisionObject.make("wall", "r", 1, [0.2, 4.0, 4.0], [tip[0] + 1.0, 0.0, 2.0], [0, 0, 0, 1])
    bare = model.contact(q, [wall], dict.fromkeys(model.padding_for(), 0.0))
    assert bare.obj is wall and bare.link == "bucket_link" and 0.1 < bare.distance < 1.0
    assert bare.clearance == pytest.approx(bare.distance)
    padded = model.contact(q, [wall], {**dict.fromkeys(model.padding_for(), 0.0), "bucket_link": bare.distance + 0.05})
    assert padded.clearance == pytest.approx(-0.05) and "closer than its padding by 0.050 m" in padded.describe()
    object_padded = CollisionObject.make("wall", "r", 1, [0.2, 4.0, 4.0], [tip[0] + 1.0, 0.0, 2.0], [0, 0, 0, 1],
                                         padding=bare.distance + 0.1)
    assert model.contact(q, [object_padded], dict.fromkeys(model.padding_for(), 0.0)).clearance == pytest.approx(-0.1)
    assert model.contact(q, [wall], model.padding_for(), margin=bare.distance).clearance < 0


# ------------------------------------------------------------------------------------------ planning
def test_a_path_across_a_box_goes_around_it(kin, model: ArmCollisionModel, cp: CollisionPlanner) -> None:
    scene = scene_of(carrier_doc(), model)
    q_a = kin.ik_position_with_angle(np.array(tip_at(0.8)), 1.6)
    direct = cp.joint_line(q_a, kin.ik_position_with_angle(np.array(tip_at(2.35)), 1.6))
    assert cp.first_hit(direct, scene) is not None, "the test's direct swing must cross the carrier"
    targets = cp.change_pose(scene, current_q=q_a, positions_with_angle=[(tip_at(2.35), 1.6)])
    assert any("over 'ic120'" in d for d in cp.report.detours), cp.report
    path = cp.path_of(targets, q_a)
    clearances = [model.contact(q, scene.objects, scene.padding).clearance for q in path]
    assert min(clearances) >= 0.0, f"padded arm enters the padded carrier: min clearance {min(clearances):.3f} m"
    assert np.max(np.abs(np.diff(path, axis=0))) <= cp.cfg.path_step_rad + 1e-9  # the check was dense
    np.testing.assert_allclose(kin.tip_position(path[-1]), tip_at(2.35), atol=1e-6)  # and ends at the goal
    assert all(t.via for t in targets[:-1]) and not targets[-1].via


def test_direct_path_is_kept_when_free(kin, model: ArmCollisionModel, cp: CollisionPlanner) -> None:
    scene = scene_of(carrier_doc(x=0.0, y=-7.5), model)  # the carrier behind the other side
    q_a = kin.ik_position_with_angle(np.array(tip_at(0.8)), 1.6)
    plain = cp.planner.change_pose(current_q=q_a, positions_with_angle=[(tip_at(2.35), 1.6)])
    targets = cp.change_pose(scene, current_q=q_a, positions_with_angle=[(tip_at(2.35), 1.6)])
    assert cp.report.detours == [] and len(targets) == len(plain)


@pytest.mark.parametrize("mode", ["position_with_angle", "joints"])
def test_target_inside_the_object_is_refused_naming_it(kin, model, cp, mode: str) -> None:
    scene = scene_of(carrier_doc(), model)
    q_a = kin.ik_position_with_angle(np.array(tip_at(0.8)), 1.6)
    inside = tip_at(math.pi / 2, radius=7.5, z=1.5)  # in the carrier's box
    goal = ({"positions_with_angle": [(inside, 1.6)]} if mode == "position_with_angle" else
            {"joint_names": ["swing_joint", "boom_joint", "arm_joint", "bucket_joint"],
             "joint_points": [list(kin.ik_position_with_angle(np.array(inside), 1.6))]})
    with pytest.raises(CollisionError) as err:
        cp.change_pose(scene, current_q=q_a, **goal)
    assert err.value.code == FAILURE
    assert f"'ic120' (record '{RECORD}')" in str(err.value) and "target" in str(err.value)


def test_no_way_over_is_refused_naming_the_blocking_object(kin, model, cp) -> None:
    # a wall 12 m high ring-fencing the front on both sides: neither over nor the long way round
    doc = carrier_doc(height=12.0)
    doc["collision_objects"].append({**doc["collision_objects"][0], "id": "wall_behind",
                                     "pose": {"position": {"x": 0.0, "y": -7.5, "z": 6.0},
                                              "orientation": {"x": 0, "y": 0, "z": 0.7071068, "w": 0.7071068}}})
    scene = scene_of(doc, model)
    q_a = kin.ik_position_with_angle(np.array(tip_at(0.8)), 1.6)
    with pytest.raises(CollisionError) as err:
        cp.change_pose(scene, current_q=q_a, positions_with_angle=[(tip_at(2.35), 1.6)])
    assert "no collision-free path" in str(err.value) and "'ic120'" in str(err.value)


def test_start_pose_in_collision_is_refused(kin, model, cp) -> None:
    scene = scene_of(carrier_doc(), model)
    q_in = kin.ik_position_with_angle(np.array(tip_at(math.pi / 2, radius=7.5, z=1.5)), 1.6)
    with pytest.raises(CollisionError, match=r"start pose .* in collision: .*'ic120'"):
        cp.change_pose(scene, current_q=q_in, positions_with_angle=[(tip_at(0.8), 1.6)])


def test_excavate_approach_goes_around_and_a_dig_into_the_object_is_refused(kin, model, cp) -> None:
    scene = scene_of(carrier_doc(), model)
    q_a = kin.ik_position_with_angle(np.array(tip_at(0.8)), 1.6)
    targets = cp.excavate(scene, tip_at(2.35, z=-0.3), 1.0, 1.0, q_a)
    assert any("approach: over 'ic120'" in d for d in cp.report.detours), cp.report
    assert [t.label for t in targets][-3:] == ["penetrate", "drag", "curl and lift"]
    path = cp.path_of(targets, q_a)
    assert min(model.contact(q, scene.objects, scene.padding).clearance for q in path) >= 0.0
    # digging right beside the carrier: the lift / drag sweep into it (not re-planned) -> refused naming it
    with pytest.raises(CollisionError, match=r"'ic120'"):
        cp.excavate(scene, tip_at(math.pi / 2, radius=4.2, z=-0.3), 1.0, 0.5, q_a)


def test_cartesian_segments_are_checked_on_the_tip_line(kin, cp) -> None:
    q_a = kin.ik_position_with_angle(np.array([6.0, 0.0, 0.5]), 1.6)
    qs = cp.tip_line(q_a, CartesianTarget(np.array([6.0, 0.0, 2.5]), 1.6))
    tips = np.array([kin.tip_position(q) for q in qs])
    np.testing.assert_allclose(tips[:, :2], [[6.0, 0.0]] * len(tips), atol=1e-6)  # straight up, not an arc
    assert np.all(np.diff(tips[:, 2]) > 0) and len(qs) >= 100
    line = cp.joint_line(q_a, np.asarray(JointTarget(kin.home).q))
    assert np.max(np.abs(np.diff(line, axis=0))) <= cp.cfg.path_step_rad + 1e-9


def test_a_bad_collision_file_names_file_line_and_key(tmp_path) -> None:
    good = (data_root() / "config" / "tms_rp" / "zx200_collision.yaml").read_text()
    for old, new, message in (
        ("  bucket_end_link: {sphere: 0.1}", "  cab_link: {sphere: 0.1}", r"links.cab_link: not an arm link"),
        ("  bucket_end_link: {sphere: 0.1}", "  bucket_end_link: {cone: 0.1}",
         r":\d+: links.bucket_end_link.cone: unknown"),
        ("lift_levels: 12", "lift_levels: many", r":\d+: lift_levels: expected an integer"),
        ("detour_margin: 0.15", "detour_margin: 0.15\ndetour_margn: 0.1", r":\d+: detour_margn: unknown key"),
    ):
        assert old in good, old
        bad = tmp_path / "zx200_collision.yaml"
        bad.write_text(good.replace(old, new))
        with pytest.raises(ConfigError, match=message):
            load_collision_config("zx200", bad)
