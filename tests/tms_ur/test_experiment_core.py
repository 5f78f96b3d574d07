"""The experiment recorder: events, metrics and report files from a scripted run."""

import json
from pathlib import Path

import numpy as np
import pytest

from tms_db.store import build_task_doc
from tms_model.excavator.kinematics import load_kinematics
from tms_model.fleet import load_named
from tms_model.site import load_site
from tms_ur.experiment_core import ExperimentRecorder, tree_actions
from tms_ur.site_map import render_site_map

ROOT = Path(__file__).resolve().parents[2]


def _scripted_run() -> ExperimentRecorder:
    rec = ExperimentRecorder()
    rec.wall_start, rec.wall_end = 0.0, 20.0
    t, mound, vessel, dumped = 0.0, 20.0, 0.0, 0.0
    rec.on_soil(t, mound, 0.0, vessel, dumped)
    for cycle in range(3):
        for _ in range(4):  # four passes of 0.7 m^3, 18 s apart
            t += 18.0
            mound -= 0.7
            vessel += 0.7
            rec.on_soil(t, mound, 0.0, vessel, dumped)
            rec.on_flags(t, {"SENSING_LOADED_FLG": vessel > 2.5})
        t += 60.0
        dumped += vessel
        vessel = 0.0
        rec.on_soil(t, mound, 0.0, vessel, dumped)
        rec.on_truth_pose(t, "ic120", 38.0, 10.0 + cycle, 3.14)
        rec.on_estimated_pose(t, "ic120", 38.03, 10.04 + cycle)
    return rec


def test_cycles_passes_and_times():
    rec = _scripted_run()
    m = rec.metrics()
    assert m["cycles"] == 3
    assert m["load_passes"] == 12
    assert m["soil_moved_m3"] == pytest.approx(8.4)
    # The first pass of each loading phase has no predecessor in that phase: 3 x 3 pass intervals.
    assert m["load_pass_time_s"]["n"] == 9 and m["load_pass_time_s"]["median"] == pytest.approx(18.0)
    assert m["haul_cycle_time_s"]["median"] == pytest.approx(4 * 18.0 + 60.0)
    assert m["localisation_error_m"]["rms"] == pytest.approx(0.05, abs=1e-6)
    assert m["real_time_factor"] == pytest.approx(rec.sim_end / 20.0)
    assert m["flags_timeline"]["SENSING_LOADED_FLG"][1][1] is True


def test_a_bucketful_falling_over_many_samples_is_one_pass_and_a_dump_one_cycle():
    """At 20 Hz a 0.8 m^3 bucketful lands in ~30 samples and a vessel empties over ~100: one event each."""
    rec = ExperimentRecorder()
    t, vessel, dumped = 0.0, 0.0, 0.0
    rec.on_soil(t, 20.0, 0.0, vessel, dumped)
    for _ in range(3):  # three passes 25 s apart, each falling over 1.5 s
        t += 25.0
        for _ in range(30):
            t += 0.05
            vessel += 0.8 / 30
            rec.on_soil(t, 20.0, 0.0, vessel, dumped)
    t += 100.0
    for _ in range(100):  # the dump: 5 s
        t += 0.05
        vessel -= 2.4 / 100
        dumped += 2.4 / 100
        rec.on_soil(t, 20.0, 0.0, vessel, dumped)
    m = rec.metrics()
    assert m["load_passes"] == 3 and m["cycles"] == 1, (m["pass_events_s"], m["dump_events_s"])
    assert m["load_pass_time_s"]["median"] == pytest.approx(26.5, abs=0.1)


def test_report_writes_every_file(tmp_path):
    rec = _scripted_run()
    index = rec.report(tmp_path)
    for name in ("metrics.json", "site_map.png", "soil.png", "flags.png", "index.html"):
        assert (tmp_path / name).stat().st_size > 100, name
    assert json.loads((tmp_path / "metrics.json").read_text())["cycles"] == 3
    assert 'src="site_map.png"' in index.read_text()


def test_leaf_times_come_from_the_running_leaves_of_each_task():
    rec = ExperimentRecorder()
    # task 2 runs excavate 10-25 s, carry 25-31 s, then excavate again 31-40 s; task 1 drives 0-40 s
    for t, leaves in [
        (10.0, ["excavate"]),
        (20.0, ["excavate"]),
        (25.0, ["carry_over_vessel (task 2 line 1, column 3404)"]),
        (31.0, ["excavate"]),
        (40.0, []),
    ]:
        rec.on_running_leaves(t, 2, leaves)
        rec.on_running_leaves(t, 1, ["drive_to_p5"] if t < 40.0 else [])
    times = rec.metrics()["leaf_time_s"]
    assert times["2"]["excavate"]["n"] == 2 and times["2"]["excavate"]["max"] == pytest.approx(15.0)
    assert times["2"]["excavate"]["median"] == pytest.approx(12.0)
    assert times["2"]["carry_over_vessel"]["mean"] == pytest.approx(6.0)
    assert set(times) == {"1", "2"} and set(times["1"]) == {"drive_to_p5"}
    assert times["1"]["drive_to_p5"]["max"] == pytest.approx(30.0)


