"""The paper's trees and seed: well-formed Groot XML, only allowed nodes, every record present with the
original shapes, geometry consistent with config/site.yaml and the machines."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from tests.tms_sp.treeutil import (
    BUILTINS,
    CUSTOM_PORTS,
    ROOT,
    SUBTASKS,
    TREE_FILES,
    iter_nodes,
    load_seed,
    node_id,
    tree_root,
)
from tms_model.geometry import Pose2D, wrap_angle, yaw_from_quaternion
from tms_sp.config import load_sensing_config

SEED = load_seed()
CFG = load_sensing_config()
SITE = yaml.safe_load((ROOT / "config" / "site.yaml").read_text())
ZX200 = yaml.safe_load((ROOT / "config" / "machines" / "zx200.yaml").read_text())
IC120 = yaml.safe_load((ROOT / "config" / "machines" / "ic120.yaml").read_text())


def _params() -> dict[tuple[str | None, str], dict]:
    return {(d.get("model_name"), d["record_name"]): d for d in SEED["parameters"]}


def _blackboard() -> dict:
    docs = [d for d in SEED["parameters"] if d["record_name"] == CFG.blackboard_records[0]]
    assert len(docs) == 1
    return docs[0]


def test_there_are_the_two_paper_trees():
    names = {p.name for p in TREE_FILES}
    assert {"paper_ic120_haul.xml", "paper_zx200_load.xml"} <= names


@pytest.mark.parametrize("path", TREE_FILES, ids=lambda p: p.name)
def test_tree_is_groot1_btcpp_v3(path):
    root = ET.parse(path).getroot()
    assert root.tag == "root" and "BTCPP_format" not in root.attrib
    tree = tree_root(path)
    assert root.get("main_tree_to_execute") == tree.get("ID")
    model = root.find("TreeNodesModel")
    assert model is not None
    declared = {el.get("ID") for el in model}
    used = {node_id(el) for el in iter_nodes(path)} & set(CUSTOM_PORTS)
    assert used <= declared, f"{path.name}: custom nodes missing from TreeNodesModel: {used - declared}"
    for el in model:
        ports = {p.get("name") for p in el}
        assert ports == CUSTOM_PORTS[el.get("ID")], el.get("ID")


@pytest.mark.parametrize("path", TREE_FILES, ids=lambda p: p.name)
def test_only_allowed_nodes_and_ports(path):
    for el in iter_nodes(path):
        nid = node_id(el)
        if el.tag in ("Action", "Decorator"):
            assert nid in CUSTOM_PORTS, f"{path.name}: unknown node id {nid!r}"
            ports = set(el.attrib) - {"ID", "name"}
            assert ports == CUSTOM_PORTS[nid], f"{path.name}: {nid} ports {sorted(ports)}"
        else:
            assert nid in BUILTINS, f"{path.name}: unknown built-in {nid!r}"
        children = len(el)
        if nid == "IfThenElse":
            assert children == 3, f"{path.name}: IfThenElse {el.get('name')} needs condition, then, else"
        elif el.tag == "Decorator":
            assert children == 1
        elif nid in ("Sequence", "Fallback", "ReactiveSequence"):
            assert children >= 1
        elif el.tag == "Action" or nid in ("AlwaysSuccess", "AlwaysFailure"):
            assert children == 0


@pytest.mark.parametrize("path", TREE_FILES, ids=lambda p: p.name)
def test_leaf_records_exist_in_the_seed_with_the_subtask_shape(path):
    params = _params()
    leaves = [el for el in iter_nodes(path) if node_id(el).startswith("LeafNode")]
    assert leaves
    for el in leaves:
        model, record, subtask = el.get("model_name"), el.get("record_name"), el.get("subtask_name")
        assert node_id(el) == "LeafNode" + model.capitalize()
        assert subtask in SUBTASKS[model], f"{record}: subtask {subtask!r} is not a subtask name of the original"
        doc = params.get((model, record))
        assert doc is not None, f"{path.name}: record ({model}, {record}) missing from config/seeds/paper.yaml"
        assert doc["type"] in ("static", "dynamic")
        payload = {
            k: v for k, v in doc.items() if k not in ("model_name", "record_name", "type", "description", "LOCK_FLG")
        }
        if subtask == "st_ic120_follow_waypoints":
            assert set(payload) == {"x", "y", "z", "qx", "qy", "qz", "qw"}
            lengths = {len(v) for v in payload.values()}
            assert len(lengths) == 1 and lengths.pop() >= 1
            assert all(isinstance(x, float | int) for v in payload.values() for x in v)
        elif subtask == "st_ic120_navigate_anywhere":
            assert set(payload) == {"x", "y", "z", "qx", "qy", "qz", "qw"}
            assert all(isinstance(v, float | int) for v in payload.values())
        elif subtask in ("st_ic120_release_soil", "subtask_zx200_release_simple"):
            assert set(payload) == {"target_angle"} and isinstance(payload["target_angle"], float | int)
        elif subtask == "subtask_zx200_excavate_simple":
            assert payload.get("position_with_angle") == 1
            assert set(payload) == {"position_with_angle", "x", "y", "z", "theta_w", "offset"}
            assert doc["LOCK_FLG"] is False
        elif subtask == "subtask_zx200_change_pose":
            if payload.get("trajectory") == 1:
                assert set(payload) == {
                    "trajectory",
                    "swing_joint",
                    "boom_joint",
                    "arm_joint",
                    "bucket_joint",
                    "bucket_end_joint",
                }
            else:
                assert payload.get("position_with_angle") == 1
                assert set(payload) - {"pass_through", "theta_w_tolerance"} == {
                    "position_with_angle",
                    "x",
                    "y",
                    "z",
                    "theta_w",
                }
                assert 0 <= payload.get("theta_w_tolerance", 0) <= 1.6, f"{record}: theta_w_tolerance [rad]"
            assert payload.get("pass_through", 0) in (0, 1, True, False), f"{record}: pass_through must be 0/1"
        else:  # pragma: no cover - a new subtask needs a shape check here
            raise AssertionError(f"no shape check for {subtask}")


@pytest.mark.parametrize("path", TREE_FILES, ids=lambda p: p.name)
def test_blackboard_nodes_use_seeded_typed_flags(path):
    bb = _blackboard()
    set_keys: set[str] = set()
    for el in iter_nodes(path):
        nid = node_id(el)
        if nid in ("BlackboardValueReaderMongo", "MongoValueWriter"):
            assert el.get("mongo_record_name") == CFG.blackboard_records[0]
            field = el.get("mongo_param_name")
            assert isinstance(bb.get(field), bool), f"{field} not a bool flag of the blackboard seed"
            if nid == "MongoValueWriter":
                assert el.get("input_value") in ("true", "false")
            else:
                assert el.get("output_port") == field
                set_keys.add(field)
        elif nid == "SetLocalBlackboard":
            assert el.get("value") in ("true", "false")  # bools: KeepRunningUntilFlgup throws on other types
            set_keys.add(el.get("output_key"))
    for el in iter_nodes(path):
        if node_id(el) == "KeepRunningUntilFlgup":
            assert el.get("key") in set_keys
        if node_id(el) == "ConditionalExpression":
            expr = el.get("conditional_expression")
            names = set(re.findall(r"[A-Za-z_]\w*", expr)) - {"and", "or", "true", "false"}
            assert names and names <= set_keys, f"{expr!r}: unknown keys {names - set_keys}"
            assert re.fullmatch(r"[\w\s()=!]+", expr)


#: The seed paper's Table 7: flag -> (update method, initial state). "Auto": written by the tasks' trees;
#: "Manual (Sensing)": written by sensing only. SENSING_CHECK_MOUND_FLG true means *not enough* soil in the mound.
TABLE7 = {
    "ARRIVAL_FLG": ("Auto", False),
    "CONTINUE_FLG": ("Auto", True),
    "MOVING_FLG": ("Auto", True),
    "INITIAL_POSE_FLG": ("Auto", True),
    "SENSING_ARRIVAL_FLG": ("Manual", False),
    "SENSING_CHECK_MOUND_FLG": ("Manual", False),
    "SENSING_LOADED_FLG": ("Manual", False),
}
PAPER_TREES = [p for p in TREE_FILES if p.name.startswith("paper_")]


def test_table7_flags_seeded_with_table7_initial_states():
    bb = _blackboard()
    assert bb["type"] == "dynamic"  # sensing may only update dynamic documents
    flags = {k for k, v in bb.items() if isinstance(v, bool)}
    assert flags == set(TABLE7), f"flags not in Table 7: {flags - set(TABLE7)}; missing: {set(TABLE7) - flags}"
    assert {f: bb[f] for f in TABLE7} == {f: initial for f, (_, initial) in TABLE7.items()}


def test_table7_flags_written_by_the_party_table7_names():
    from tms_sp.processor import FLAGS

    written, read = set(), set()
    for path in PAPER_TREES:
        for el in iter_nodes(path):
            if node_id(el) == "MongoValueWriter":
                written.add(el.get("mongo_param_name"))
            elif node_id(el) == "BlackboardValueReaderMongo":
                read.add(el.get("mongo_param_name"))
    auto = {f for f, (method, _) in TABLE7.items() if method == "Auto"}
    manual = set(TABLE7) - auto
    assert written == auto, f"trees write {written}, Table 7's Auto flags are {auto}"
    assert set(FLAGS) == manual  # sensing writes the Manual ones, and only those
    assert set(TABLE7) <= read | {"CONTINUE_FLG"} and manual <= read


def test_seed_tasks_point_at_tree_files_one_machine_each():
    ids = [t["task_id"] for t in SEED["tasks"]]
    assert len(ids) == len(set(ids)) and all(isinstance(i, int) and i > 0 for i in ids)
    machines = set()
    for task in SEED["tasks"]:
        text = (ROOT / task["file"]).read_text()
        ET.fromstring(text)
        found = set(re.findall(r"zx120|zx200|ic120", text.lower()))  # the original generator's model detection
        assert len(found) == 1, f"{task['file']}: one machine per task, found {found}"
        machines |= found
        assert task["description"]
    assert machines == {"ic120", "zx200"}


def test_seed_documents_are_keyed_and_unique():
    keys = [(d.get("model_name"), d["record_name"]) for d in SEED["parameters"]]
    assert len(keys) == len(set(keys))
    for d in SEED["parameters"]:
        assert d["type"] in ("static", "dynamic") and d["model_name"]


def _pose_list(doc) -> list[Pose2D]:
    xs = doc["x"] if isinstance(doc["x"], list) else [doc["x"]]
    get = (lambda k, i: doc[k][i]) if isinstance(doc["x"], list) else (lambda k, i: doc[k])
    out = []
    for i in range(len(xs)):
        q = [get(k, i) for k in ("qx", "qy", "qz", "qw")]
        assert math.isclose(np.linalg.norm(q), 1.0, abs_tol=1e-6)
        out.append(Pose2D(get("x", i), get("y", i), yaw_from_quaternion(q)))
    return out


ROUTE = ["LOAD_PATH", "RELEASE_PATH", "TURN_TO_RELEASE", "RELEASE_MOVE", "LOAD_MOVE", "TURN_TO_LOAD"]
REVERSE = {"LOAD_PATH", "RELEASE_MOVE"}


def test_ic120_route_matches_site_points_and_drives_in_reverse_where_it_must():
    params = _params()
    p = CFG.points
    seq = [p["ic120_start"]]
    for record in ROUTE:
        for pose in _pose_list(params[("ic120", record)]):
            prev = seq[-1]
            dist = math.hypot(pose.x - prev.x, pose.y - prev.y)
            if dist > 1e-6:
                bearing = math.atan2(pose.y - prev.y, pose.x - prev.x)
                reverse = abs(wrap_angle(bearing - pose.yaw)) > math.pi / 2
                assert reverse == (record in REVERSE), f"{record}: reverse={reverse}"
            else:
                assert record.startswith("TURN_")
            seq.append(pose)
    named = {name: seq_pose for name in ("P1", "P2", "P3", "P4", "P5") for seq_pose in seq
             if math.hypot(seq_pose.x - p[name].x, seq_pose.y - p[name].y) < 1e-6}
    assert set(named) == {"P1", "P2", "P3", "P4", "P5"}
    for name in ("P1", "P5"):  # loading and dumping poses exactly as site.yaml says
        hits = [s for s in seq if math.hypot(s.x - p[name].x, s.y - p[name].y) < 1e-6]
        assert all(abs(wrap_angle(s.yaw - p[name].yaw)) < 1e-5 for s in hits)
    assert (
        math.hypot(seq[-1].x - seq[0].x, seq[-1].y - seq[0].y) < 1e-6
        and abs(wrap_angle(seq[-1].yaw - seq[0].yaw)) < 1e-6
    )
    d15 = math.hypot(p["P5"].x - p["P1"].x, p["P5"].y - p["P1"].y)
    assert 30.0 <= d15 <= 40.0


def _footprint_corners(pose: Pose2D) -> np.ndarray:
    half_l, half_w = IC120["footprint"]["length"] / 2, IC120["footprint"]["width"] / 2
    local = np.array([[sx * half_l, sy * half_w, 0.0] for sx in np.linspace(-1, 1, 7) for sy in np.linspace(-1, 1, 5)])
    return pose.to_map(local)


def test_ic120_route_keeps_clear_of_the_mound_and_the_backhoe():
    params = _params()
    m = CFG.mound
    swing = CFG.swing_axis_map()
    tail = 3.0  # [m] ZX200 upper-structure swing radius (counterweight) + margin
    poses = [CFG.points["ic120_start"]]
    for record in ROUTE:
        poses.extend(_pose_list(params[("ic120", record)]))
    half_diag = math.hypot(IC120["footprint"]["length"], IC120["footprint"]["width"]) / 2
    for a, b in zip(poses, poses[1:], strict=False):
        if math.hypot(b.x - a.x, b.y - a.y) < 1e-6:  # turn in place: the swept disk must be clear
            assert math.hypot(a.x - m.cx, a.y - m.cy) > m.base_radius + half_diag
            assert math.hypot(a.x - swing[0], a.y - swing[1]) > tail + half_diag
            continue
        for s in np.linspace(0, 1, 50):
            pose = Pose2D(a.x + s * (b.x - a.x), a.y + s * (b.y - a.y), b.yaw)
            c = _footprint_corners(pose)
            assert np.min(np.hypot(c[:, 0] - m.cx, c[:, 1] - m.cy)) > m.base_radius + 0.3, (a, b, s)
            assert np.min(np.hypot(c[:, 0] - swing[0], c[:, 1] - swing[1])) > tail, (a, b, s)


def _fk_tip(q: dict[str, float]) -> np.ndarray:
    """Bucket tip in ZX200 base_link from the URDF chain in config/machines/zx200.yaml."""

    def rot(axis, angle):
        axis = np.asarray(axis, float)
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k

    def rpy(r, p, y):
        return rot([0, 0, 1], y) @ rot([0, 1, 0], p) @ rot([1, 0, 0], r)

    t = np.eye(4)
    for name in ZX200["front_joints"]:
        j = ZX200["joints"][name]
        step = np.eye(4)
        step[:3, :3] = rpy(*j["origin_rpy"]) @ rot(j["axis"], q[name])
        step[:3, 3] = j["origin_xyz"]
        t = t @ step
    return (t @ np.array([*ZX200["bucket_tip_xyz"], 1.0]))[:3]


def test_fk_helper_matches_the_reference_home_tip():
    tip = _fk_tip({"swing_joint": 0, "boom_joint": 0, "arm_joint": 1.65806, "bucket_joint": 0})
    assert tip == pytest.approx([5.60, -0.09, -2.48], abs=0.02)  # the zx200_ros2 URDF chain


def test_zx200_joint_poses_within_limits_and_above_ground():
    for doc in SEED["parameters"]:
        if doc.get("model_name") == "zx200" and doc.get("trajectory") == 1:
            for name in ZX200["front_joints"]:
                lim = ZX200["joints"][name]["position"]
                if lim is not None:
                    assert lim[0] <= doc[name] <= lim[1], (doc["record_name"], name)
            tip = _fk_tip(doc)
            m = CFG.mound
            r = math.hypot(tip[0] - m.cx, tip[1] - m.cy)
            surface = m.ground_z + m.height * min(max((m.base_radius - r) / (m.base_radius - m.top_radius), 0.0), 1.0)
            assert tip[2] > surface + 0.5, f"{doc['record_name']}: bucket tip z={tip[2]:.2f} m, soil at {surface:.2f} m"
            # Facing the mound (swing 0), never over the IC120's lane (y > 4.8 m).
            assert tip[1] < 3.0


def test_dynamic_targets_seeded_as_sensing_computes_them_for_the_seeded_site():
    from tms_sp.heightgrid import rasterize
    from tms_sp.mound import assess_mound
    from tms_sp.synthetic import truncated_cone
    from tms_sp.vessel import assess_vessel, release_in_excavator

    params = _params()
    m = CFG.mound
    xg, yg = CFG.mound_grid.centres()
    z = truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, m.height, m.ground_z)(xg, yg)
    grid = rasterize(np.column_stack([xg.ravel(), yg.ravel(), z.ravel()]), CFG.mound_grid)
    target = assess_mound(grid, CFG.swing_axis_map(), CFG.excavation).target.record_fields(CFG.excavator_base)
    seeded = params[("zx200", CFG.excavation_record)]
    for key in ("x", "y", "z", "theta_w", "offset"):
        assert seeded[key] == pytest.approx(target[key], abs=0.02), key
    spec = CFG.vessel_geom.grid_spec(CFG.resolution)
    xv, yv = spec.centres()
    empty = rasterize(np.column_stack([xv.ravel(), yv.ravel(), 0 * xv.ravel()]), spec)
    va = assess_vessel(empty, CFG.vessel_geom, CFG.vessel)
    pose, angle = release_in_excavator(va.release_xyz, CFG.points["P1"], CFG.excavator_base, CFG.vessel_geom,
                                   CFG.swing_axis_in_base, CFG.vessel.carry_theta_w)
    seeded = params[("zx200", CFG.release_record)]
    for key in ("x", "y", "z", "theta_w"):
        assert seeded[key] == pytest.approx(pose[key], abs=0.02), key
    assert params[("zx200", CFG.angle_record)]["target_angle"] == pytest.approx(angle["target_angle"], abs=0.01)
    # The release point is within the ZX200's reach (about 9.5 m at ground).
    assert math.hypot(seeded["x"], seeded["y"]) < 9.0


def test_site_map_is_current_and_the_route_is_free_on_it():
    from tms_sp import sitemap

    committed = (ROOT / "config" / "maps" / "site.pgm").read_bytes()
    assert committed == sitemap.pgm_bytes(sitemap.render(CFG)), "run `python -m tms_sp.sitemap`"
    meta = yaml.safe_load((ROOT / "config" / "maps" / "site.yaml").read_text())
    assert meta["image"] == "site.pgm" and meta["resolution"] == sitemap.RESOLUTION
    img = sitemap.render(CFG)[::-1]  # row 0 = min y
    ox, oy = meta["origin"][:2]

    def free(x, y):
        return img[int((y - oy) / meta["resolution"]), int((x - ox) / meta["resolution"])] == 254

    for name in ("P1", "P2", "P3", "P4", "P5", "ic120_start"):
        assert free(CFG.points[name].x, CFG.points[name].y), name
    assert not free(CFG.mound.cx, CFG.mound.cy) and not free(0.0, 0.0)
