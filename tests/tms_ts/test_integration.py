"""tms_ts across processes: manager, subtask servers, planning stub and the DB on disk.

Every process runs on the test's own ROS_DOMAIN_ID (fixtures ``domain``/``procs``).
"""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.integration


def _handoff_tree(model: str, leaf: str, subtask: str, record: str, mine: str, other: str) -> str:
    return f"""<root main_tree_to_execute="BehaviorTree">
  <BehaviorTree ID="BehaviorTree">
    <Repeat num_cycles="5">
      <Sequence>
        <Decorator ID="KeepRunningUntilFlgup" key="MY_TURN">
          <Action ID="BlackboardValueReaderMongo" output_port="MY_TURN" mongo_record_name="HANDOFF" \
mongo_param_name="{mine}"/>
        </Decorator>
        <Action ID="{leaf}" model_name="{model}" subtask_name="{subtask}" record_name="{record}"/>
        <Action ID="MongoValueWriter" input_value="false" mongo_record_name="HANDOFF" mongo_param_name="{mine}"/>
        <Action ID="MongoValueWriter" input_value="true" mongo_record_name="HANDOFF" mongo_param_name="{other}"/>
      </Sequence>
    </Repeat>
  </BehaviorTree>
</root>"""


def _one_leaf(model: str, leaf: str, subtask: str, record: str) -> str:
    return (f'<root main_tree_to_execute="B"><BehaviorTree ID="B"><Sequence><AlwaysSuccess/>'
            f'<Action ID="{leaf}" name="work" model_name="{model}" subtask_name="{subtask}" record_name="{record}"/>'
            f"</Sequence></BehaviorTree></root>")


def _seed(store) -> None:
    store.upsert_parameter({"model_name": "ic120", "type": "static", "record_name": "load_point",
                            "x": 10.0, "y": 2.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0})
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "initial_pose", "trajectory": 1,
                            "swing_joint": 0.0, "boom_joint": -0.3, "arm_joint": 1.2, "bucket_joint": 0.5,
                            "LOCK_FLG": True})
    store.upsert_parameter({"record_name": "HANDOFF", "type": "dynamic", "IC120_TURN": True, "ZX200_TURN": False})


def _state(system, task_id):
    t = system.task(task_id)
    return None if t is None else t.state


def test_two_tasks_hand_a_flag_back_and_forth_for_5_rounds(ts_system):
    from tms_msg.msg import TaskIds, TaskState

    _seed(ts_system.store)
    ts_system.store.add_task(_handoff_tree("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere", "load_point",
                                           "IC120_TURN", "ZX200_TURN"), task_id=1, description="ic120 side")
    ts_system.store.add_task(_handoff_tree("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose",
                                           "ZX200_TURN", "IC120_TURN"), task_id=2, description="zx200 side")
    system = ts_system.start(stub_duration_s=0.2)
    system.publish("/tms_ts/start", TaskIds(task_ids=[1, 2]))
    system.wait(lambda: _state(system, 1) == TaskState.SUCCESS and _state(system, 2) == TaskState.SUCCESS, 120,
                "both handoff tasks to succeed")
    goals = [line.split()[1] for line in system.procs["stub"].lines if line.startswith("GOAL ")]
    assert goals == ["/ic120/navigate_to_pose", "/zx200/tms_rp_zx200_change_pose"] * 5, goals
    doc = system.store.get_record("HANDOFF")
    assert doc["IC120_TURN"] is True and doc["ZX200_TURN"] is False  # handed back after round 5
    assert system.store.get_parameter("zx200", "initial_pose")["LOCK_FLG"] is False  # cleared on result


def test_cancel_one_task_then_emergency_cancels_the_other(ts_system):
    from std_msgs.msg import Bool, Int32

    from tms_msg.msg import TaskIds, TaskState

    _seed(ts_system.store)
    ts_system.store.add_task(_one_leaf("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere", "load_point"), task_id=3)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose"), task_id=4
    )
    system = ts_system.start(stub_duration_s=60.0)
    system.publish("/tms_ts/start", TaskIds(task_ids=[3, 4]))
    system.wait(lambda: len([ln for ln in system.procs["stub"].lines if ln.startswith("GOAL")]) == 2, 30,
                "both planning goals")
    system.wait(lambda: all(system.task(i) and system.task(i).running_leaves for i in (3, 4)), 10, "running leaves")
    assert "work" in system.task(3).running_leaves[0]

    system.publish("/tms_ts/cancel", Int32(data=3))
    system.wait(lambda: _state(system, 3) == TaskState.CANCELED, 30, "task 3 CANCELED")
    assert "confirmed stop" in system.task(3).message, system.task(3).message
    assert system.procs["stub"].wait_for("CANCELED /ic120/navigate_to_pose", 10), (
        system.task(3).message,
        system.procs["ic120"].output,
        system.procs["stub"].output,
    )
    system.spin(1.0)
    assert _state(system, 4) == TaskState.RUNNING, system.task(4)
    assert "CANCELED /zx200/tms_rp_zx200_change_pose" not in system.procs["stub"].output

    system.publish("/emergency_signal", Bool(data=True))
    system.wait(lambda: _state(system, 4) == TaskState.CANCELED, 30, "task 4 CANCELED")
    assert "confirmed stop" in system.task(4).message and "emergency_signal" in system.task(4).message
    assert system.procs["stub"].wait_for("CANCELED /zx200/tms_rp_zx200_change_pose", 10)
    assert _state(system, 3) == TaskState.CANCELED  # not FAILURE
    assert system.store.get_parameter("zx200", "initial_pose")["LOCK_FLG"] is False