def test_a_failed_task_cancels_every_partner_that_still_runs():
    from tms_ur.experiment_core import tasks_to_cancel_after_failure

    assert tasks_to_cancel_after_failure([1, 2], {1: "RUNNING", 2: "RUNNING"}) == []
    assert tasks_to_cancel_after_failure([1, 2], {1: "RUNNING", 2: "FAILURE"}) == [1]
    # a partner not heard from yet is cancelled too; one that already ended is not
    assert tasks_to_cancel_after_failure([1, 2, 3], {2: "FAILURE", 3: "SUCCESS"}) == [1]
    assert tasks_to_cancel_after_failure([1, 2], {1: "CANCELED", 2: "FAILURE"}) == []


def test_errors_are_taken_at_the_estimate_stamp_not_against_the_last_truth_received():
    """A tip swinging at 6 m/s: truth every 50 ms, exact estimates every 20 ms delivered 0.1 s after the truth of
    their time. Pairing each with the last truth received reads up to 0.3 m of error that is not there."""
    from tms_ur.experiment_core import AlignedError

    def x_at(t: float) -> float:
        return 6.0 * t

    aligned: list[float] = []
    errors = AlignedError(aligned)
    naive: list[float] = []
    last_truth = None
    events = [(k * 0.05, "truth") for k in range(1, 101)] + [(k * 0.02 + 0.1, "estimate") for k in range(250)]
    for arrival, kind in sorted(events):
        if kind == "truth":
            errors.truth(arrival, x_at(arrival), 0.0)
            last_truth = x_at(arrival)
        else:
            stamp = arrival - 0.1
            errors.estimate(stamp, x_at(stamp), 0.0)
            if last_truth is not None:
                naive.append(abs(x_at(stamp) - last_truth))
    assert max(naive) > 0.25  # what the old pairing reported
    assert len(aligned) > 200 and max(aligned) < 1e-9, (len(aligned), max(aligned))
    assert errors.unmatched == 3  # stamped 0, 0.02 and 0.04 s: before the first truth sample


def test_an_estimate_whose_truth_never_comes_is_unmatched_not_compared():
    from tms_ur.experiment_core import AlignedError

    aligned: list[float] = []
    errors = AlignedError(aligned, horizon_s=1.0, max_gap_s=0.25)
    errors.truth(0.0, 0.0, 0.0)
    errors.truth(1.0, 1.0, 0.0)  # a gap of 1 s: no interpolation across it
    errors.estimate(0.5, 0.5, 0.0)
    for k in range(1, 40):  # truth stops after 1.0 s; estimates go on every 1/8 s, the last at 5.875 s
        errors.estimate(1.0 + k / 8, 0.0, 0.0)
    assert aligned == []
    # the one in the gap, and the 30 that waited more than horizon_s (stamped before 4.875 s) for their truth
    assert errors.unmatched == 1 + 30


def _route_run() -> ExperimentRecorder:
    """Synthetic truth paths: the IC120 driving P3 -> P1 -> P5 and back, the ZX200 parked."""
    rec = ExperimentRecorder()
    t = 0.0
    legs = [(22.0, 10.0), (12.0, 8.5), (1.2, 6.5), (12.0, 8.5), (22.0, 10.0), (30.0, 10.0), (38.0, 10.0)]
    for (xa, ya), (xb, yb) in zip(legs, legs[1:], strict=False):
        for s in np.linspace(0.0, 1.0, 20):
            t += 0.5
            rec.on_truth_pose(t, "ic120", xa + s * (xb - xa), ya + s * (yb - ya), 0.0)
    rec.on_truth_pose(t, "zx200", 0.0, 0.0, 0.0)
    return rec


