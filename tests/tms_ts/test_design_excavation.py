"""The design subtask's pure core (tms_ts.design_excavation) and its record (the ``*_excavate_design`` row of
tms_ts.subtask_specs): passes as the original's excavate / change_pose / release goals in the base frame, the stop
reasons named with the design, and the seed's trench within the paper site's excavator's reach, off the mound."""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from pathlib import Path

import numpy as np
import pytest

from tests.rosproc import ROOT
from tests.tms_rp.test_excavation_sweep import _drag
from tms_common.config import load_yaml
from tms_model.excavator.kinematics import ExcavatorKinematics, site_excavator_kind
from tms_model.machines import load_machine
from tms_model.site import load_site
from tms_rp.arm.planner import ArmPlanner, load_planner_config
from tms_rp.excavation.design import Design, DesignError, Grid, cell_centres, distance_to_polygon
from tms_rp.excavation.planner import BasePose, PlannerSettings
from tms_ts.design_excavation import (
    DUMP_THETA_W,
    DesignExcavation,
    Done,
    PassGoals,
    base_from_swing_centre,
    ground_top,
    standing_pose,
    to_base,
)
from tms_ts.errors import SubtaskRecordError
from tms_ts.plans import AnglePlan, ChangePosePlan, DesignPlan, ExcavatePlan
from tms_ts.subtask_specs import SUBTASKS, build_excavate_design

KIND = site_excavator_kind()
MACHINE = load_machine(KIND)
ROW = next(s for s in SUBTASKS.values() if s.name.endswith("_excavate_design") and s.machine == KIND)
SEED = ROOT / "config" / "seeds" / "design_trench.yaml"
TRENCH = {"name": "tr", "kind": "trench", "start": [-5.0, -5.0], "end": [-5.0, 5.0], "width": 1.0, "depth": 0.5,
          "ground_z": 0.0, "margin": 0.5}
RECORD = {"design": "tr", "base_x": 0.0, "base_y": 0.0, "base_yaw": 0.0}


def flat(x0: float = -11.0, x1: float = 3.0, y0: float = -9.0, y1: float = 9.0, cell: float = 0.1) -> Grid:
    return Grid(z=np.zeros((round((y1 - y0) / cell), round((x1 - x0) / cell))), x_min=x0, y_min=y0, x_max=x1,
                y_max=y1)


def plan_of(**fields: object) -> DesignPlan:
    return build_excavate_design({**RECORD, **fields}, "job")


def dig(grid: Grid, step: PassGoals) -> None:
    """An idealised machine: the pass's cells to their planned heights, the volume onto its dump cells."""
    cut = step.cut
    z = grid.z
    area = (grid.x_max - grid.x_min) / z.shape[1] * (grid.y_max - grid.y_min) / z.shape[0]
    r, c = cut.cells[:, 0], cut.cells[:, 1]
    removed = float(np.sum(z[r, c] - cut.cut_to)) * area
    z[r, c] = cut.cut_to
    dr, dc = cut.dump_cells[:, 0], cut.dump_cells[:, 1]
    z[dr, dc] += removed / (len(dr) * area)


# ---- the record ---------------------------------------------------------------------------------------------
def test_the_row_is_ours_beside_the_originals() -> None:
    assert ROW.steps is not None and set(ROW.steps) == {"excavate", "change_pose", "release"}
    for what, step in ROW.steps.items():
        assert step.planning_action == SUBTASKS[step.name].planning_action, what
        assert not step.clears_lock_flg  # the design record is not sensing's target
    assert SUBTASKS[ROW.steps["excavate"].name].clears_lock_flg  # the original's row keeps its behaviour


def test_record_defaults_and_fields() -> None:
    p = plan_of(dump_x=1.0, dump_y=-7.5)
    assert p.design == "tr" and p.base == {"x": 0.0, "y": 0.0, "yaw": 0.0, "z": 0.0}
    assert p.dump == {"x": 1.0, "y": -7.5} and p.dump_height == 1.5 and p.max_passes == 200 and p.terrain_id == 3031
    assert plan_of().dump is None