def test_emergency_escalates_when_a_subtask_never_confirms(ts_system):
    from std_msgs.msg import Bool

    from tms_msg.msg import TaskIds, TaskState

    _seed(ts_system.store)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose"), task_id=7
    )
    system = ts_system.start(stub_duration_s=60.0, ignore_cancel=True, halt_timeout_s=2.0, stop_timeout_s=30.0)
    emg = []
    system.node.create_subscription(Bool, "/zx200/emg_stop", emg.append, 10)
    system.publish("/tms_ts/start", TaskIds(task_ids=[7]))
    system.wait(lambda: "GOAL" in system.procs["stub"].output, 30, "the planning goal")
    system.publish("/emergency_signal", Bool(data=True))
    system.wait(lambda: _state(system, 7) == TaskState.CANCELED, 30, "task 7 CANCELED after escalation")
    assert "emergency stop sent" in system.task(7).message
    system.wait(lambda: emg and emg[-1].data is True, 10, "/zx200/emg_stop true")


def test_absent_server_and_missing_record_fail_naming_the_culprit(ts_system):
    from tms_msg.msg import TaskIds, TaskState

    _seed(ts_system.store)
    ts_system.store.add_task(_one_leaf("ic120", "LeafNodeIc120", "st_ic120_teleport", "load_point"), task_id=5)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "no_such_pose"), task_id=6
    )
    ts_system.store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "half_pose",
                                      "target_angle": 0.5})  # a release record, not a pose
    ts_system.store.add_task(_one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "half_pose"), task_id=8)
    system = ts_system.start(server_wait_s=2.0)
    system.publish("/tms_ts/start", TaskIds(task_ids=[5, 6, 8, 99]))
    system.wait(lambda: all(_state(system, i) == TaskState.FAILURE for i in (5, 6, 8, 99)), 60, "four failures")
    assert "/ic120/st_ic120_teleport" in system.task(5).message and "not available" in system.task(5).message
    # a record that fails validation: the goal is accepted and aborted with its code, the reason names the record
    assert (
        "aborted record 'no_such_pose': RECORD_INVALID: record 'no_such_pose': not found" in system.task(6).message
    ), system.task(6).message
    assert "RECORD_INVALID: record 'half_pose' field 'trajectory|pose|position_with_angle'" in system.task(8).message, \
        system.task(8).message
    assert "99" in system.task(99).message
    assert "GOAL" not in system.procs["stub"].output  # nothing reached planning


def test_a_manager_stopped_mid_task_cancels_its_subtasks_and_locks_the_machines(ts_system):
    """SIGINT to the manager (Ctrl-C, or a launch stopping): its running subtasks are canceled down to the
    planning servers and both machines' locks engaged before it exits 0, no traceback. With rclpy's own
    signal handler the context was gone before destroy_node, and neither went out."""
    import signal

    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool

    from tms_msg.msg import TaskIds

    _seed(ts_system.store)
    ts_system.store.add_task(_one_leaf("ic120", "LeafNodeIc120", "st_ic120_navigate_anywhere", "load_point"), task_id=3)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose"), task_id=4
    )
    locks: dict[str, list[bool]] = {"zx200": [], "ic120": []}
    for machine, seen in locks.items():
        ts_system.node.create_subscription(Bool, f"/{machine}/lock", lambda msg, seen=seen: seen.append(msg.data),
                                           QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    system = ts_system.start(stub_duration_s=60.0)
    system.publish("/tms_ts/start", TaskIds(task_ids=[3, 4]))
    system.wait(lambda: len([ln for ln in system.procs["stub"].lines if ln.startswith("GOAL")]) == 2, 30,
                "both planning goals")
    system.wait(lambda: all(system.task(i) and system.task(i).running_leaves for i in (3, 4)), 10, "running leaves")
    manager = system.procs["manager"]
    manager.signal(signal.SIGINT)
    assert manager.wait(10) == 0, manager.output
    assert "Traceback" not in manager.output, manager.output
    system.wait(lambda: locks["zx200"] == [True] and locks["ic120"] == [True], 10, f"both locks engaged: {locks}")
    for goal in ("/ic120/navigate_to_pose", "/zx200/tms_rp_zx200_change_pose"):
        assert system.procs["stub"].wait_for(f"CANCELED {goal}", 10), system.procs["stub"].output


def test_a_subtask_server_stopped_mid_goal_cancels_downstream_and_aborts_naming_why(ts_system):
    """SIGINT to a subtask server while its goal runs: the planning goal is canceled, the task ends FAILURE saying
    the server was stopping, the server exits 0 with no traceback (it used to die in the shut-down context)."""
    import signal

    from tms_msg.msg import TaskIds, TaskState

    _seed(ts_system.store)
    ts_system.store.add_task(
        _one_leaf("zx200", "LeafNodeZx200", "subtask_zx200_change_pose", "initial_pose"), task_id=4
    )
    system = ts_system.start(stub_duration_s=60.0)
    system.publish("/tms_ts/start", TaskIds(task_ids=[4]))
    system.wait(lambda: any(ln.startswith("GOAL") for ln in system.procs["stub"].lines), 30, "the planning goal")
    server = system.procs["zx200"]
    server.signal(signal.SIGINT)
    assert server.wait(15) == 0, server.output
    assert "Traceback" not in server.output, server.output
    assert system.procs["stub"].wait_for("CANCELED /zx200/tms_rp_zx200_change_pose", 10), system.procs["stub"].output
    system.wait(lambda: _state(system, 4) == TaskState.FAILURE, 30, "task 4 FAILURE")
    assert "subtask server stopping" in system.task(4).message, system.task(4).message
