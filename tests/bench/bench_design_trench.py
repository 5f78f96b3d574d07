"""Excavation to a design surface on the MuJoCo plant over CAN: the trench of task 35, the embankment of task 36
(issue 35).

``python -m tests.bench design_trench`` runs ``SCENARIO=design scripts/demo.sh`` (``SCENARIO=embankment`` in the
environment: the embankment) (config/launch/design_trench.yaml:
plant, the ZX200's converter, arm controller and planner, dynamic terrain, subtask server, manager, supervisor; a
full run of ~30 passes, 10-20 min of wall time on 2 cores), which ends by calling this module with ``--report``.

``python -m tests.bench.bench_design_trench --report RUN_DIR [--db PATH] [--seed NAME]`` judges a finished run: the
design and the record of the seed (``config/seeds/design_trench.yaml``, or ``design_embankment`` for
``SCENARIO=embankment``; the parameter that names a ``design``) from the run's
store (``TMS_DB_PATH`` or ``--db``), the plant's true height field (``RUN_DIR/heights.npz``) and the newest sensed
dynamic heightmap against the design (:mod:`tms_rp.excavation.evaluation`), the task's end and times from the
supervisor's ``metrics.json``. Writes ``RUN_DIR/design.json`` and ``RUN_DIR/design_error.png`` (linked from the
report's ``index.html``) and prints the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from tms_common.config import load_yaml, repo_root
from tms_db import get_design, open_store
from tms_model.fleet import load_named
from tms_rp.excavation.design import Design, cell_centres
from tms_rp.excavation.evaluation import excavated_volume, figures, plot_errors, truth_grid
from tms_rp.excavation.planner import BasePose
from tms_sp.terrain import DYNAMIC_ID, heightmap_from_blob, latest_heightmap
from tms_ts.design_excavation import DesignExcavation
from tms_ts.subtask_specs import build_excavate_design

SEED = "design_trench"
PASSES = re.compile(r"(\d+) pass\(es\), ([0-9.]+) m3 planned moved")


BASE = re.compile(r"record '([^']+)': measured base pose x (\S+) y (\S+) yaw (\S+)")


def _legs(log: Path) -> tuple[int | None, float | None, dict[str, BasePose]]:
    """From the launch's output: the passes and planned volume summed over the design subtask's goals (one per base
    pose of the tree), and the base pose each measured, by record; (None, None, {}) without the output."""
    passes, volume, bases = None, None, {}
    if log.is_file():
        for line in log.read_text(errors="replace").splitlines():
            if "_excavate_design '" in line and (found := PASSES.search(line)):
                passes = (passes or 0) + int(found.group(1))
                volume = (volume or 0.0) + float(found.group(2))
            elif found := BASE.search(line):
                bases[found.group(1)] = BasePose(float(found.group(2)), float(found.group(3)), float(found.group(4)))
    return passes, volume, bases


def _job(seed: Path) -> dict:
    """The seed's first design record (the first parameter naming a ``design``)."""
    data, _ = load_yaml(seed)
    for doc in data.get("parameters", []):
        if "design" in doc:
            return doc
    raise SystemExit(f"{seed}: no parameter names a design")


def _task_end(metrics: dict, log: Path) -> tuple[str, str]:
    """(state, message) of the run's one task: the state from the supervisor's metrics, the message from its last
    line about the task in the launch's output (``launch.log``, which demo.sh writes), if there is one."""
    states = metrics.get("task_end_states") or {}
    state = str(next(iter(states.values()), "")) if isinstance(states, dict) else ""
    message = ""
    if log.is_file():
        for line in log.read_text(errors="replace").splitlines():
            if "[experiment] task " in line and ("pass(es)" in line or state in line):
                message = line.split("[experiment] ", 1)[1].strip()
    return state, message