@pytest.mark.parametrize(("fields", "match"), [
    ({"design": ""}, r"record 'job'.*design.*must be a design's name"),
    ({"design": None}, r"design"),
    ({"base_x": "0"}, r"base_x.*finite number"),
    ({"dump_x": 1.0}, r"dump_x\|dump_y.*both or neither"),
    ({"max_passes": 2.5}, r"max_passes.*integer"),
    ({"dump_height": 0.0}, r"dump_height"),
])
def test_record_errors_name_the_record_and_field(fields: dict, match: str) -> None:
    doc = {**RECORD, **fields}
    if fields.get("design", "x") is None:
        del doc["design"]
    with pytest.raises(SubtaskRecordError, match=match):
        build_excavate_design(doc, "job")


def test_a_missing_base_is_named() -> None:
    doc = dict(RECORD)
    del doc["base_yaw"]
    with pytest.raises(SubtaskRecordError, match="base_yaw"):
        build_excavate_design(doc, "job")


# ---- the passes as goals --------------------------------------------------------------------------------------
def test_a_pass_becomes_excavate_carry_release_in_the_base_frame() -> None:
    run = DesignExcavation(plan_of(dump_x=1.0, dump_y=-7.5), MACHINE)
    step = run.step(TRENCH, flat())
    assert isinstance(step, PassGoals) and step.number == 1
    (w1, exc), (w2, carry), (w3, rel) = step.goals
    assert (w1, w2, w3) == ("excavate", "change_pose", "release")
    assert isinstance(exc, ExcavatePlan) and isinstance(carry, ChangePosePlan) and isinstance(rel, AnglePlan)
    cut = step.cut
    arm = load_planner_config(KIND)
    depth = arm.penetrate_depth
    assert exc.pwa["x"] == pytest.approx(cut.start[0]) and exc.pwa["y"] == pytest.approx(cut.start[1])
    assert exc.pwa["z"] == pytest.approx(cut.start[2] + depth)  # the arm planner goes penetrate_depth deeper
    # the drag ends curl_carry short of the band's end: the curl and lift cuts the rest
    assert cut.length > 2 * arm.curl_carry > 0
    assert exc.pwa["offset"] == pytest.approx(cut.length - arm.curl_carry) and exc.pwa["theta_w"] == pytest.approx(1.1)
    assert carry.pwa == pytest.approx({"x": 1.0, "y": -7.5, "z": 1.5, "theta_w": DUMP_THETA_W})
    assert carry.pass_through
    origin = run.planner.kin.swing_origin
    assert rel.what == "release" and rel.target_angle == pytest.approx(math.atan2(-7.5 - origin[1], 1.0 - origin[0]))
    assert run.volume == pytest.approx(cut.volume) and run.passes == 1


def test_the_dump_height_counts_from_the_sensed_heap_at_a_fixed_dump_place() -> None:
    """The spoil heap at the record's dump place grows pass by pass (3.2 m after 31 passes of the trench on the plant,
    which buried a bucket opening at dump_height over the bare ground): the carry goes dump_height over the highest
    sensed cell within a bucket width of the place; a place outside the sensed terrain keeps the record's dump_z."""
    grid = flat()
    x, y = cell_centres(grid)
    r = np.hypot(x - 1.0, y + 7.5)
    grid.z[:] = np.where(r < 1.5, 2.0 * (1.0 - r / 1.5), 0.0)  # a cone 2 m high at (1, -7.5)
    top = ground_top(grid, 1.0, -7.5, MACHINE.bucket.width)
    assert top == pytest.approx(float(grid.z.max()))
    assert ground_top(grid, 30.0, 0.0, 1.0) is None
    carry = DesignExcavation(plan_of(dump_x=1.0, dump_y=-7.5), MACHINE).step(TRENCH, grid).goals[1][1]
    assert carry.pwa["z"] == pytest.approx(top + 1.5)
    # a heap beside the place, farther than a bucket width: not under the bucket
    shifted = flat()
    shifted.z[:] = np.where(np.hypot(x - 1.0, y + 4.0) < 0.5, 3.0, 0.0)
    carry = DesignExcavation(plan_of(dump_x=1.0, dump_y=-7.5), MACHINE).step(TRENCH, shifted).goals[1][1]
    assert carry.pwa["z"] == pytest.approx(1.5)
    # the place outside the terrain: the record's dump_z
    carry = DesignExcavation(plan_of(dump_x=1.0, dump_y=-12.0, dump_z=0.2), MACHINE).step(TRENCH, grid).goals[1][1]
    assert carry.pwa["z"] == pytest.approx(0.2 + 1.5)


