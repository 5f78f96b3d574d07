"""BT.CPP 3.8 semantics of every built-in node (reference §6), one test (or more) per node."""

from __future__ import annotations

import pytest

from tests.tms_ts.scripted import log, tree
from tms_ts.bt.core import FAILURE, IDLE, RUNNING, SUCCESS
from tms_ts.errors import TreeRuntimeError


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_sequence_remembers_running_child_and_resets_on_failure():
    t = tree('<Sequence><Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></Sequence>', a="S", b="RRS", c="F")
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is RUNNING and log(t) == ["b"]  # a is not re-ticked: running child remembered
    assert t.tick() is FAILURE and log(t) == ["b", "c"]
    assert t.tick() is FAILURE and log(t) == ["a", "b", "c"]  # failure reset the index to 0


def test_sequence_star_retries_the_failed_child_without_restarting():
    t = tree('<SequenceStar><Scripted id="a"/><Scripted id="b"/></SequenceStar>', a="S", b="FS")
    assert t.tick() is FAILURE and log(t) == ["a", "b"]
    assert t.tick() is SUCCESS and log(t) == ["b"]  # a not ticked again
    t2 = tree('<SequenceWithMemory><Scripted id="a"/></SequenceWithMemory>', a="S")  # v4 name
    assert t2.tick() is SUCCESS


def test_fallback_remembers_running_child_and_stops_on_success():
    t = tree('<Fallback><Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></Fallback>', a="F", b="RS", c="S")
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is SUCCESS and log(t) == ["b"]
    t2 = tree('<Fallback><Scripted id="a"/><Scripted id="b"/></Fallback>', a="F", b="F")
    assert t2.tick() is FAILURE and log(t2) == ["a", "b"]


def test_reactive_sequence_reticks_from_start_and_halts_later_children():
    t = tree('<ReactiveSequence><Scripted id="a"/><Scripted id="b"/></ReactiveSequence>', a="SSF", b="R")
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is RUNNING and log(t) == ["a", "b"]  # condition re-evaluated every tick
    assert t.tick() is FAILURE and log(t) == ["a", "halt b"]  # a failing halts the running b
    t2 = tree('<ReactiveSequence><Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></ReactiveSequence>',
              a="S", b="SR", c="R")
    assert t2.tick() is RUNNING and log(t2) == ["a", "b", "c"]
    assert t2.tick() is RUNNING and log(t2) == ["a", "b", "halt c"]  # earlier child RUNNING halts later ones


def test_reactive_fallback_reticks_from_start():
    t = tree('<ReactiveFallback><Scripted id="a"/><Scripted id="b"/></ReactiveFallback>', a="FFS", b="R")
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is SUCCESS and log(t) == ["a", "halt b"]


def test_parallel_thresholds_negative_means_all_and_skips_finished_children():
    t = tree('<Parallel success_threshold="-1" failure_threshold="1">'
             '<Scripted id="a"/><Scripted id="b"/></Parallel>', a="S", b="RRS")
    assert t.tick() is RUNNING and log(t) == ["a", "b"]
    assert t.tick() is RUNNING and log(t) == ["b"]  # finished a is skipped
    assert t.tick() is SUCCESS and log(t) == ["b"]


def test_parallel_failure_threshold_halts_running_siblings():
    t = tree('<Parallel success_threshold="2" failure_threshold="1">'
             '<Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></Parallel>', a="R", b="RF", c="R")
    assert t.tick() is RUNNING
    log(t)
    assert t.tick() is FAILURE and log(t) == ["a", "b", "halt a", "halt c"]  # c still RUNNING from tick 1
    assert t.root.children[2].status is IDLE


def test_parallel_success_threshold_one_of_three_and_impossible_success():
    t = tree('<Parallel success_threshold="1" failure_threshold="3">'
             '<Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></Parallel>', a="R", b="S", c="R")
    assert t.tick() is SUCCESS and log(t) == ["a", "b", "halt a"]
    # success_threshold 3 of 3: one failure makes success impossible -> FAILURE even with failure_threshold 3
    t2 = tree('<Parallel success_threshold="-1" failure_threshold="3">'
              '<Scripted id="a"/><Scripted id="b"/><Scripted id="c"/></Parallel>', a="F", b="R", c="R")
    assert t2.tick() is FAILURE
    t3 = tree('<Parallel success_threshold="4"><Scripted id="a"/></Parallel>', a="S")
    with pytest.raises(TreeRuntimeError, match="can never succeed"):
        t3.tick()


