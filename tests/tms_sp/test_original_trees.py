"""The original system's own trees of the seed paper's experiment, unchanged, on our runtime (tms_ts), DB
(tms_db) and sensing (SiteSensing) with the records of config/seeds/original_202412.yaml, in the small
simulated world of test_protocol (leaves complete against it; no plant).

The trees are the original's files (irvs/ros2_tms_for_construction,
tms_ts/tms_ts_manager/config/demo_202412/new2_task_zx200_act_and_sim.xml and new_task_ic120_sim.xml); the
project does not carry copies of them. Point TMS_ORIGINAL_TREES at that folder of a checkout to run this.

What the original does with them, and so what this checks: the ZX200 tree re-sends ``initial_pose`` every
turn of its loop while it waits; it digs and loads while ARRIVAL_FLG, SENSING_ARRIVAL_FLG and neither
SENSING_LOADED_FLG nor SENSING_CHECK_MOUND_FLG; it allows the dump to move (MOVING_FLG) once sensing says the
vessel is loaded. The IC120 sim tree has no dump leaf: it drives to P5 and back with its load. The work ends
when CONTINUE_FLG is cleared (here by the operator, as nothing else clears it while the mound has soil);
both trees then write TERMINATE_FLG with SetBlackboard as the text "true", which the original's
KeepRunningUntilFlgup refuses (BehaviorTree.CPP 3.8: SetBlackboard stores the string, Any::type() is
std::string; the node throws "Unsupported type for key [TERMINATE_FLG]" and the original's manager ends the
task "canceled"). Both tasks end that way here too, naming the flag.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

import tms_db
import tms_ts.loader as tms_ts_loader
from tests.tms_sp.test_protocol import DT, World, step_and_sense
from tests.tms_sp.treeutil import ROOT
from tms_db.cli import seed
from tms_sp.config import load_sensing_config
from tms_sp.processor import SiteSensing
from tms_ts.bt.core import TreeContext

BB = "SAMPLE_BLACKBOARD_SHIMIZU"
FOLDER = os.environ.get("TMS_ORIGINAL_TREES", "")
FILES = {"ic120": "new_task_ic120_sim.xml", "zx200": "new2_task_zx200_act_and_sim.xml"}

pytestmark = pytest.mark.skipif(
    not FOLDER or not all((Path(FOLDER) / f).is_file() for f in FILES.values()),
    reason="needs the original's 2024-12 task files: set TMS_ORIGINAL_TREES to "
           "<ros2_tms_for_construction>/tms_ts/tms_ts_manager/config/demo_202412",
)


def test_the_originals_2024_12_trees_load_dig_haul_and_end_as_the_original_ends_them(tmp_path):
    cfg = load_sensing_config()
    cfg = dataclasses.replace(cfg, blackboard_records=(BB,), approach_record="",
                              arrival=dataclasses.replace(cfg.arrival, hold_s=1.0))
    store = tms_db.open_store(path=tmp_path / "db")
    seed(store, ROOT / "config" / "seeds" / "paper.yaml")  # the site's other records
    seed(store, ROOT / "config" / "seeds" / "original_202412.yaml")
    world = World(store, cfg)
    sensing = SiteSensing(cfg, store)
    sensing.check_records()
    t = 0.0
    trees = {name: tms_ts_loader.load_tree((Path(FOLDER) / f).read_text(),
                                           TreeContext(store=store, ros=world, clock=lambda: t), source=f)
             for name, f in FILES.items()}
    rng = np.random.default_rng(0)
    outcome: dict[str, str] = {}
    round_trips, stop_after = 0, 3
    for _ in range(3000):
        t += DT
        step_and_sense(world, sensing, t, rng)
        for name, tree in trees.items():
            if name not in outcome:
                try:
                    status = tree.tick().name
                except Exception as exc:  # noqa: BLE001 - the outcome under test
                    outcome[name] = f"{type(exc).__name__}: {exc}"
                    continue
                if status != "RUNNING":
                    outcome[name] = status
        round_trips = world.log.count("ic120:SIM_LOAD_PATH")
        if round_trips >= stop_after and store.get_record(BB)["CONTINUE_FLG"]:
            store.set_fields(BB, {"CONTINUE_FLG": False})  # the operator ends the work
        if len(outcome) == 2:
            break
    assert set(outcome) == {"ic120", "zx200"}, (outcome, world.log[-10:])
    for name, text in outcome.items():
        assert "TERMINATE_FLG" in text and "KeepRunningUntilFlgup" in text, (name, text)
    # The work happened: the ZX200 dug and loaded the vessel with the original's pass, then left the IC120
    # to shuttle (its sim tree does not dump; sensing kept SENSING_LOADED_FLG true after the tree reset it).
    passes = world.log.count("zx200:target_excavate_pose")
    pass_leaves = ["zx200:target_excavate_pose", "zx200:hold_soil_while_elevating_pose",
                   "zx200:hold_soil_while_turning_pose", "zx200:target_release_pose", "zx200:release_angle",
                   "zx200:after_release_soil_pose"]
    first = world.log.index(pass_leaves[0])
    assert world.log[first:first + len(pass_leaves)] == pass_leaves
    assert passes >= 3 and world.vessel > 0.75 * cfg.vessel_geom.capacity * cfg.vessel.target_fill, (
        passes,
        world.vessel,
    )
    assert round_trips >= stop_after and world.dumped == 0.0
    # initial_pose was sent again and again while the ZX200 waited (each one a goal to the pose it held)
    assert world.log.count("zx200:initial_pose") > 3 * round_trips
