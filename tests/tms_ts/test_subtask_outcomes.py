"""Typed subtask outcomes: one row per subtask, codes instead of prose, a cancel honoured before planning answers.

The first tests need no process; the last ones run a real ``tms_ts_subtasks`` with no planning server at all.
"""

from __future__ import annotations

import time

import pytest

from tests.rosproc import executable

ROWS_SAMPLES = {
    # a valid record per goal builder kind
    "change_pose": {"trajectory": 1, "swing_joint": 0.1, "boom_joint": -0.3, "arm_joint": 1.2, "bucket_joint": 0.5},
    "excavate": {"position_with_angle": 1, "x": 5.8, "y": 0.0, "z": 1.1, "theta_w": 1.2, "offset": 1.5},
    "release": {"target_angle": 1.57},
    "dump": {"target_angle": 0.8},
    "navigate_to_pose": {"x": 1.0, "y": 2.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0, "yaw": 90.0},
    "poses": {"x": [1.0, 2.0], "y": [0.0, 1.0], "qx": [0.0], "qy": [0.0], "qz": [0.0], "qw": [1.0], "yaw": [0.0, 90.0]},
}


JOINTS = {"swing_joint": 0.1, "boom_joint": -0.4, "arm_joint": 1.3, "bucket_joint": 0.6}


def _sample(spec) -> dict:
    if spec.steps is not None:  # ours: excavation to a stored design (its steps are the rows below)
        return {"design": "d", "base_x": 0.0, "base_y": 0.0, "base_yaw": 0.0}
    for kind in ("change_pose", "excavate", "release_simple"):
        if kind in spec.name:
            return ROWS_SAMPLES[kind.removesuffix("_simple")]
    if "_sample_" in spec.name:  # st_<machine>_sample_<joint>: <machine>_<joint>_goal_pos [deg]
        machine, joint = spec.name.removeprefix("st_").split("_sample_")
        return {f"{machine}_{joint}_goal_pos": 20.0}
    if "release_soil" in spec.name or spec.name.endswith("_swing"):
        return ROWS_SAMPLES["dump"]
    if "swing_align" in spec.name:
        return {}
    return ROWS_SAMPLES["navigate_to_pose" if "anywhere" in spec.name else "poses"]


def test_every_row_builds_its_own_actions_goal_and_reads_its_result() -> None:
    from tms_msg.msg import Zx200PlanningOutcome
    from tms_msg_rp.msg import TmsRpErrorCodes
    from tms_ts.subtask_specs import SUBTASKS

    for spec in SUBTASKS.values():
        plan = spec.build(_sample(spec), "r")
        if spec.steps is not None:  # several goals, each its step row's (tests/tms_ts/test_design_excavation.py)
            assert all(SUBTASKS[step.name].planning_action == step.planning_action for step in spec.steps.values())
            continue
        if spec.resolve is not None:
            plan = spec.resolve(plan, JOINTS, None)
        goal = spec.goal(plan)
        if spec.downstream == "service":  # a request, a response with a bool
            assert isinstance(goal, spec.action_type.Request), (spec.name, type(goal))
            assert spec.check(spec.action_type.Response(result=True))[0] is True, spec.name
            assert spec.check(spec.action_type.Response(result=False))[0] is False, spec.name
            continue
        assert isinstance(goal, spec.action_type.Goal), (spec.name, type(goal))
        ok_result, failed_result = spec.action_type.Result(), spec.action_type.Result()
        if hasattr(ok_result, "success"):
            ok_result.success = True
        elif hasattr(ok_result.error_code, "val"):
            ok_result.error_code.val, failed_result.error_code.val = (
                TmsRpErrorCodes.SUCCESS,
                Zx200PlanningOutcome.OUT_OF_REACH,
            )
        else:
            failed_result.error_code = 9004
        assert spec.check(ok_result)[0] is True, spec.name
        assert spec.check(failed_result)[0] is False, spec.name
    deg = SUBTASKS["st_ic120_navigate_anywhere_deg"]
    assert deg.goal(deg.build(ROWS_SAMPLES["navigate_to_pose"], "r")).pose.pose.orientation.z == pytest.approx(2**-0.5)