def test_the_base_frame_follows_the_base_pose() -> None:
    base = BasePose(2.0, 1.0, math.pi / 2, 0.3)
    assert to_base(base, 2.0, 4.0, 0.3) == pytest.approx((3.0, 0.0, 0.0))  # 3 m ahead of a machine facing north
    assert to_base(base, 0.0, 1.0, 1.3) == pytest.approx((0.0, 2.0, 1.0))  # 2 m to its left
    # the same design and terrain seen from a machine moved and turned: the goals move with it
    shifted = {**TRENCH, "start": [2.0 - 5.0, 1.0 - 5.0], "end": [2.0 - 5.0, 1.0 + 5.0]}
    rotated = {**TRENCH, "start": [2.0 + 5.0, 1.0 - 5.0], "end": [2.0 - 5.0, 1.0 - 5.0]}  # west of a north-facer
    a = DesignExcavation(plan_of(base_x=2.0, base_y=1.0), MACHINE).step(shifted, flat(-9, 5, -8, 10))
    b = DesignExcavation(plan_of(base_x=2.0, base_y=1.0, base_yaw=math.pi / 2), MACHINE).step(
        rotated, flat(-8, 12, -9, 4))
    assert isinstance(a, PassGoals) and isinstance(b, PassGoals)
    for step in (a, b):  # in its own frame each machine cuts the trench 5 m behind it
        pwa = step.goals[0][1].pwa
        assert -6.0 <= pwa["x"] <= -4.0 and abs(pwa["y"]) <= 5.5, pwa


def test_the_run_ends_within_tolerance_naming_the_design() -> None:
    grid = flat()
    # clipped strips (not the subtask's default): this digger lowers exactly the planned cells
    run = DesignExcavation(plan_of(dump_x=1.0, dump_y=-7.5), MACHINE, PlannerSettings(level_sweep=False))
    for _ in range(200):
        step = run.step(TRENCH, grid)
        if isinstance(step, Done):
            break
        dig(grid, step)
    assert isinstance(step, Done) and step.ok, step
    assert step.message.startswith("design 'tr' done after") and "within tolerance" in step.message
    assert run.volume == pytest.approx(5.0, rel=0.05)  # 10 m x 1 m x 0.5 m
    assert step.error is not None and step.error.mae <= 0.02


def test_by_default_a_pass_is_the_level_sweep_the_arm_drags() -> None:
    """The arm's excavate drags the edge level over the whole bucket width: the subtask plans that sweep, one edge
    height, the whole band inside the trench's floor (no wall or apron cell under the bucket)."""
    grid = flat()
    run = DesignExcavation(plan_of(dump_x=1.0, dump_y=-7.5), MACHINE)
    assert run.planner.settings.level_sweep
    design = Design.from_dict(TRENCH)
    target = design.sample(grid).target
    for _ in range(5):
        step = run.step(TRENCH, grid)
        assert isinstance(step, PassGoals)
        cut = step.cut
        assert np.ptp(cut.path[:, 2]) == 0.0 and step.goals[0][1].pwa["z"] == pytest.approx(cut.start[2])
        rows, cols = cut.cells[:, 0], cut.cells[:, 1]
        assert np.all(target[rows, cols] == pytest.approx(-0.5))  # only floor cells under the bucket
        assert np.all(cut.cut_to >= target[rows, cols] - 1e-9)
        grid.z[rows, cols] = cut.cut_to