def test_site_map_labels_do_not_overlap_and_the_plot_fills_the_figure(tmp_path):
    """The paper's two machines, as the report draws them: the excavator at its base with its reach, the carrier
    at the loading point; colours blue and orange as before the site map took a list."""
    site = load_site()
    kin = load_kinematics("zx200")
    rec = _route_run()
    machines = [load_named(name, site=site) for name in rec.paths]
    info = render_site_map(tmp_path / "site_map.png", site, machines=machines, paths=rec.paths)
    assert (tmp_path / "site_map.png").stat().st_size > 10_000
    texts = [t for t, _ in info["labels"]]
    # every pose is labelled once; poses at one position share one label; the dump zone is named
    assert sorted(" / ".join(texts).replace(" / ", "|").split("|")) == sorted([*site.points, "dump zone"])
    assert any("P3" in t and "ic120_start" in t for t in texts)
    boxes = [b for _, b in info["labels"]]
    for i, a in enumerate(boxes):
        for j in range(i + 1, len(boxes)):
            assert not a.overlaps(boxes[j]), (texts[i], texts[j])
    assert info["axes_fraction"] > 0.6, info["axes_fraction"]
    assert info["reach"] == pytest.approx(kin.envelope()["max_reach"])
    assert info["drawn"] == ["zx200", "ic120"]
    assert info["colors"] == {"zx200": "tab:blue", "ic120": "tab:orange"}
    assert {f"zx200 swing reach ({info['reach']:.1f} m)", "zx200", "ic120 at loading", "ic120 vessel"} <= set(
        info["legend"]
    )


def test_site_map_draws_any_list_of_machines_by_type(tmp_path):
    """Three carriers (two of one kind) and an excavator, and a dozer with a path: each drawn after its type."""
    site = load_site()
    names = ["ic120", "ic120_1", "mst110cr", "zx200", "d37pxi_24"]
    machines = [load_named(name, site=site) for name in names]
    paths = {"ic120_1": [(0.0, 20.0, 10.0), (1.0, 12.0, 8.5), (2.0, 1.2, 6.5)],
             "d37pxi_24": [(0.0, 30.0, 0.0), (1.0, 34.0, 0.0)]}
    info = render_site_map(tmp_path / "site_map.png", site, machines=machines, paths=paths)
    assert (tmp_path / "site_map.png").stat().st_size > 10_000
    # excavators first (their colours do not depend on how many carriers follow), then carriers, then dozers
    assert info["drawn"] == ["zx200", "ic120", "ic120_1", "mst110cr", "d37pxi_24"]
    assert list(info["colors"]) == info["drawn"] and len(set(info["colors"].values())) == 5
    assert set(info["reaches"]) == {"zx200"}
    legend = set(info["legend"])
    for carrier in ("ic120", "ic120_1 (ic120)", "mst110cr"):
        assert {f"{carrier} at loading", f"{carrier} vessel"} <= legend, legend
    assert {"d37pxi_24 (d37pxi) (last pose)", "d37pxi_24 (d37pxi) blade", "ic120_1 path", "d37pxi_24 path"} <= legend
    # an excavator with no base point on the site and no path has nowhere to be drawn
    lone = render_site_map(tmp_path / "lone.png", site, machines=[load_named("zx120", site=site)])
    assert lone["drawn"] == [] and lone["reach"] is None


def test_fleet_passes_count_every_carrier_and_localisation_is_per_carrier():
    """Carriers by name: passes are rises of the carriers' landed totals (not the one vessel of /sim/truth/soil),
    each carrier's estimate is compared with its own truth."""
    carriers = ["ic120_1", "ic120_2", "mst110cr_2"]
    rec = ExperimentRecorder(carriers=carriers)
    rec.wall_start, rec.wall_end = 0.0, 100.0
    t, dumped = 0.0, 0.0
    loaded = dict.fromkeys(carriers, 0.0)
    rec.on_soil(t, 20.0, 0.0, 0.0, dumped)
    for c in carriers:
        rec.on_carrier_soil(t, c, 0.0, 0.0, 0.0)
    for i, c in enumerate(carriers):
        for _ in range(3):  # three passes of 0.5 m^3 into this carrier, 20 s apart
            t += 20.0
            loaded[c] += 0.5
            rec.on_carrier_soil(t, c, loaded[c], loaded[c], 0.0)
            rec.on_soil(t, 20.0 - sum(loaded.values()), 0.0, 0.0, dumped)  # the plant's one vessel: ic120_1 only
        t += 60.0
        dumped += loaded[c]
        rec.on_carrier_soil(t, c, 0.0, loaded[c], loaded[c])
        rec.on_soil(t, 20.0 - sum(loaded.values()), 0.0, 0.0, dumped)
        rec.on_truth_pose(t, c, 38.0, 10.0 + i, 0.0)
        rec.on_estimated_pose(t, c, 38.0, 10.0 + i + 0.1 * (i + 1))  # 0.1, 0.2, 0.3 m off
    m = rec.metrics()
    assert m["load_passes"] == 9, m["pass_events_s"]
    assert m["load_pass_time_s"]["n"] == 6 and m["load_pass_time_s"]["median"] == pytest.approx(20.0)
    assert m["localisation_error_m"]["n"] == 3
    assert m["localisation_error_m"]["max"] == pytest.approx(0.3, abs=1e-6)
    assert m["localisation_error_m"]["unmatched"] == 0
    assert {c: f["soil_moved_m3"] for c, f in m["carriers"].items()} == dict.fromkeys(carriers, 1.5)