def test_zx200_rows_speak_the_originals_planning_actions_and_send_options_only_when_needed() -> None:
    from tms_msg_rp.action import TmsRpZx200ChangePose, TmsRpZx200ExcavateSimple, TmsRpZx200ReleaseSimple
    from tms_ts.subtask_specs import SUBTASKS

    rows = {s.planning_action: s for s in SUBTASKS.values() if s.outcome_topic}
    assert {name: s.action_type for name, s in rows.items()} == {
        "tms_rp_zx200_change_pose": TmsRpZx200ChangePose, "tms_rp_zx200_excavate_simple": TmsRpZx200ExcavateSimple,
        "tms_rp_zx200_release_simple": TmsRpZx200ReleaseSimple,
        "tms_rp_zx200_change_pose_plan": TmsRpZx200ChangePose,
        "tms_rp_zx200_excavate_simple_plan": TmsRpZx200ExcavateSimple}
    change = rows["tms_rp_zx200_change_pose"]
    pwa = {"position_with_angle": 1, "x": 5.0, "y": 0.0, "z": 1.0, "theta_w": 1.2}
    plain = change.build(pwa, "r")
    assert change.options(plain) is None  # nothing beyond the original's goal: no options call
    assert change.options(change.build({**pwa, "pass_through": 1, "theta_w_tolerance": 0.3}, "r")) == {
        "pass_through": True, "theta_w_tolerance": 0.3}
    assert change.goal(plain).position_with_angle_sequence[0].theta_w == 1.2


def test_codes_have_names_and_the_leaf_constant_is_the_interfaces() -> None:
    from tms_msg.msg import SubtaskOutcome
    from tms_ts.outcomes import CODE_NAMES, SERVER_LOST, code_name

    assert SERVER_LOST == SubtaskOutcome.SERVER_LOST
    assert code_name(SubtaskOutcome.RECORD_INVALID) == "RECORD_INVALID"
    assert code_name(4321) == "code 4321"
    assert len(CODE_NAMES) == 10 and CODE_NAMES[0] == "NONE"


def test_two_machines_servers_started_by_hand_get_their_own_names() -> None:
    from tms_ts.nodes.tms_ts_subtasks import node_name_from_args

    assert node_name_from_args(["x", "--ros-args", "-p", "machine:=zx200", "-p", "db_path:=/tmp/d"]) == "zx200_subtasks"
    assert (
        node_name_from_args(["x", "--ros-args", "-p", "db_path:=/tmp/d", "--param", "machine:=ic120"])
        == "ic120_subtasks"
    )
    assert node_name_from_args(["x", "--ros-args", "--params-file", "f.yaml"]) == "tms_ts_subtasks"


@pytest.fixture
def lone_subtasks(tmp_path, procs, ros_node):
    """A zx200 ``tms_ts_subtasks`` whose planning server never comes (planning_wait_s 30 s)."""
    from tms_db import open_store

    db = str(tmp_path / "db")
    store = open_store(path=db)
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "initial_pose", "trajectory": 1,
                            "swing_joint": 0.0, "boom_joint": -0.3, "arm_joint": 1.2, "bucket_joint": 0.5})
    store.close()
    proc = procs([executable("tms_ts", "tms_ts_subtasks"), "--ros-args", "-p", "machine:=zx200",
                  "-p", f"db_path:={db}", "-p", "planning_wait_s:=30.0"], name="zx200")
    assert proc.wait_for("subtask servers", 60), proc.output
    return proc


def _spin_until(node, predicate, timeout: float, what: str):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        node.executor_for_test.spin_once(timeout_sec=0.05)
        if predicate():
            return
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


