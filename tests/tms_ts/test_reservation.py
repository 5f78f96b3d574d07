"""The loading-point reservation of the fleet trees (trees/README.md, "Reservation").

Every task of the manager is ticked from one thread, one task after the other, and the global-blackboard nodes
call the store synchronously: a read-check-write (BlackboardValueReaderMongo -> ConditionalExpression ->
MongoValueWriter) completing inside one tick has no other task's node in between, so two carriers that want the
loading point in the same tick never both get it. Checked on the original's bare pattern, against a variant
that spreads the claim over two ticks (which does let both in), and on the fleet carrier tree itself with the
tasks stepped as the manager steps them.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tms_ts.bt.core import TreeContext
from tms_ts.loader import load_tree
from tms_ts.task import RUNNING, SUCCEEDED, TaskRun

ROOT = Path(__file__).resolve().parents[2]
BB = "GLOBAL_BLACKBOARD_FLEET"

CLAIM = """<root main_tree_to_execute="T"><BehaviorTree ID="T">
  <Sequence>
    <Action ID="SetLocalBlackboard" output_key="GOT" value="false"/>
    <Decorator ID="KeepRunningUntilFlgup" key="GOT">
      <Sequence>
        <Action ID="BlackboardValueReaderMongo" output_port="LOADAREA" mongo_record_name="BB" \
mongo_param_name="LOADAREA"/>
        <IfThenElse>
          <Action ID="ConditionalExpression" conditional_expression="LOADAREA == false"/>
          <Sequence>
            @GAP@
            <Action ID="MongoValueWriter" input_value="true" mongo_record_name="BB" mongo_param_name="LOADAREA"/>
            <Action ID="MongoValueWriter" input_value="{machine}" mongo_record_name="BB" mongo_param_name="HOLDER"/>
            <Action ID="SetLocalBlackboard" output_key="GOT" value="true"/>
          </Sequence>
          <AlwaysSuccess/>
        </IfThenElse>
      </Sequence>
    </Decorator>
  </Sequence>