# ---- stops, each naming the design ----------------------------------------------------------------------------
def test_a_design_out_of_reach_fails_naming_it() -> None:
    far = {**TRENCH, "name": "far", "start": [-25.0, -5.0], "end": [-25.0, 5.0]}
    step = DesignExcavation(plan_of(design="far"), MACHINE).step(far, flat(-30, 3, -9, 9))
    assert isinstance(step, Done) and not step.ok
    assert step.message.startswith("design 'far': the pass planner stops after 0 pass(es)")
    assert "nothing reachable to cut" in step.message


def test_terrain_not_covering_the_design_fails_naming_both() -> None:
    step = DesignExcavation(plan_of(), MACHINE).step(TRENCH, flat(-5.2, 3, -9, 9))
    assert isinstance(step, Done) and not step.ok
    assert "design 'tr': its area x [-6, -4]" in step.message and "sensed terrain (dynamic heightmap id 3031)" \
        in step.message and "x [-5.2, 3]" in step.message


def test_a_bad_stored_document_fails_naming_the_design_and_key() -> None:
    step = DesignExcavation(plan_of(), MACHINE).step({**TRENCH, "width": -1}, flat())
    assert isinstance(step, Done) and not step.ok
    assert "design 'tr': the stored document is refused" in step.message and "width" in step.message
    other = DesignExcavation(plan_of(), MACHINE).step({**TRENCH, "name": "other"}, flat())
    assert isinstance(other, Done) and "stored document is named 'other'" in other.message


def test_max_passes_fails_naming_the_design() -> None:
    run = DesignExcavation(plan_of(max_passes=2), MACHINE)
    grid = flat()
    for _ in range(2):
        step = run.step(TRENCH, grid)
        assert isinstance(step, PassGoals)
        dig(grid, step)
    step = run.step(TRENCH, grid)
    assert isinstance(step, Done) and not step.ok
    assert step.message.startswith("design 'tr': not within tolerance after max_passes = 2 (2 pass(es)")


# ---- the seed: two base poses ------------------------------------------------------------------------------------
def _seed_records() -> tuple[dict, dict[str, dict]]:
    data, _ = load_yaml(SEED)
    return data, {p["record_name"]: p for p in data["parameters"]}


TREE_LEGS = [("design_trench_base_south", "st_zx200_navigate_anywhere_deg"), ("design_trench_south", ROW.name),
             ("design_trench_via_south", "st_zx200_navigate_anywhere_deg"),
             ("design_trench_via_north", "st_zx200_navigate_anywhere_deg"),
             ("design_trench_base_north", "st_zx200_navigate_anywhere_deg"), ("design_trench_north", ROW.name)]


def test_the_seed_trench_is_reachable_from_its_two_bases_on_flat_ground_and_off_the_mound() -> None:
    data, records = _seed_records()
    design = Design.from_dict(next(d for d in data["designs"] if d["name"] == records["design_trench_south"]["design"]))
    assert design.kind == "trench" and (design.params["width"], design.params["depth"]) == (1.0, 0.5)
    assert math.dist(design.params["start"], design.params["end"]) == pytest.approx(10.0)
    site = load_site()
    mound = site.mound
    for x, y in design.area:  # off the mound: every corner further from its centre than its base radius + 1 m
        assert math.hypot(x - mound.cx, y - mound.cy) > mound.base_radius + 1.0, (x, y)
    grid = flat(-11, 3, -12, 12)
    xc, yc = cell_centres(grid)
    sampled = design.sample(grid)
    bottom = sampled.inside & (sampled.target < -0.4)
    covered = np.zeros_like(bottom)
    for nav, job in (("design_trench_base_south", "design_trench_south"),
                     ("design_trench_base_north", "design_trench_north")):
        b, j = records[nav], records[job]
        assert j["base_measured"] and j["scope"] == "reachable" and j["design"] == design.name
        base = BasePose(b["x"], b["y"], math.radians(b["yaw"]), j["base_z"])
        run = DesignExcavation(build_excavate_design(j, job), MACHINE, base=base)
        axis = run.planner.swing_axis(base)
        radius = np.hypot(xc - axis[0], yc - axis[1])
        reach = bottom & run.planner.reachable(radius, sampled.target)
        assert reach.sum() > 0.5 * bottom.sum(), job  # each base reaches the trench's near half and more
        covered |= reach
        assert math.hypot(b["x"] - mound.cx, b["y"] - mound.cy) > mound.base_radius + 3.0, nav
        dump = np.array([j["dump_x"], j["dump_y"]])
        assert not design.contains(dump[:1], dump[1:]).any()
        # the heap beside the machine, not under it: a dump disc of the plant's radius clear of its footprint circle
        footprint = math.hypot(MACHINE.footprint.length, MACHINE.footprint.width) / 2
        assert math.dist(dump, (b["x"], b["y"])) > footprint + 1.2
        # the release opens the bucket with its tip held over the dump (tms_rp.arm.planner): there the arm can hold
        # the edge open enough for the plant to spill at 60 % of its full rate or more (3.6 m out it could not: the
        # load stayed in and fell on the apron on the way back)
        arm = ArmPlanner(ExcavatorKinematics(MACHINE), load_planner_config(KIND))
        tip = np.array([math.dist(dump, axis), 0.0, j["dump_height"] + j["dump_z"]])
        assert arm.feasible_theta_w(tip, arm.cfg.release_theta_w) < MACHINE.bucket.release_tip_angle - 0.3, job
        assert run.planner.reachable(np.hypot(*(dump - axis)), np.array(j["dump_height"])).all(), job
    assert covered[bottom].all()  # together every trench cell at its bottom


