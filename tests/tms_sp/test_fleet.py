"""The fleet experiment's trees (one per kind, the machine a task parameter) and seed, run together on the real BT
runtime (tms_ts) and embedded DB (tms_db) with the real sensing processor following the carrier that holds the
loading point. Leaves complete against a small simulated site of three carriers. Checks: every task SUCCESS, each
carrier loaded and dumped, never two carriers in the loading area, every release over the holder's vessel, and
the fleet points of the seed are config/site.yaml's."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import yaml

import tms_db
import tms_ts.loader as tms_ts_loader
from tests.tms_sp.treeutil import ROOT
from tms_db.cli import seed
from tms_model.geometry import Pose2D, yaw_from_quaternion
from tms_sp import synthetic as syn
from tms_sp.config import carrier_vessel_geometry, load_sensing_config
from tms_sp.processor import SiteSensing
from tms_ts.bt.core import TreeContext

BB = "GLOBAL_BLACKBOARD_FLEET"
SEED = yaml.safe_load((ROOT / "config" / "seeds" / "fleet.yaml").read_text())
SITE = yaml.safe_load((ROOT / "config" / "site.yaml").read_text())["points"]
CARRIERS = ("ic120_1", "ic120_2", "mst110cr_2")


def _last_pose(doc: dict) -> Pose2D:
    last = (lambda k: doc[k][-1]) if isinstance(doc["x"], list) else (lambda k: doc[k])
    return Pose2D(last("x"), last("y"), yaw_from_quaternion((last("qx"), last("qy"), last("qz"), last("qw"))))


class Goal:
    def __init__(self, model: str, subtask: str, record: str) -> None:
        self.model, self.subtask, self.record = model, subtask, record
        self.state, self.error_code, self.message, self.feedback = "accepted", 0, "", ""
        self.ticks_left = 2

    def cancel(self) -> None:
        self.state = "canceled"


class FleetWorld:
    def __init__(self, store, cfg, geoms) -> None:
        self.store, self.cfg, self.geoms = store, cfg, geoms
        self.spec = cfg.mound_grid
        xg, yg = self.spec.centres()
        m = cfg.mound
        self.surface = syn.truncated_cone(m.cx, m.cy, m.base_radius, m.top_radius, 0.6, m.ground_z)(xg, yg)
        self.pose = {
            c: Pose2D(SITE[f"wait_{c}"]["x"], SITE[f"wait_{c}"]["y"], SITE[f"wait_{c}"]["yaw"]) for c in CARRIERS
        }
        self.vessel = dict.fromkeys(CARRIERS, 0.0)
        self.dumped = dict.fromkeys(CARRIERS, 0.0)
        self.bucket = 0.0
        self.goals: list[Goal] = []
        self.inside: set[str] = set()
        self.max_inside = 0
        self.releases: list[str] = []

    def subtask_server_ready(self, model_name: str, subtask_name: str) -> bool:
        return True

    def send_subtask_goal(self, model_name: str, subtask_name: str, record_name: str) -> Goal:
        if record_name == "ENTER_PATH":
            self.inside.add(model_name)
            self.max_inside = max(self.max_inside, len(self.inside))
        goal = Goal(model_name, subtask_name, record_name)
        self.goals.append(goal)
        return goal

    def emergency_stop(self, model_name: str, reason: str) -> None:
        raise AssertionError(reason)

    def confirm_seq(self) -> int:
        return 0

    def confirmations(self, since: int) -> list:
        return []

    def step(self) -> None:
        for goal in list(self.goals):
            goal.ticks_left -= 1
            if goal.ticks_left <= 0:
                self._complete(goal)
                goal.state = "succeeded"
                self.goals.remove(goal)

    def _complete(self, goal: Goal) -> None:
        doc = self.store.get_parameter(goal.model, goal.record)
        if goal.model in CARRIERS:
            if "release_soil" in goal.subtask:
                if doc["target_angle"] > 0.5:
                    self.dumped[goal.model] += self.vessel[goal.model]
                    self.vessel[goal.model] = 0.0
            else:
                self.pose[goal.model] = _last_pose(doc)
                if goal.record == "LEAVE_PATH":
                    self.inside.discard(goal.model)
        elif goal.subtask == "subtask_zx200_excavate_simple":
            tx, ty, tz = self.cfg.excavator_base.to_map(np.array([doc["x"], doc["y"], doc["z"]]))
            xg, yg = self.spec.centres()
            disk = np.hypot(xg - tx, yg - ty) <= 0.8
            lowered = np.where(disk, np.minimum(self.surface, max(tz, self.cfg.mound.ground_z)), self.surface)
            self.bucket += float((self.surface - lowered).sum() * self.spec.cell_area)
            self.surface = lowered
        elif goal.subtask == "subtask_zx200_release_simple":
            pose = self.store.get_parameter("zx200", self.cfg.release_record)
            radius, ang = math.hypot(pose["x"], pose["y"]), doc["target_angle"]
            point = np.array([radius * math.cos(ang), radius * math.sin(ang), 0.0])
            into = None
            for c in CARRIERS:
                g = self.geoms[c]
                centre = self.pose[c].to_map(g.origin_in_base())
                local = Pose2D(centre[0], centre[1], self.pose[c].yaw).from_map(point)
                if abs(local[0]) < g.inner_length / 2 and abs(local[1]) < g.inner_width / 2:
                    into = c
            holder = self.store.get_record(BB)["LOADAREA_MACHINE"]
            assert into == holder, f"released over {into}, the loading point is held by {holder}"
            self.releases.append(into)
            self.vessel[into] += self.bucket
            self.bucket = 0.0

    def mound_scan(self, rng) -> np.ndarray:
        xg, yg = self.spec.centres()
        pts = np.column_stack([xg.ravel(), yg.ravel(), self.surface.ravel()])
        pts[:, 2] += rng.normal(0, 0.02, len(pts))
        return pts

    def vessel_scan(self, carrier: str, rng) -> np.ndarray:
        g = self.geoms[carrier]
        spec = g.grid_spec(self.cfg.resolution)
        v = self.vessel[carrier]
        heap = syn.vessel_heap(v, g.inner_length, g.inner_width, spread=1.2) if v > 0 else (lambda x, y: 0 * x)
        return syn.scan(heap, (spec.x_min, spec.x_max), (spec.y_min, spec.y_max), 3000, rng, noise=0.01, outliers=0.0)


def test_fleet_seed_points_are_the_sites_and_every_task_names_its_machine():
    tasks = {t["task_id"]: t for t in SEED["tasks"]}
    assert {t["blackboard"]["machine"] for t in tasks.values()} == {"zx200", *CARRIERS}
    params = {(d.get("model_name"), d["record_name"]): d for d in SEED["parameters"]}
    for c in CARRIERS:
        enter, ret = params[(c, "ENTER_PATH")], params[(c, "RETURN_PATH")]
        assert (enter["x"][-1], enter["y"][-1]) == (SITE["P1"]["x"], SITE["P1"]["y"])
        assert (enter["x"][0], enter["y"][0]) == (SITE["P2"]["x"], SITE["P2"]["y"])
        assert (ret["x"][-1], ret["y"][-1]) == (SITE[f"wait_{c}"]["x"], SITE[f"wait_{c}"]["y"])
        assert (ret["x"][-2], ret["y"][-2]) == (SITE[f"turn_{c}"]["x"], SITE[f"turn_{c}"]["y"])
        dump = params[(c, "DUMP_PATH")]
        assert (dump["x"][-1], dump["y"][-1]) == (SITE["fleet_dump"]["x"], SITE["fleet_dump"]["y"])
    spots = [(SITE[f"wait_{c}"]["x"], SITE[f"wait_{c}"]["y"]) for c in CARRIERS]
    assert min(math.dist(a, b) for i, a in enumerate(spots) for b in spots[i + 1:]) > 7.1


def test_fleet_trees_load_each_carrier_in_turn_and_sensing_follows_the_holder(tmp_path):
    cfg = load_sensing_config()
    cfg = dataclasses.replace(cfg, blackboard_records=(BB,), arrival=dataclasses.replace(cfg.arrival, hold_s=1.0))
    store = tms_db.open_store(path=tmp_path / "db")
    seed(store, ROOT / "config" / "seeds" / "fleet.yaml")
    geoms = {c: carrier_vessel_geometry(cfg, c) for c in CARRIERS}
    assert geoms["mst110cr_2"].capacity != geoms["ic120_1"].capacity  # its kind's vessel
    world = FleetWorld(store, cfg, geoms)
    sensing = SiteSensing(cfg, store, carrier=CARRIERS[0], vessels=geoms)
    sensing.check_records()
    t = 0.0
    clock = lambda: t  # noqa: E731
    trees = {}
    for task in store.list_tasks():
        ctx = TreeContext(store=store, ros=world, clock=clock)
        trees[task["blackboard"]["machine"]] = tms_ts_loader.load_tree(
            task["task_sequence"], ctx, source=f"task {task['task_id']}", blackboard=task["blackboard"])
    rng = np.random.default_rng(0)
    status: dict[str, str] = {}
    sensed: list[str] = []
    for _ in range(6000):
        t += 0.5
        world.step()
        carrier = sensing.follow_holder("LOADAREA_MACHINE", set(CARRIERS))
        if not sensed or sensed[-1] != carrier:
            sensed.append(carrier)
        sensing.on_carrier_pose(t, world.pose[carrier])
        sensing.on_mound_points(world.mound_scan(rng))
        sensing.on_vessel_points(world.vessel_scan(carrier, rng))
        for name, tree in trees.items():
            if status.get(name) in (None, "RUNNING"):
                status[name] = tree.tick().name
        if sum(1 for v in world.dumped.values() if v > 0) == len(CARRIERS):
            store.set_fields(BB, {"CONTINUE_FLG": False})
        if all(s in ("SUCCESS", "FAILURE") for s in status.values()):
            break
    assert set(status.values()) == {"SUCCESS"}, status
    assert all(world.dumped[c] > 0.5 for c in CARRIERS), world.dumped
    assert world.max_inside == 1
    assert sensed[:3] == list(CARRIERS), sensed
    assert world.releases[0] == "ic120_1" and set(world.releases) == set(CARRIERS)
