"""The manager's status bookkeeping (tms_ts.status) and its tree loader thread (tms_ts.tree_loading), without ROS:
finished runs leave after the retention, snapshots go out on change and once after the end, a load that raises
ends that start only."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from tms_msg.msg import TaskState
from tms_ts.loader import load_tree
from tms_ts.status import ALL_TASKS, StatusBook, snapshot_text
from tms_ts.task import TaskRun
from tms_ts.tree_loading import Loaded, LoadRequest, TreeLoadWorker

ENDS = (
    '<root><BehaviorTree ID="B"><Sequence><AlwaysSuccess/><AlwaysSuccess name="two"/></Sequence></BehaviorTree></root>'
)
SLEEPS = '<root><BehaviorTree ID="B"><Sequence><AlwaysSuccess/><Sleep msec="3600000"/></Sequence></BehaviorTree></root>'


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def _run(task_id: int, xml: str) -> TaskRun:
    run = TaskRun(task_id, load_tree(xml))
    run.step()  # no leaves: no server to wait for, the first step ticks
    return run


def _snapshots(msg) -> dict[int, str]:
    return {t.task_id: t.tree_snapshot for t in msg.tasks}


def test_snapshot_text_is_the_trees_form_and_bounded_and_iterative():
    tree = load_tree(SLEEPS)
    assert snapshot_text(tree.root, 100, len(tree.nodes)) == tree.snapshot()
    # a chain deeper than Python's recursion limit: no RecursionError (Tree.snapshot recurses)
    root = node = SimpleNamespace(name="n", node_id="n", status=None, children=[])
    for _ in range(5000):
        child = SimpleNamespace(name="n", node_id="n", status=None, children=[])
        node.children.append(child)
        node = child
    text = snapshot_text(root, 50, 5001)
    lines = text.splitlines()
    assert len(lines) == 51 and lines[-1] == "... 4951 more nodes (snapshot_max_nodes 50)"
    assert lines[49].startswith(" " * 98 + "n [?]")


def test_a_running_tasks_snapshot_goes_out_only_when_it_changes_or_is_asked_for():
    book = StatusBook(clock=Clock())
    run = _run(1, SLEEPS)
    first = book.build({1: run})
    assert "Sleep [R]" in _snapshots(first)[1]
    assert _snapshots(book.build({1: run}))[1] == ""  # unchanged: not sent again
    assert book.build({1: run}).tasks[0].state == TaskState.RUNNING  # the state still is, every time
    book.request(1)
    assert _snapshots(book.build({1: run}))[1] == _snapshots(first)[1]
    book.request(ALL_TASKS)
    assert _snapshots(book.build({1: run}))[1] != ""
    run.cancel("test")  # halted: the snapshot changes (every node IDLE), so it goes out
    assert run.done
    book.retire(run)
    msg = book.build({})
    assert msg.tasks[0].state == TaskState.CANCELED and "[R]" not in _snapshots(msg)[1] != ""


def test_a_finished_runs_snapshot_is_sent_once_and_the_run_leaves_after_the_retention():
    clock = Clock()
    book = StatusBook(retention_s=60.0, clock=clock)
    run = _run(7, ENDS)
    assert run.done
    book.retire(run)
    first = book.build({})
    assert [t.task_id for t in first.tasks] == [7] and first.tasks[0].state == TaskState.SUCCESS
    # the tree as it ended (halted: every node IDLE again, as the manager showed it before)
    assert first.tasks[0].tree_snapshot == "Sequence [I]\n  AlwaysSuccess [I]\n  AlwaysSuccess 'two' [I]"
    clock.t += 59.0
    again = book.build({})
    assert [t.task_id for t in again.tasks] == [7] and again.tasks[0].tree_snapshot == ""  # once only
    clock.t += 2.0
    assert book.build({}).tasks == []  # 61 s after its end: gone


def test_an_end_is_published_once_even_with_no_retention_and_at_most_keep_max_are_kept():
    clock = Clock()
    book = StatusBook(retention_s=0.0, keep_max=3, clock=clock)
    book.record(5, TaskState.FAILURE, "cannot start task 5: x")
    clock.t += 10.0  # nobody published in between: the end still reaches one message
    assert [(t.task_id, t.message) for t in book.build({}).tasks] == [(5, "cannot start task 5: x")]
    clock.t += 0.001
    assert book.build({}).tasks == []
    book = StatusBook(retention_s=3600.0, keep_max=3, clock=clock)
    for task_id in range(10, 20):
        book.record(task_id, TaskState.SUCCESS, "")
    assert [t.task_id for t in book.build({}).tasks] == [17, 18, 19]  # the last three ends


def test_a_task_started_again_leaves_the_finished_list_and_a_loading_one_is_reported_running():
    book = StatusBook(clock=Clock())
    book.record(3, TaskState.FAILURE, "old")
    book.forget(3)
    msg = book.build({}, [(3, "tree being loaded off the tick")])
    assert [(t.task_id, t.state, t.message) for t in msg.tasks] == [
        (3, TaskState.RUNNING, "loading: tree being loaded off the tick")]


def _wait(predicate, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.01)


def test_the_loader_thread_survives_whatever_a_load_raises_and_keeps_the_order():
    def load(request: LoadRequest):
        for task_id in request.task_ids:
            if task_id in (1, 5):
                raise RecursionError("maximum recursion depth exceeded")
            yield Loaded(request.seq, task_id, tree=f"tree {task_id}")

    worker = TreeLoadWorker(load)
    for seq, task_ids in enumerate(((1,), (2,), (3,), (4, 5, 6))):
        assert worker.submit(LoadRequest(seq, task_ids=task_ids))
    got: list[Loaded] = []
    _wait(lambda: got.extend(worker.take()) or len(got) == 6)
    assert [g.task_id for g in got] == [1, 2, 3, 4, 5, 6]
    assert got[0].tree is None and got[0].error == ("cannot start task 1: loading raised RecursionError: "
                                                    "maximum recursion depth exceeded")
    assert [g.tree for g in got[1:4]] == ["tree 2", "tree 3", "tree 4"] and worker.pending == 0
    # the ids of a request after the one that raised end with its error too: none is left "loading" for ever
    assert [g.error.split(":")[0] for g in got[4:]] == ["cannot start task 5", "cannot start task 6"]
    worker.close()
    assert worker.join(5.0)


def test_the_loader_refuses_beyond_max_pending_and_a_load_runs_on_its_own_thread():
    release = threading.Event()
    threads = []

    def load(request: LoadRequest):
        threads.append(threading.current_thread().name)
        release.wait(10)
        yield Loaded(request.seq, request.task_ids[0])

    worker = TreeLoadWorker(load, max_pending=2)
    assert worker.submit(LoadRequest(1, task_ids=(1,))) and worker.submit(LoadRequest(2, task_ids=(2,)))
    assert not worker.submit(LoadRequest(3, task_ids=(3,)))  # two wait already
    assert worker.pending == 2 and worker.take() == []  # take() never blocks on a load under way
    release.set()
    _wait(lambda: worker.pending == 0)
    assert [r.task_id for r in worker.take()] == [1, 2]
    assert threads == ["tms_ts_tree_loader"] * 2 and threading.current_thread().name not in threads
    worker.close()
    assert not worker.submit(LoadRequest(4, task_ids=(4,)))
    with pytest.raises(ValueError):
        TreeLoadWorker(load, max_pending=0)