def pass_execution(job: dict, design: Design, maps: list, base: BasePose | None = None) -> dict[str, Any]:
    """How the machine carried out its passes, from the sensed heightmaps in time order: each pass the subtask's
    planner (the record's settings) plans on one map, matched with the first later map where the cells it lowers
    by more than 3 cm dropped 3 cm on average, then one map later (the pass over); their heights against the
    planned edge height (+ = left above): mean, 10th / 90th percentile, and the mean by place along the drag
    (0 = the far end where the edge enters, 1 = the near end) and across it [m]. The subtask planned on maps of
    its own moments, so a matched pass is the pass planned there, not necessarily the one the machine ran. A record
    with ``base_measured`` needs the ``base`` the subtask measured; the maps are then matched from that base alone
    (the first base pose's passes of a tree of several)."""
    plan = build_excavate_design(job, str(job.get("record_name", "")))
    run = DesignExcavation(plan, load_named(str(job["model_name"])),
                           base=BasePose(base.x, base.y, base.yaw, float(plan.base.get("z", 0.0))) if base else None)
    planner = run.planner
    devs: list[np.ndarray] = []
    along: dict[float, list] = {}
    across: dict[float, list] = {}
    planned = achieved = 0.0
    i = 0
    while i < len(maps) - 2:
        a = maps[i]
        cut = planner.next_pass(a, design, run.base).cut
        if cut is None:
            break
        r, c = cut.cells[:, 0], cut.cells[:, 1]
        before = a.z[r, c]
        act = before > cut.cut_to + 0.03
        j = i + 1
        while j < len(maps) and (before - maps[j].z[r, c])[act].mean() < 0.03:
            j += 1
        if j + 1 >= len(maps) or not act.any():
            break
        after = maps[j + 1].z[r, c]
        dev = (after - cut.cut_to)[act]
        devs.append(dev)
        area = (a.x_max - a.x_min) / a.z.shape[1] * (a.y_max - a.y_min) / a.z.shape[0]
        planned += cut.volume
        achieved += float(np.sum((before - after)[act])) * area
        xc, yc = cell_centres(a)
        u = np.array(cut.direction)
        dx, dy = xc[r, c][act] - cut.start[0], yc[r, c][act] - cut.start[1]
        for f, o, e in zip((dx * u[0] + dy * u[1]) / max(cut.length, 1e-9), -dx * u[1] + dy * u[0], dev, strict=True):
            along.setdefault(round(f * 4) / 4, []).append(e)
            across.setdefault(round(o * 4) / 4, []).append(e)
        i = j + 1
    if not devs:
        return {"passes_matched": 0}
    d = np.concatenate(devs)
    return {"passes_matched": len(devs), "planned_m3": planned, "achieved_m3": achieved,
            "above_planned_cm": {"mean": float(d.mean()) * 100, "p10": float(np.percentile(d, 10)) * 100,
                                 "p90": float(np.percentile(d, 90)) * 100},
            "by_along_cm": {f"{k:g}": float(np.mean(v)) * 100 for k, v in sorted(along.items())},
            "by_across_m_cm": {f"{k:g}": float(np.mean(v)) * 100 for k, v in sorted(across.items())}}


def _dynamic_maps(store: Any, ident: int) -> list:
    """Every stored dynamic heightmap of ``ident``, oldest first (the launch keeps them all)."""
    docs = sorted(store.find_blobs({"type": "dynamic", "id": ident}), key=lambda doc: str(doc.get("time", "")))
    return [heightmap_from_blob(store.get_blob(doc["_id"]), doc, source=str(doc.get("time"))) for doc in docs
            if "offset_z" in doc]


def _area_volume(grid: Any, design: Design, *, target: bool = False) -> float:
    """[m^3] above z = 0 over the design's area on ``grid``: its surface, or the design's (``target``)."""
    sample = design.sample(grid)
    z = sample.target if target else np.asarray(grid.z, float)
    return float(np.sum(z[sample.inside]) * sample.cell_area)