def test_the_route_between_the_bases_keeps_the_machine_off_the_trench() -> None:
    """The navigator's map does not know the trench: each straight leg of the tree after the south base (vias, north
    base) keeps the machine's footprint circle 0.5 m clear of the design's area (the first, from the start, runs before
    anything is dug), and of the south heap."""
    data, records = _seed_records()
    design = Design.from_dict(next(d for d in data["designs"] if d["name"] == records["design_trench_south"]["design"]))
    start = load_site().points["zx200_base"]
    stops = [(records[r]["x"], records[r]["y"]) for r, sub in TREE_LEGS if sub == "st_zx200_navigate_anywhere_deg"]
    assert math.dist(stops[0], (start.x, start.y)) > 5.0  # the first leg is a drive
    clear = math.hypot(MACHINE.footprint.length, MACHINE.footprint.width) / 2 + 0.5
    heap = (records["design_trench_south"]["dump_x"], records["design_trench_south"]["dump_y"])
    for a, b in itertools.pairwise(stops):
        t = np.linspace(0.0, 1.0, 200)[:, None]
        pts = np.asarray(a) + t * (np.asarray(b) - np.asarray(a))
        assert distance_to_polygon(pts[:, 0], pts[:, 1], np.array(design.area)).min() > clear, (a, b)
        assert np.hypot(pts[:, 0] - heap[0], pts[:, 1] - heap[1]).min() > clear - 0.5 + 1.2, (a, b)  # its dump disc