@pytest.mark.integration
def test_cancel_is_honoured_while_waiting_for_planning_and_a_bad_record_aborts_with_its_code(lone_subtasks, ros_node):
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from tms_common.goals import OUTCOME_QOS
    from tms_msg.msg import SubtaskOutcome
    from tms_msg_ts.action import LeafNodeBase

    client = ActionClient(ros_node, LeafNodeBase, "/zx200/subtask_zx200_change_pose")
    outcomes: dict[bytes, SubtaskOutcome] = {}
    ros_node.create_subscription(SubtaskOutcome, "/zx200/subtask_outcome",
                                 lambda m: outcomes.__setitem__(bytes(m.goal_id.uuid), m), OUTCOME_QOS)
    _spin_until(ros_node, client.server_is_ready, 30, "the subtask server")
    feedback: list[str] = []

    def send(record: str):
        future = client.send_goal_async(LeafNodeBase.Goal(model_name="zx200", record_name=record),
                                        feedback_callback=lambda msg: feedback.append(msg.feedback.status))
        _spin_until(ros_node, future.done, 10, "the goal response")
        return future.result()

    def outcome(handle) -> SubtaskOutcome:  # the typed outcome beside the bool result
        key = bytes(handle.goal_id.uuid)
        _spin_until(ros_node, lambda: key in outcomes, 5, "the goal's SubtaskOutcome")
        return outcomes[key]

    # a record that does not exist: accepted (not rejected), then aborted RECORD_INVALID naming the record
    handle = send("no_such_pose")
    assert handle.accepted
    result = handle.get_result_async()
    _spin_until(ros_node, result.done, 10, "the RECORD_INVALID result")
    assert result.result().status == GoalStatus.STATUS_ABORTED and result.result().result.result is False
    assert outcome(handle).error_code == SubtaskOutcome.RECORD_INVALID
    assert "'no_such_pose'" in outcome(handle).error_msg
    assert (
        outcome(handle).action == "/zx200/subtask_zx200_change_pose" and outcome(handle).record_name == "no_such_pose"
    )
    # the reason is also the last feedback, for a client that reads only the original's type
    _spin_until(ros_node, lambda: any(f.startswith("RECORD_INVALID: ") for f in feedback), 5, "the reason in feedback")

    # a valid record: the goal waits for the planning server (30 s); a cancel ends it at once
    handle = send("initial_pose")
    assert handle.accepted
    result = handle.get_result_async()
    ros_node.executor_for_test.spin_once(timeout_sec=0.3)  # the goal is now waiting for planning
    asked = time.monotonic()
    cancel = handle.cancel_goal_async()
    _spin_until(ros_node, result.done, 5, "the CANCELED result")
    took = time.monotonic() - asked
    assert result.result().status == GoalStatus.STATUS_CANCELED and result.result().result.result is False
    assert outcome(handle).error_code == SubtaskOutcome.CANCELED
    assert "nothing was sent" in outcome(handle).error_msg
    assert took < 1.0, f"cancel took {took:.2f} s"
    assert cancel.done()


@pytest.mark.integration
def test_the_server_is_named_after_its_machine_and_its_start_up_parameters_refuse_a_set(lone_subtasks, ros_node):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    _spin_until(ros_node, lambda: "zx200_subtasks" in ros_node.get_node_names(), 20, "node zx200_subtasks")
    cli = ros_node.create_client(SetParameters, "/zx200_subtasks/set_parameters")
    _spin_until(ros_node, cli.service_is_ready, 20, "its set_parameters service")
    value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=1.0)
    future = cli.call_async(SetParameters.Request(parameters=[Parameter(name="planning_wait_s", value=value)]))
    _spin_until(ros_node, future.done, 10, "the set_parameters answer")
    answer = future.result().results[0]
    assert answer.successful is False and "read-only" in answer.reason, answer