def report(run_dir: Path, db: str | None, seed: str = SEED) -> dict[str, Any]:
    root = repo_root()
    job = _job(root / "config" / "seeds" / f"{seed}.yaml")
    store = open_store(path=db or os.environ.get("TMS_DB_PATH"))
    design = Design.from_dict(get_design(store, str(job["design"])))
    ground = float(job.get("base_z", 0.0))
    doc, blob = latest_heightmap(store, "dynamic", ident=int(job.get("terrain_id", DYNAMIC_ID)))
    sensed = heightmap_from_blob(blob, doc, source="newest dynamic heightmap")
    truth = truth_grid(run_dir / "heights.npz", design)
    metrics_path = run_dir / "metrics.json"
    metrics = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
    state, message = _task_end(metrics, run_dir / "launch.log")
    passes, volume, bases = _legs(run_dir / "launch.log")
    found = PASSES.search(message)
    if passes is None and found:
        passes, volume = int(found.group(1)), float(found.group(2))
    out: dict[str, Any] = {
        "design": design.name,
        "task_state": state,
        "task_message": message,
        "passes": passes,
        "planned_volume_m3": volume,
        "measured_bases": {k: [b.x, b.y, b.yaw] for k, b in bases.items()},
        "truth": figures(design, truth),
        "sensed": figures(design, sensed),
        "sensed_time": doc.get("time"),
        "excavated_from_area_m3_truth": excavated_volume(truth, design, ground),
        "design_volume_m3": excavated_volume(truth.__class__(z=design.sample(truth).target, x_min=truth.x_min,
                                                             y_min=truth.y_min, x_max=truth.x_max,
                                                             y_max=truth.y_max), design, ground),
    }
    maps = _dynamic_maps(store, int(job.get("terrain_id", DYNAMIC_ID)))
    if maps:
        # net volumes over the area against the first sensed heightmap (the ground before the first pass): what the
        # run took out of it and what the design asks to take out (a pile's design too, where the area was not flat)
        first = maps[0]
        out["removed_from_area_m3"] = _area_volume(first, design) - _area_volume(truth, design)
        out["design_removal_m3"] = _area_volume(first, design) - _area_volume(first, design, target=True)
    if job.get("base_measured") and job["record_name"] not in bases:
        out["execution"] = {"passes_matched": 0, "why": f"no measured base of {job['record_name']} in launch.log"}
    else:
        out["execution"] = pass_execution(job, design, maps, bases.get(job["record_name"]))
    for key in ("sim_time_s", "wall_time_s", "real_time_factor", "ended"):
        if key in metrics:
            out[key] = metrics[key]
    (run_dir / "design.json").write_text(json.dumps(out, indent=2, default=float) + "\n")
    png = plot_errors(design, {"plant truth (0.05 m patch)": truth, "sensed (newest dynamic heightmap)": sensed},
                      run_dir / "design_error.png",
                      title=f"{design.name}: {out['passes']} passes, task {state or '?'}")
    index = run_dir / "index.html"
    if index.is_file():
        html = index.read_text()
        link = f'<h2>Design surface</h2><p><a href="design.json">design.json</a></p><img src="{png.name}">'
        if png.name not in html:
            index.write_text(html.replace("</body>", link + "</body>") if "</body>" in html else html + link)
    for label in ("truth", "sensed"):
        f = out[label]
        print(f"{label:6s}: MAE {f['mae_cm']:.2f} cm, p95 {f['p95_cm']:.2f} cm, max {f['max_cm']:.2f} cm, signed mean "
              f"{f['signed_mean_cm']:+.2f} cm, {f['cut_remaining_m3']:.3f} m3 above, {f['fill_remaining_m3']:.3f} m3 "
              f"below ({f['cells']} cells of {f['cell_m']:.2f} m)")
    ex = out["execution"]
    if ex["passes_matched"]:
        print(f"execution: {ex['passes_matched']} passes matched, {ex['achieved_m3']:.2f} of {ex['planned_m3']:.2f} m3 "
              f"planned, the band {ex['above_planned_cm']['mean']:+.1f} cm above the planned edge height (p10 "
              f"{ex['above_planned_cm']['p10']:+.1f}, p90 {ex['above_planned_cm']['p90']:+.1f}); by place along the "
              f"drag {ex['by_along_cm']}; across [m] {ex['by_across_m_cm']}")
    if "removed_from_area_m3" in out:
        print(f"net out of the area since the first heightmap: {out['removed_from_area_m3']:.3f} m3 of the design's "
              f"{out['design_removal_m3']:.3f} m3")
    below = (f", dug below the ground out of the area (truth) {out['excavated_from_area_m3_truth']:.3f} m3 of the "
             f"design's {out['design_volume_m3']:.3f} m3" if out["design_volume_m3"] > 0 else "")
    print(f"passes {out['passes']}, planned {out['planned_volume_m3']} m3{below}; task {state}; "
          f"{run_dir / 'design.json'}, {png}")
    return out


def main() -> None:
    """The full run (demo.sh, which then writes the report through ``--report``)."""
    root = repo_root()
    run_dir = root / "runs" / f"bench-design-{time.strftime('%Y%m%d-%H%M%S')}"
    scenario = os.environ.get("SCENARIO", "design")  # or embankment (task 36)
    if scenario not in ("design", "embankment"):
        raise SystemExit(f"SCENARIO={scenario}: this bench runs design or embankment")
    env = dict(os.environ, SCENARIO=scenario, RECORD="0", RUN_DIR=str(run_dir))
    start = time.monotonic()
    rc = subprocess.run([str(root / "scripts" / "demo.sh")], cwd=root, env=env, check=False).returncode
    print(f"design run: exit {rc} after {time.monotonic() - start:.0f} s wall; {run_dir}")
    if not (run_dir / "design.json").is_file():
        raise RuntimeError(f"no design figures in {run_dir} (demo.sh exit {rc})")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--report", metavar="RUN_DIR", type=Path, help="judge a finished run")
    parser.add_argument("--db", help="the run's embedded store (default TMS_DB_PATH)")
    parser.add_argument("--seed", default=SEED, help=f"the run's seed under config/seeds (default {SEED})")
    args = parser.parse_args()
    if args.report is None:
        main()
    else:
        report(args.report, args.db, args.seed)
    sys.exit(0)