def test_bases_in_line_with_the_trench_cut_what_bases_beside_it_cannot() -> None:
    """An ideal machine (the excavate goal's level, bucket-wide drag) on flat ground. From beside the trench's ends
    the radial drags meet its walls at a slant: only many small passes cut the wedges along them; from the seed's two
    bases in line with it (each leg ending when nothing reachable from it is worth a pass, or the whole design within
    tolerance) the drags run along the trench, the bands moved sideways onto it (``lateral_step``), and cut it in a
    few bucket-full passes, also from bases off their goals by the navigator's tolerance. The figures:
    tms_rp/excavation/README.md."""
    data, records = _seed_records()
    doc = next(d for d in data["designs"] if d["name"] == records["design_trench_south"]["design"])

    arm = ArmPlanner(ExcavatorKinematics(MACHINE), load_planner_config(KIND))

    def legs(bases: list[tuple[BasePose, dict]]) -> tuple[Done, int]:
        grid, passes = flat(-11, 3, -12, 12), 0
        for base, job in bases:
            run = DesignExcavation(build_excavate_design(job, "job"), MACHINE, base=base)
            while not isinstance(step := run.step(doc, grid), Done):
                # the arm planner takes every excavate goal (a pass 8.73 m out once failed on the plant)
                pwa = step.goals[0][1].pwa
                arm.feasible_theta_w(np.array([pwa["x"], pwa["y"], pwa["z"] - run.penetrate_depth]), pwa["theta_w"])
                _drag(grid, step.cut, run.planner.bucket_width)
            assert step.ok and ("part reachable from the base" in step.message or "within tolerance" in step.message)
            passes += run.passes
        return step, passes

    jobs = ("design_trench_south", "design_trench_north")

    def in_line(dx: float, dy: float, dyaw: float) -> list[tuple[BasePose, dict]]:
        # off the goal by (dx, dy, dyaw), the south base one way and the north the other
        return [(BasePose(records[n]["x"] + sign * dx, records[n]["y"] + sign * dy,
                          math.radians(records[n]["yaw"]) + sign * dyaw, 0.0), records[j])
                for sign, n, j in ((1, "design_trench_base_south", jobs[0]), (-1, "design_trench_base_north", jobs[1]))]

    beside, n_beside = legs([(BasePose(0.0, sign * 4.5, 0.0, 0.0),
                              {**records[j], "dump_x": 0.5, "dump_y": sign * 9.5, "max_passes": 200})
                             for sign, j in ((-1, jobs[0]), (1, jobs[1]))])
    line, n_line = legs(in_line(0.0, 0.0, 0.0))
    print(f"\ntrench, ideal level sweeps: from beside its ends {n_beside} passes, MAE {beside.error.mae * 100:.2f} cm; "
          f"in line {n_line} passes, MAE {line.error.mae * 100:.2f} cm, p95 {line.error.p95 * 100:.1f} cm")
    # beside the ends, the bands moved sideways cut the slanted walls' wedges too, but only in many small passes
    assert line.error.mae < 0.005 and 5 * n_line < n_beside
    assert n_line < records[jobs[0]]["max_passes"]
    for off in ((0.1, 0.2, 0.1), (0.1, -0.2, -0.1)):  # the navigator's goal tolerance: 0.2 m, 0.1 rad
        assert legs(in_line(*off))[0].error.mae < 0.005, off


def _south_leg() -> tuple[dict, DesignExcavation]:
    """The seed's design document and its south leg's run, from the base it names."""
    data, records = _seed_records()
    doc = next(d for d in data["designs"] if d["name"] == records["design_trench_south"]["design"])
    b = records["design_trench_base_south"]
    run = DesignExcavation(build_excavate_design(records["design_trench_south"], "job"), MACHINE,
                           base=BasePose(b["x"], b["y"], math.radians(b["yaw"]), 0.0))
    return doc, run


def test_cells_a_machine_does_not_cut_are_left_after_two_futile_passes() -> None:
    """A machine that cuts the trench but not its south end strip (y < -4.8, as the plant's bucket did not at the
    near wall in run 15): the passes over the strip do not lower it; after two over each of its cells they are left
    out, and the leg ends naming them instead of planning the strip until max_passes."""
    doc, run = _south_leg()
    grid = flat(-11, 3, -12, 12)
    _, yc = cell_centres(grid)
    strip = (yc < -4.8) & (yc > -5.0)
    over_strip = 0
    while not isinstance(step := run.step(doc, grid), Done):
        before = grid.z.copy()
        _drag(grid, step.cut, run.planner.bucket_width)
        grid.z[strip] = before[strip]  # the bucket does not reach into the strip
        over_strip += int(strip[step.cut.cells[:, 0], step.cut.cells[:, 1]].any())
    assert step.ok and "part reachable" in step.message, step.message
    assert re.search(r"\d+ cell\(s\) left after 2 passes each lowered them by less than 20% of the depth planned",
                     step.message)
    assert 2 <= over_strip <= 6 and run.passes < 20  # not planned again and again
    design = Design.from_dict(doc)
    s = design.sample(grid)
    assert np.all(grid.z[strip & s.inside & (np.abs(cell_centres(grid)[0] + 5) < 0.5)] > -0.1)  # left


