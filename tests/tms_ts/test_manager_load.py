"""The manager loads trees off its tick (issue 38, item 3): a slow load holds up neither the other tasks' ticks nor
a cancel nor an emergency stop, and a load that raises ends that start only.

The manager node runs in this process on the executor its executable uses (``events``), with a real DDS
participant: the cancel and the emergency stop come from another rclpy context over DDS. A load is made slow by
wrapping ``load_tree`` in a pure-Python busy loop of ``SLOW_S`` seconds (it holds the GIL the way the XML parser
and the node constructors do); before this change the manager loaded on the executor's thread and every tick,
cancel and emergency stop waited for the whole load.
"""

from __future__ import annotations

import time

import pytest

from tms_msg.msg import TaskState

pytestmark = pytest.mark.integration

SLOW_S = 3.0
RUNS = ('<root><BehaviorTree ID="B"><ReactiveSequence>'
        '<Action ID="BlackboardValueReaderMongo" output_port="flg" mongo_record_name="BB" mongo_param_name="FLG"/>'
        '<Sleep msec="3600000"/></ReactiveSequence></BehaviorTree></root>')
ENDS = '<root><BehaviorTree ID="{id}"><Sequence><AlwaysSuccess name="{name}"/></Sequence></BehaviorTree></root>'


@pytest.fixture
def manager(tmp_path, domain, ros_node, monkeypatch):
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from rclpy.task import Future

    from tms_common.node import make_executor
    from tms_db import open_store
    from tms_ts.nodes import tms_ts_manager as module

    db = str(tmp_path / "db")
    with open_store(path=db) as store:
        store.upsert_parameter({"record_name": "BB", "type": "dynamic", "FLG": True})
        store.add_task(RUNS, task_id=1)
        store.add_task(RUNS.replace('"B"', '"B2"'), task_id=2)
        store.add_task(ENDS.format(id="S", name="SLOW"), task_id=3)
        store.add_task(ENDS.format(id="D", name="RAISES"), task_id=4)
        store.add_task(ENDS.format(id="E", name="fine"), task_id=5)

    real = module.load_tree

    def load_tree(xml, ctx=None, **kwargs):
        if "SLOW" in xml:  # pure Python for SLOW_S: holds the GIL as a large tree's parse and build do
            end, x = time.monotonic() + SLOW_S, 0
            while time.monotonic() < end:
                x += sum(range(100))
        if "RAISES" in xml:  # what no loader should raise, and a deep recursion did
            raise RecursionError("maximum recursion depth exceeded")
        return real(xml, ctx, **kwargs)

    monkeypatch.setattr(module, "load_tree", load_tree)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = module.TaskManager(context=ctx, parameter_overrides=[
        Parameter("db_path", value=db), Parameter("tick_rate_hz", value=20.0), Parameter("status_rate_hz", value=4.0)])
    ex = make_executor("events", context=ctx)  # as the executable runs it
    ex.add_node(node)

    def spin(seconds: float, until=None) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_until_future_complete(Future(), timeout_sec=0.02)
            if until is not None and until():
                return True
        return until is None

    node.spin = spin
    yield node
    ex.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.shutdown(context=ctx)


def _ended(node, task_id: int) -> TaskState | None:
    entry = node.status.ended.get(task_id)
    return None if entry is None else entry.state


def test_a_slow_load_delays_no_tick_no_cancel_and_no_emergency_stop(manager, ros_node):
    from std_msgs.msg import Bool, Int32

    node = manager
    cancel = ros_node.create_publisher(Int32, "/tms_ts/cancel", 10)
    emergency = ros_node.create_publisher(Bool, "/emergency_signal", 10)
    assert node.spin(20, lambda: cancel.get_subscription_count() and emergency.get_subscription_count())
    node.start_task(1)
    node.start_task(2)
    assert node.spin(10, lambda: all(t in node.runs and node.runs[t].state == "running" for t in (1, 2)))

    node.start_task(3)  # SLOW_S of loading from here
    assert node.spin(1.0, lambda: node.loader.pending == 1 and 3 in node._loading)
    start, ticks0 = time.monotonic(), node._stats["ticks"]
    node._stats["max_late_ms"] = 0.0  # the lateness while the tree loads, from here
    cancel.publish(Int32(data=1))
    # CANCELED within 1 s, the load still under way: the cancel did not wait for it
    assert node.spin(1.0, lambda: _ended(node, 1) is not None)
    assert _ended(node, 1).state == TaskState.CANCELED and node.loader.pending == 1
    emergency.publish(Bool(data=True))
    assert node.spin(1.0, lambda: _ended(node, 2) is not None)
    assert _ended(node, 2).state == TaskState.CANCELED and node.loader.pending == 1
    assert time.monotonic() - start < SLOW_S - 0.5

    # the tree that was loading when the emergency stop came never runs
    assert node.spin(SLOW_S + 5, lambda: _ended(node, 3) is not None)
    window = time.monotonic() - start
    assert 3 not in node.runs
    assert _ended(node, 3).state == TaskState.CANCELED
    assert _ended(node, 3).message == "canceled by /emergency_signal while its tree loaded (not started)"
    # ticks went on: at most 0.5 s late at any time (the load alone took SLOW_S), 80 % of them on time
    assert node._stats["max_late_ms"] < 500.0, node._stats
    assert node._stats["ticks"] - ticks0 >= 0.8 * window * 20.0, (node._stats, window)


def test_a_load_that_raises_ends_that_start_only_and_an_unstored_tree_runs_under_an_ad_hoc_id(manager):
    from std_msgs.msg import String

    node = manager
    node.start_task(4)
    node.start_task(5)
    node.start_task(99)  # no such task: the DB's error, as before
    assert node.spin(10, lambda: all(_ended(node, t) is not None for t in (4, 5, 99)))
    assert _ended(node, 4).state == TaskState.FAILURE
    assert _ended(node, 4).message == "cannot start task 4: RecursionError: maximum recursion depth exceeded"
    assert _ended(node, 5).state == TaskState.SUCCESS
    assert _ended(node, 99).state == TaskState.FAILURE and "99" in _ended(node, 99).message
    ticks = node._stats["ticks"]
    # /task_sequence: parsed and matched against the stored tasks on the loader's thread too
    node._on_task_sequence(String(data=ENDS.format(id="N", name="not stored")))
    assert node.spin(10, lambda: _ended(node, -1) is not None)
    assert _ended(node, -1).state == TaskState.SUCCESS
    first = node.status.ended[5]
    node._on_task_sequence(String(data=ENDS.format(id="E", name="fine")))  # task 5's tree: runs as 5
    assert node.spin(10, lambda: node.status.ended.get(5) not in (None, first))
    assert _ended(node, 5).state == TaskState.SUCCESS and -2 not in node.status.ended
    node.spin(0.5)
    assert node._stats["ticks"] > ticks  # still ticking