def test_if_then_else_evaluates_condition_once_then_sticks_to_branch():
    t = tree('<IfThenElse><Scripted id="c"/><Scripted id="then"/><Scripted id="else"/></IfThenElse>',
             c="SF", then="RRS", **{"else": "S"})
    assert t.tick() is RUNNING and log(t) == ["c", "then"]
    assert t.tick() is RUNNING and log(t) == ["then"]  # condition not re-ticked
    assert t.tick() is SUCCESS and log(t) == ["then"]
    assert t.tick() is SUCCESS and log(t) == ["c", "else"]
    t2 = tree('<IfThenElse><Scripted id="c"/><Scripted id="then"/></IfThenElse>', c="F", then="S")
    assert t2.tick() is FAILURE and log(t2) == ["c"]


def test_while_do_else_reevaluates_condition_and_halts_other_branch():
    t = tree('<WhileDoElse><Scripted id="c"/><Scripted id="do"/><Scripted id="else"/></WhileDoElse>',
             c="SSF", do="R", **{"else": "R"})
    assert t.tick() is RUNNING and log(t) == ["c", "do"]
    assert t.tick() is RUNNING and log(t) == ["c", "do"]
    assert t.tick() is RUNNING and log(t) == ["c", "halt do", "else"]


def test_inverter_force_success_force_failure():
    assert tree('<Inverter><Scripted id="a"/></Inverter>', a="S").tick() is FAILURE
    assert tree('<Inverter><Scripted id="a"/></Inverter>', a="F").tick() is SUCCESS
    assert tree('<Inverter><Scripted id="a"/></Inverter>', a="R").tick() is RUNNING
    assert tree('<ForceSuccess><Scripted id="a"/></ForceSuccess>', a="F").tick() is SUCCESS
    assert tree('<ForceSuccess><Scripted id="a"/></ForceSuccess>', a="R").tick() is RUNNING
    assert tree('<ForceFailure><Scripted id="a"/></ForceFailure>', a="S").tick() is FAILURE


def test_repeat_loops_inside_one_tick_and_fails_on_child_failure():
    t = tree('<Repeat num_cycles="3"><Scripted id="a"/></Repeat>', a="S")
    assert t.tick() is SUCCESS and log(t) == ["a", "a", "a"]
    t2 = tree('<Repeat num_cycles="3"><Scripted id="a"/></Repeat>', a="SRSS")
    assert t2.tick() is RUNNING and log(t2) == ["a", "a"]
    assert t2.tick() is SUCCESS and log(t2) == ["a", "a"]  # count kept across ticks: 3 successes
    t3 = tree('<Repeat num_cycles="5"><Scripted id="a"/></Repeat>', a="SF")
    assert t3.tick() is FAILURE and log(t3) == ["a", "a"]


def test_repeat_forever_yields_after_the_sync_loop_budget():
    t = tree('<Repeat num_cycles="-1"><Scripted id="a"/></Repeat>', a="S")
    t.ctx.sync_loop_budget = 50
    assert t.tick() is RUNNING and len(log(t)) == 50


def test_retry_until_successful_loops_inside_one_tick():
    t = tree('<RetryUntilSuccessful num_attempts="3"><Scripted id="a"/></RetryUntilSuccessful>', a="FFS")
    assert t.tick() is SUCCESS and log(t) == ["a", "a", "a"]
    t2 = tree('<RetryUntilSuccessful num_attempts="2"><Scripted id="a"/></RetryUntilSuccessful>', a="F")
    assert t2.tick() is FAILURE and log(t2) == ["a", "a"]
    t3 = tree('<RetryUntilSuccessful num_attempts="-1"><Scripted id="a"/></RetryUntilSuccessful>', a="F")
    t3.ctx.sync_loop_budget = 10
    assert t3.tick() is RUNNING and len(log(t3)) == 10


def test_keep_running_until_failure():
    t = tree('<KeepRunningUntilFailure><Scripted id="a"/></KeepRunningUntilFailure>', a="SSF")
    assert t.tick() is RUNNING
    assert t.tick() is RUNNING
    assert t.tick() is FAILURE


def test_delay_runs_child_only_after_the_timer():
    t = tree('<Delay delay_msec="1000"><Scripted id="a"/></Delay>', a="S")
    clock = FakeClock()
    t.ctx.clock = clock
    assert t.tick() is RUNNING and log(t) == []
    clock.t += 0.999
    assert t.tick() is RUNNING and log(t) == []
    clock.t += 0.002
    assert t.tick() is SUCCESS and log(t) == ["a"]