</BehaviorTree></root>"""


@pytest.fixture
def store(tmp_path):
    from tms_db import open_store

    s = open_store(path=tmp_path / "db")
    s.upsert_parameter({"record_name": "BB", "model_name": "global_blackboard", "type": "dynamic",
                        "LOADAREA": False, "HOLDER": ""})
    yield s
    s.close()


def _claimers(store, gap: str) -> list[str]:
    """Two carriers wanting the free point in the same manager tick; who claimed it (set GOT)."""
    clock = [0.0]
    runs = []
    for i, name in enumerate(("ic120_1", "ic120_2")):
        ctx = TreeContext(store=store, clock=lambda: clock[0], task_clock=lambda: clock[0])
        tree = load_tree(CLAIM.replace("@GAP@", gap), ctx, source=f"task {i}", blackboard={"machine": name})
        runs.append((name, TaskRun(i, tree, clock=lambda: clock[0])))
    for _ in range(20):  # the manager's tick: every run stepped in turn, in one thread
        clock[0] += 0.05
        for _name, run in runs:
            if not run.done:
                run.step()
    return [name for name, run in runs if run.tree.ctx.blackboard.get("GOT") is True]


def test_a_claim_completed_in_one_tick_is_atomic_only_one_carrier_gets_the_point(store):
    assert _claimers(store, "") == ["ic120_1"]
    assert store.get_record("BB")["HOLDER"] == "ic120_1"


def test_a_claim_spread_over_two_ticks_is_not_atomic_both_carriers_would_enter(store):
    # A Delay between the check and the write returns RUNNING: the other task ticks in between, still reads false.
    gap = '<Delay delay_msec="50"><AlwaysSuccess/></Delay>'
    assert _claimers(store, gap) == ["ic120_1", "ic120_2"]


class _Goal:
    def __init__(self, ticks: int) -> None:
        self.state, self.error_code, self.message, self.feedback = "accepted", 0, "", ""
        self.ticks_left = ticks

    def cancel(self) -> None:
        self.state = "canceled"


class _Site:
    """Leaves complete after a few ticks; a carrier is inside the loading area from the start of its ENTER_PATH
    goal to the end of its LEAVE_PATH goal. A stand-in for the ZX200 task loads whoever arrived."""

    def __init__(self, store) -> None:
        self.store = store
        self.goals: list[tuple[str, str, _Goal]] = []
        self.inside: set[str] = set()
        self.max_inside = 0
        self.entries: list[str] = []
        self.loaded: list[str] = []
        self._loading = 0

    def subtask_server_ready(self, model_name: str, subtask_name: str) -> bool:
        return True

    def send_subtask_goal(self, model_name: str, subtask_name: str, record_name: str) -> _Goal:
        assert self.store.get_parameter(model_name, record_name)  # the machine's own record exists
        if record_name == "ENTER_PATH":
            assert self.store.get_record(BB)["LOADAREA_MACHINE"] == model_name and self.store.get_record(BB)["LOADAREA"]
            self.inside.add(model_name)
            self.entries.append(model_name)
            self.max_inside = max(self.max_inside, len(self.inside))
        goal = _Goal(3 if record_name in ("ENTER_PATH", "LEAVE_PATH") else 2)
        self.goals.append((model_name, record_name, goal))
        return goal

    def emergency_stop(self, model_name: str, reason: str) -> None:
        raise AssertionError(reason)

    def confirm_seq(self) -> int:
        return 0

    def confirmations(self, since: int) -> list:
        return []

    def step(self) -> None:
        for entry in list(self.goals):
            model, record, goal = entry
            goal.ticks_left -= 1
            if goal.ticks_left <= 0:
                goal.state = "succeeded"
                self.goals.remove(entry)
                if record == "LEAVE_PATH":
                    self.inside.discard(model)
        bb = self.store.get_record(BB)
        if bb["ARRIVAL_FLG"] and not bb["LOADED_FLG"]:
            self._loading += 1
            if self._loading >= 4:  # a few passes
                self.loaded.append(bb["LOADAREA_MACHINE"])
                self.store.set_fields(BB, {"LOADED_MACHINE": bb["LOADAREA_MACHINE"], "LOADED_FLG": True})
        elif bb["LOADED_FLG"] and not bb["ARRIVAL_FLG"]:
            self._loading = 0
            self.store.set_fields(BB, {"LOADED_FLG": False})


def test_fleet_carriers_take_turns_and_never_stand_at_the_loading_point_together(tmp_path):
    from tms_db import open_store
    from tms_db.cli import seed

    store = open_store(path=tmp_path / "db")
    seed(store, ROOT / "config" / "seeds" / "fleet.yaml")
    site = _Site(store)
    clock = [0.0]
    runs = []
    for task in store.list_tasks():
        if task["task_id"] == 11:
            continue  # the ZX200 task: the stand-in in _Site.step
        ctx = TreeContext(store=store, ros=site, clock=lambda: clock[0], task_clock=lambda: clock[0])
        tree = load_tree(task["task_sequence"], ctx, source=f"task {task['task_id']}", blackboard=task["blackboard"])
        runs.append(TaskRun(task["task_id"], tree, clock=lambda: clock[0]))
    names = [run.tree.ctx.blackboard.get("machine") for run in runs]
    assert names == ["ic120_1", "ic120_2", "mst110cr_2"]
    for _ in range(3000):
        clock[0] += 0.05
        site.step()
        for run in runs:
            if not run.done:
                run.step()
        if len(site.loaded) >= 7:
            store.set_fields(BB, {"CONTINUE_FLG": False})
        if all(run.done for run in runs):
            break
    assert [run.state for run in runs] == [SUCCEEDED] * 3, [(r.state, r.message) for r in runs]
    assert site.max_inside == 1
    # first come, first served: the tickets taken at the first tick, then each return queues again
    assert site.entries[:6] == names + names, site.entries
    assert site.loaded == site.entries
    bb = store.get_record(BB)
    assert bb["LOADAREA"] is False and bb["NOW_SERVING"] == len(site.entries) + 1
    assert RUNNING not in [run.state for run in runs]