def test_an_edge_that_goes_deeper_than_sent_is_aimed_higher() -> None:
    """A machine whose edge goes 5 cm deeper than the excavate goal sends it (the arm under the soil's load): the
    subtask measures that on the cells each pass lowered and aims the edge higher, so the trench's floor ends within
    a centimetre of the design where without it the whole floor would be 5 cm too deep."""
    doc, run = _south_leg()
    grid = flat(-11, 3, -12, 12)
    offsets = []
    while not isinstance(step := run.step(doc, grid), Done):
        sent = step.goals[0][1].pwa["z"] - run.penetrate_depth  # the edge height the excavate goal asks (base z 0)
        _drag(grid, dataclasses.replace(step.cut, start=(*step.cut.start[:2], sent - 0.05)), run.planner.bucket_width)
        offsets.append(run.edge_offset)
    xc, yc = cell_centres(grid)
    floor = (np.abs(xc + 5.0) < 0.45) & (yc < -0.5) & (yc > -4.5)  # the south leg's floor, off its ends
    assert offsets[0] == 0.0 and offsets[-1] == pytest.approx(0.05, abs=0.01)
    assert abs(float(np.median(grid.z[floor])) + 0.5) < 0.01, float(np.median(grid.z[floor]))


def test_the_tree_drives_to_each_base_and_digs_there() -> None:
    xml = (ROOT / "trees" / "design_trench.xml").read_text()
    legs = re.findall(r'record_name="([^"]+)" subtask_name="([^"]+)"', xml)
    assert legs == TREE_LEGS
    _, records = _seed_records()
    assert all(r in records for r, _ in legs)
    assert Path(SEED).is_file()


# ---- a leg of several: the measured base, the reachable scope -------------------------------------------------------
def test_a_measured_base_and_the_reachable_scope_are_read_and_checked() -> None:
    doc = {"design": "tr", "base_measured": 1, "scope": "reachable"}
    p = build_excavate_design(doc, "job")
    assert p.base_measured and p.scope == "reachable" and p.base == {"z": 0.0}
    assert plan_of().scope == "design" and not plan_of().base_measured
    with pytest.raises(SubtaskRecordError, match=r"record 'job'.*base_x.*base_measured, not both"):
        build_excavate_design({**doc, "base_x": 0.0}, "job")
    with pytest.raises(SubtaskRecordError, match=r"scope.*design, reachable.*'all'"):
        build_excavate_design({**RECORD, "scope": "all"}, "job")
    with pytest.raises(DesignError, match=r"design 'tr'.*base_measured.*none given"):
        DesignExcavation(p, MACHINE)
    with pytest.raises(DesignError, match=r"design 'tr'.*fixes the base pose"):
        DesignExcavation(plan_of(), MACHINE, base=BasePose(0.0, 0.0, 0.0, 0.0))


def test_the_reachable_scope_ends_ok_where_the_design_scope_fails() -> None:
    far = {**TRENCH, "name": "far", "start": [-25.0, -5.0], "end": [-25.0, 5.0]}
    base = BasePose(0.0, 0.0, 0.0, 0.0)
    leg = DesignExcavation(build_excavate_design({"design": "far", "base_measured": 1, "scope": "reachable"}, "j"),
                           MACHINE, base=base).step(far, flat(-30, 3, -9, 9))
    assert isinstance(leg, Done) and leg.ok
    assert leg.message.startswith("design 'far': the part reachable from the base at (0.00, 0.00, yaw 0.000) done")
    whole = DesignExcavation(plan_of(design="far"), MACHINE).step(far, flat(-30, 3, -9, 9))
    assert isinstance(whole, Done) and not whole.ok


