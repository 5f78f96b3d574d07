"""The design run's execution measure (tests/bench/bench_design_trench.py pass_execution): a pass planned on one
heightmap matched with the heightmaps after it, and how far above the planned edge height its band ended."""

from __future__ import annotations

import numpy as np
import pytest

from tests.bench.bench_design_trench import SEED, _job, _legs, pass_execution
from tms_common.config import load_yaml, repo_root
from tms_model.fleet import load_named
from tms_rp.excavation.design import Design, Grid
from tms_rp.excavation.planner import BasePose
from tms_ts.design_excavation import DesignExcavation
from tms_ts.subtask_specs import build_excavate_design


def test_a_pass_left_10_cm_high_reads_10_cm_above_plan(tmp_path):
    seed = repo_root() / "config" / "seeds" / f"{SEED}.yaml"
    job = _job(seed)
    design = Design.from_dict(next(d for d in load_yaml(seed)[0]["designs"] if d["name"] == job["design"]))
    a = Grid(z=np.zeros((320, 120)), x_min=-8.0, y_min=-8.0, x_max=-2.0, y_max=8.0)
    base = BasePose(-0.08, -4.47, -0.034, 0.0)  # the first base pose of the seed's tree, as a run measured it
    assert job["base_measured"]
    run = DesignExcavation(build_excavate_design(job, "r"), load_named(str(job["model_name"])), base=base)
    cut = run.planner.next_pass(a, design, run.base).cut
    b = Grid(z=a.z.copy(), x_min=a.x_min, y_min=a.y_min, x_max=a.x_max, y_max=a.y_max)
    b.z[cut.cells[:, 0], cut.cells[:, 1]] = cut.cut_to + 0.1
    ex = pass_execution(job, design, [a, b, b], base)
    assert ex["passes_matched"] == 1
    assert ex["above_planned_cm"]["mean"] == pytest.approx(10.0, abs=1e-6)
    assert ex["achieved_m3"] == pytest.approx(cut.volume - 0.1 * len(cut.cells) * 0.05**2, rel=1e-3)
    assert pass_execution(job, design, [a, a, a], base) == {"passes_matched": 0}


def test_the_legs_passes_and_measured_bases_are_read_from_the_launch_output(tmp_path):
    log = tmp_path / "launch.log"
    log.write_text(
        "[site_server] [INFO] [1.0] [subtasks_zx200]: design 'd': record 'south': measured base pose x -0.081 y "
        "-4.467 yaw -0.0340 (z 0 from the record)\n"
        "[site_server] [INFO] [2.0] [subtasks_zx200]: /zx200/subtask_zx200_excavate_design 'south' succeeded: design "
        "'d': the part reachable from the base at (-0.08, -4.47, yaw -0.034) done after 31 pass(es), 4.100 m3 "
        "planned moved (...)\n"
        "[site_server] [INFO] [3.0] [subtasks_zx200]: /zx200/subtask_zx200_excavate_design 'north' succeeded: design "
        "'d': the part reachable from the base at (0.01, 4.52, yaw 0.010) done after 7 pass(es), 0.500 m3 planned "
        "moved (...)\n")
    passes, volume, bases = _legs(log)
    assert (passes, volume) == (38, pytest.approx(4.6))
    assert bases == {"south": BasePose(-0.081, -4.467, -0.034)}
    assert _legs(tmp_path / "none.log") == (None, None, {})