def test_any_machines_errors_per_machine_and_excavator_and_the_report_draws_them(tmp_path):
    """Three carriers and an excavator (names, not the paper's two): every machine's estimate is compared with its
    own truth, the excavator's tip with its own; the report's site map draws the machines recorded."""
    carriers = ["ic120", "ic120_1", "mst110cr"]
    rec = ExperimentRecorder(carriers=carriers)
    rec.wall_start, rec.wall_end = 0.0, 10.0
    rec.on_soil(0.0, 20.0, 0.0, 0.0, 0.0)
    for k in range(20):
        t = k * 0.5
        for i, c in enumerate(carriers):
            rec.on_truth_pose(t, c, 10.0 + t, 5.0 * i, 0.0)
            rec.on_estimated_pose(t, c, 10.0 + t, 5.0 * i + 0.1 * (i + 1))  # 0.1, 0.2, 0.3 m off
        rec.on_truth_pose(t, "zx200", 0.0, 0.0, 0.0)
        rec.on_truth_tip(t, 8.0, 0.0, "zx200")
        rec.on_estimated_tip(t, 8.0, 0.05, "zx200")
    m = rec.metrics()
    assert m["localisation_error_m"]["n"] == 60 and m["localisation_error_m"]["max"] == pytest.approx(0.3)
    assert m["end_effector_error_m"]["n"] == 20 and m["end_effector_error_m"]["max"] == pytest.approx(0.05)
    assert m["localisation_error_m"]["unmatched"] == 0 and m["end_effector_error_m"]["unmatched"] == 0
    assert set(m["carriers"]) == set(carriers)
    rec.report(tmp_path)
    assert (tmp_path / "site_map.png").stat().st_size > 10_000


def test_the_paper_figures_do_not_depend_on_the_machines_watched():
    """The paper's run recorded with extra machines watched (no messages from them) gives the same figures."""
    paper = _scripted_run().metrics()
    rec = _scripted_run()
    for name in ("zx120", "ic120_1", "mst110cr", "d37pxi_24"):
        rec.on_truth_pose(rec.sim_end, name, 50.0, 50.0, 0.0)  # a pose, no estimate: no error, no pass
    m = rec.metrics()
    for key in ("cycles", "load_passes", "soil_moved_m3", "load_pass_time_s", "haul_cycle_time_s",
                "localisation_error_m", "end_effector_error_m", "task_states"):
        assert m[key] == paper[key], key


def test_tree_actions_are_the_leaves_subtasks_and_their_planning_actions():
    """The paper's trees call the action servers the supervisor used to list by hand; a fleet tree's {machine}
    comes from the task's blackboard."""
    paper = []
    for tree in ("trees/paper_ic120_haul.xml", "trees/paper_zx200_load.xml"):
        doc = build_task_doc((ROOT / tree).read_text(), 1, "", None)
        paper += tree_actions(doc["task_sequence"], doc.get("blackboard"))
    assert sorted(paper) == sorted([
        "/zx200/tms_rp_zx200_change_pose", "/zx200/tms_rp_zx200_excavate_simple", "/zx200/tms_rp_zx200_release_simple",
        "/ic120/follow_waypoints", "/ic120/navigate_to_pose", "/ic120/set_dump_angle",
        "/zx200/subtask_zx200_change_pose", "/zx200/subtask_zx200_excavate_simple",
        "/zx200/subtask_zx200_release_simple", "/ic120/st_ic120_follow_waypoints",
        "/ic120/st_ic120_navigate_anywhere", "/ic120/st_ic120_release_soil"])
    doc = build_task_doc((ROOT / "trees/fleet_mst110cr_haul.xml").read_text(), 14, "", None, {"machine": "mst110cr_2"})
    fleet = tree_actions(doc["task_sequence"], doc["blackboard"])
    assert "/mst110cr_2/st_mst110cr_follow_waypoints" in fleet and "/mst110cr_2/follow_waypoints" in fleet
    assert all(a.startswith("/mst110cr_2/") for a in fleet), fleet
    # a {key} the blackboard does not give is left out, not waited for under its literal name
    assert tree_actions(doc["task_sequence"], {}) == []