def test_the_base_pose_of_a_standing_machine_from_its_swing_centre() -> None:
    rng = np.random.default_rng(3)
    truth = BasePose(1.0, -4.5, 0.3, 0.0)
    o = ExcavatorKinematics(MACHINE).swing_origin
    sx = truth.x + math.cos(truth.yaw) * o[0] - math.sin(truth.yaw) * o[1]
    sy = truth.y + math.sin(truth.yaw) * o[0] + math.cos(truth.yaw) * o[1]
    samples = [(sx + rng.normal(0, 0.01), sy + rng.normal(0, 0.01), truth.yaw + rng.normal(0, 0.001))
               for _ in range(50)]
    base = base_from_swing_centre(MACHINE, *standing_pose(samples, "t"), 0.0)
    assert (base.x, base.y, base.yaw) == pytest.approx((truth.x, truth.y, truth.yaw), abs=0.005)
    # the heading averaged on the circle across +-pi
    across = standing_pose([(0.0, 0.0, math.pi - 0.001), (0.0, 0.0, -math.pi + 0.001), (0.0, 0.0, math.pi)], "t")
    assert abs(math.remainder(across[2] - math.pi, 2 * math.pi)) < 0.002  # not 0, the arithmetic mean
    moving = [(0.1 * i, 0.0, 0.0) for i in range(20)]
    with pytest.raises(DesignError, match=r"who: the machine is not standing still"):
        standing_pose(moving, "who")
    with pytest.raises(DesignError, match=r"who: 2 pose sample\(s\), at least 3"):
        standing_pose(samples[:2], "who")


# ---- the embankment seed (config/seeds/design_embankment.yaml) on its plant's pile ----------------------------------
EMBANKMENT_SEED = ROOT / "config" / "seeds" / "design_embankment.yaml"


def test_the_seed_embankment_is_cut_out_of_the_plants_pile_by_level_sweeps() -> None:
    """The pile of config/sim/design_embankment_plant.yaml (the plant's own initial heights, 0.05 m) covers the
    embankment's body, so cutting alone makes it; the subtask's passes, carried out as level sweeps by an ideal
    machine, end with the planner's own stop well inside the seed's max_passes and a few centimetres of MAE (what
    level radial drags leave on the faces; the plant run's figures: tms_rp/excavation/README.md)."""
    from sim_bridge.config import load_plant
    from sim_bridge.soil import HeightField

    data, _ = load_yaml(EMBANKMENT_SEED)
    job = next(p for p in data["parameters"] if p["record_name"] == "design_embankment_job")
    doc = next(d for d in data["designs"] if d["name"] == job["design"])
    design = Design.from_dict(doc)
    assert design.kind == "embankment" and job["base_z"] == 0.0
    field = HeightField(load_plant(ROOT / "config" / "sim" / "design_embankment_plant.yaml").soil)
    f = field.fine
    grid = Grid(z=np.flipud(f.h).copy(), x_min=f.x0, y_min=f.y0, x_max=f.x1, y_max=f.y1)  # row 0 = north
    sampled = design.sample(grid)
    assert np.all(grid.z[sampled.inside] >= sampled.target[sampled.inside] - 1e-9)  # nothing to fill
    assert design.contains(np.array([job["dump_x"]]), np.array([job["dump_y"]])).sum() == 0
    run = DesignExcavation(build_excavate_design(job, "design_embankment_job"), MACHINE)
    start = None
    while True:
        step = run.step(doc, grid)
        if isinstance(step, Done):
            break
        start = start or step.error
        _drag(grid, step.cut, run.planner.bucket_width)  # the excavate goal on an ideal machine
    assert not step.ok and "nothing reachable worth a pass" in step.message, step.message
    print(f"\nembankment seed, ideal level sweeps: {run.summary()}; start MAE {start.mae * 100:.1f} cm; {step.message}")
    assert run.passes < job["max_passes"]
    assert start.mae > 0.1 and step.error.mae < 0.06 and step.error.fill_volume == 0.0


def test_the_embankment_tree_runs_the_row_on_its_seed_record() -> None:
    xml = (ROOT / "trees" / "design_embankment.xml").read_text()
    assert f'subtask_name="{ROW.name}"' in xml and 'record_name="design_embankment_job"' in xml
    data, _ = load_yaml(EMBANKMENT_SEED)
    assert [t["file"] for t in data["tasks"]] == ["trees/design_embankment.xml"]