def test_delay_timeout_and_sleep_run_on_the_task_clock_not_the_transport_clock():
    # The manager passes its ROS clock as task_clock: simulated time under use_sim_time, which can run
    # faster than the wall clock (``clock``) that times goal acceptance and halts.
    wall, sim = FakeClock(), FakeClock()
    for xml, first in (('<Delay delay_msec="1000"><Scripted id="a"/></Delay>', "S"),
                       ('<Sleep msec="1000"/>', None)):
        t = tree(xml, **({"a": first} if first else {}))
        t.ctx.clock, t.ctx.task_clock = wall, sim
        assert t.tick() is RUNNING
        wall.t += 5.0  # wall time alone does not end it
        assert t.tick() is RUNNING
        sim.t += 1.001
        assert t.tick() is SUCCESS
    t = tree('<Timeout msec="500"><Scripted id="a"/></Timeout>', a="R")
    t.ctx.clock, t.ctx.task_clock = wall, sim
    assert t.tick() is RUNNING
    wall.t += 5.0
    assert t.tick() is RUNNING
    sim.t += 0.6
    assert t.tick() is FAILURE and log(t) == ["a", "a", "halt a"]


def test_timeout_halts_child_and_fails():
    t = tree('<Timeout msec="500"><Scripted id="a"/></Timeout>', a="R")
    clock = FakeClock()
    t.ctx.clock = clock
    assert t.tick() is RUNNING
    clock.t += 0.6
    assert t.tick() is FAILURE and log(t) == ["a", "halt a"]
    t2 = tree('<Timeout msec="500"><Scripted id="a"/></Timeout>', a="RS")
    t2.ctx.clock = clock
    assert t2.tick() is RUNNING and t2.tick() is SUCCESS


def test_always_success_failure_and_set_blackboard_writes_strings():
    assert tree("<AlwaysSuccess/>").tick() is SUCCESS
    assert tree("<AlwaysFailure/>").tick() is FAILURE
    t = tree('<Sequence><SetBlackboard output_key="A" value="true"/>'
             '<SetBlackboard output_key="B" value="{A}"/></Sequence>')
    assert t.tick() is SUCCESS
    assert t.ctx.blackboard.get("A") == "true" and t.ctx.blackboard.get("B") == "true"  # strings, as BT.CPP 3.8


def test_halting_a_running_tree_halts_the_running_leaf_only():
    t = tree('<Sequence><Scripted id="a"/><Parallel success_threshold="-1"><Scripted id="b"/><Scripted id="c"/>'
             '</Parallel></Sequence>', a="S", b="R", c="S")
    assert t.tick() is RUNNING
    log(t)
    t.halt()
    assert log(t) == ["halt b"]
    assert all(n.status is IDLE for n in t.nodes)


def test_subtree_shared_and_remapped_blackboards():
    xml = ('<root main_tree_to_execute="Main">'
           '<BehaviorTree ID="Main"><Sequence>'
           '<SetLocalBlackboard value="seven" output_key="outer"/>'
           '<SubTree ID="Inner" x="{outer}" lit="hello"/>'
           '<SubTree ID="Shared" __shared_blackboard="true"/>'
           '</Sequence></BehaviorTree>'
           '<BehaviorTree ID="Inner"><Sequence><SetLocalBlackboard value="{x}" output_key="copy"/>'
           '<SetLocalBlackboard value="eight" output_key="x"/><SetLocalBlackboard value="{lit}" output_key="seen"/>'
           '</Sequence></BehaviorTree>'
           '<BehaviorTree ID="Shared"><SetLocalBlackboard value="1.5" output_key="shared"/></BehaviorTree>'
           '</root>')
    from tms_ts.loader import load_tree

    t = load_tree(xml)
    assert t.tick() is SUCCESS
    snap = t.ctx.blackboard.snapshot()
    # x remapped to outer; copy/seen stay in the subtree. Text values: value="{x}" (a std::string port) declares
    # x, and so outer, std::string, which refuses an int (BT.CPP 3.8).
    assert snap == {"outer": "eight", "shared": 1.5}


def test_v4_format_with_tag_names():
    from tms_ts.loader import load_tree

    t = load_tree('<root BTCPP_format="4"><BehaviorTree ID="Main"><Sequence name="seq">'
                  '<SetLocalBlackboard value="2" output_key="n"/>'
                  '<Repeat num_cycles="{n}"><Counter key="c"/></Repeat></Sequence></BehaviorTree></root>')
    t.ctx.blackboard.set("c", "0")
    assert t.tick() is SUCCESS and t.ctx.blackboard.get("c") == "2"
