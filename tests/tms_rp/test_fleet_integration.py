"""Machines by name over the MuJoCo plant and COM3 CAN: the one tracked stack per machine, as real processes.

Each machine's nodes run in a container process of its own (``python -m tms_launch.container``, as tms-launch
runs a computer of the real system); the plant and the converters share one process with in-process CAN
buses (``TMS_CAN_IN_PROCESS``, the composed paper layout's plant container). The nodes are the generic
``tracked_localization``, ``tracked_navigator`` and ``vessel_controller`` of each machine by name.
"""

from __future__ import annotations

import json
import math
import sys
import time

import pytest
import yaml

from tests.rosutil import ActionCall, pose_stamped, spin_until, yaw_of
from tms_common.config import config_path, load_yaml

pytestmark = pytest.mark.integration

#: the generic node classes, through the executables the venv has (tms_launch.container.node_class)
STACK = {"localization": ("tms_rp", "tracked_localization"), "navigator": ("tms_rp", "tracked_navigator"),
         "vessel": ("tms_rc", "vessel_controller"), "arm": ("tms_rc", "excavator_arm_controller")}


def _plant_yaml(tmp_path, machines: dict[str, str], poses: dict[str, object]) -> str:
    data, _ = load_yaml(config_path("sim", "plant.yaml"))
    # paths in a plant file are relative to its directory: absolute ones for a file under tmp_path
    data["machines"] = {name: str(config_path("machines", f"{kind}.yaml")) for name, kind in machines.items()}
    data["initial_poses"] = poses
    data["site"] = str(config_path("site.yaml"))
    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _container(procs, name: str, nodes: list[dict], **env: str):
    return procs([sys.executable, "-m", "tms_launch.container", name, json.dumps(nodes)], name=name, **env)


def _node(name: str, package: str, executable: str, ns: str, **params: object) -> dict:
    args = ["--ros-args", "-r", f"__ns:=/{ns}", "-r", f"__node:={name}"]
    for key, value in params.items():
        args += ["-p", f"{key}:={str(value).lower() if isinstance(value, bool) else value}"]
    return {"name": name, "package": package, "executable": executable, "ros_args": args}


def _stack(machine: str, *, vessel: bool = False, arm: bool = False) -> list[dict]:
    nodes = [_node("tracked_localization", *STACK["localization"], machine, machine=machine),
             _node("tracked_navigator", *STACK["navigator"], machine, machine=machine)]
    if vessel:
        nodes.append(_node("vessel_controller", *STACK["vessel"], machine, machine=machine))
    if arm:
        nodes.append(_node("excavator_arm_controller", *STACK["arm"], machine))
    return nodes


def _plant(procs, tmp_path, machines: dict[str, str], poses: dict[str, object], parked: dict[str, str]):
    """The plant with ``machines`` (each with its converter) and ``parked`` ones (no converter: held at rest by
    the plant's watchdog; the plant needs an excavator and a carrier on the site)."""
    plant = [{"name": "sim_plant", "package": "sim_bridge", "executable": "sim_plant",
              "ros_args": ["--ros-args", "-p", f"config:={_plant_yaml(tmp_path, {**machines, **parked}, poses)}"]}]
    plant += [_node("com3_bridge", "com3_can", "com3_bridge", name, machine=name) for name in machines]
    return _container(procs, "plant", plant, TMS_CAN_IN_PROCESS=",".join([*machines, *parked]))


class _Truth:
    """The plant's truth of one machine by name: last pose (x, y, yaw) and joints."""

    def __init__(self, node, name: str) -> None:
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState

        self.pose: tuple[float, float, float] | None = None
        self.joints: dict[str, float] = {}
        node.create_subscription(PoseStamped, f"/sim/truth/{name}/pose", self._on_pose, 10)
        node.create_subscription(JointState, f"/sim/truth/{name}/joint_states",
                                 lambda m: self.joints.update(zip(m.name, m.position, strict=False)), 10)

    def _on_pose(self, m) -> None:
        self.pose = (m.pose.position.x, m.pose.position.y, yaw_of(m.pose.orientation))


def _wait_estimate(node, name: str, *procs, timeout: float = 90.0) -> None:
    from nav_msgs.msg import Odometry

    got: list = []
    sub = node.create_subscription(Odometry, f"/{name}/odometry/global", got.append, 10)
    spin_until(node, lambda: len(got) > 10 or any(p.popen.poll() is not None for p in procs), timeout)
    assert len(got) > 10, \
        f"no /{name}/odometry/global\n" + "\n".join(f"--- {p.name}:\n{p.output[-2500:]}" for p in procs)
    node.destroy_subscription(sub)


def _err(pose: tuple[float, float, float], goal: tuple[float, float, float]) -> tuple[float, float]:
    return (math.hypot(pose[0] - goal[0], pose[1] - goal[1]),
            abs((pose[2] - goal[2] + math.pi) % (2 * math.pi) - math.pi))


def test_two_carriers_of_one_kind_navigate_and_dump_through_their_own_converters(procs, domain, ros_node, tmp_path):
    """ic120_1 and ic120_2 in one plant: names, not kinds, on every topic and action."""
    from com3_msgs.action import SetDumpAngle
    from com3_msgs.srv import DumpUp
    from nav2_msgs.action import NavigateToPose

    t0 = time.monotonic()
    names = ("ic120_1", "ic120_2")
    start = {"ic120_1": [22.0, 4.0, 0.0], "ic120_2": [22.0, 16.0, 0.0]}
    goals = {"ic120_1": (29.0, 4.0, 0.0), "ic120_2": (29.0, 16.0, 0.0)}
    from tms_db import open_store
    from tms_msg_ts.action import LeafNodeBase

    db = str(tmp_path / "db")
    store = open_store(path=db)
    store.upsert_parameter(
        {"model_name": "ic120_2", "type": "static", "record_name": "release_angle", "target_angle": 0.4}
    )
    store.close()
    plant = _plant(procs, tmp_path, dict.fromkeys(names, "ic120"), {**start, "zx200": "zx200_base"}, {"zx200": "zx200"})
    pcs = {n: _container(procs, f"{n}_pc", _stack(n, vessel=True)) for n in names}
    # ic120_2's subtasks as an MST2200VD's (the kind's rows): its release_soil calls the DumpUp service
    server = _container(procs, "site_server", [_node("ic120_2_subtasks", "tms_ts", "tms_ts_subtasks", "ic120_2",
                                                     model_name="ic120_2", machine="mst2200vd", db_path=db)])
    truth = {n: _Truth(ros_node, n) for n in names}
    for n in names:
        _wait_estimate(ros_node, n, plant, pcs[n])
    calls = {n: ActionCall(ros_node, NavigateToPose, f"/{n}/navigate_to_pose", NavigateToPose.Goal(
        pose=pose_stamped(*goals[n]))) for n in names}
    for n in names:  # both drive at once, each through its own navigator and converter
        status, result = calls[n].wait(120.0)
        assert status == 4 and result.error_code == 0, (
            n,
            result.error_msg,
            pcs[n].output[-3000:],
            plant.output[-2000:],
        )
    for n in names:
        assert spin_until(ros_node, lambda n=n: truth[n].pose is not None, 5.0)
        e_xy, e_yaw = _err(truth[n].pose, goals[n])
        print(f"{n}: at {truth[n].pose}, error {e_xy:.3f} m {e_yaw:.3f} rad")
        assert e_xy < 0.25 and e_yaw < 0.12, n
    # dump: ic120_1 through the OPERA action; ic120_2 through the MST release subtask, whose downstream is the
    # DumpUp service vessel_target_pos of ic120_2's vessel controller
    dump = ActionCall(ros_node, SetDumpAngle, "/ic120_1/set_dump_angle", SetDumpAngle.Goal(target_angle=0.6))
    release = ActionCall(ros_node, LeafNodeBase, "/ic120_2/st_mst2200_release_soil",
                         LeafNodeBase.Goal(model_name="ic120_2", record_name="release_angle"), server_timeout=60.0)
    status, result = dump.wait(60.0)
    assert status == 4 and result.success, pcs["ic120_1"].output[-2000:]
    status, result = release.wait(60.0)
    assert status == 4 and result.result, (server.output[-2000:], pcs["ic120_2"].output[-2000:])
    cli = ros_node.create_client(DumpUp, "/ic120_2/vessel_target_pos")  # a bad angle: the reply says false
    assert spin_until(ros_node, cli.service_is_ready, 20.0)
    reply = cli.call_async(DumpUp.Request(vessel_angle=3.0))
    assert spin_until(ros_node, reply.done, 10.0) and reply.result().result is False
    for n, target in (("ic120_1", 0.6), ("ic120_2", 0.4)):
        assert spin_until(ros_node, lambda n=n, t=target: abs(truth[n].joints.get("vessel_joint", -9.0) - t)
                          < math.radians(2.0), 5.0), (n, truth[n].joints)
    # each name's vessel controller serves its own actions; the IC120 has no vessel swing: no set_swing_angle
    from rclpy.action import get_action_server_names_and_types_by_node

    for n in names:
        served = {a for a, _ in get_action_server_names_and_types_by_node(ros_node, "vessel_controller", f"/{n}")}
        assert served == {f"/{n}/set_dump_angle"}, served
    print(f"two carriers: {time.monotonic() - t0:.1f} s")


def test_zx200_drives_to_a_pose_through_its_subtask_and_a_sample_subtask_moves_one_joint(procs, domain, ros_node,
                                                                                       tmp_path):
    from tms_db import open_store
    from tms_msg.msg import SubtaskOutcome
    from tms_msg_ts.action import LeafNodeBase

    t0 = time.monotonic()
    db = str(tmp_path / "db")
    store = open_store(path=db)
    goal = (-5.0, -1.0, 0.0)  # behind the machine, heading kept: driven in reverse, away from the mound
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "zx200_goal",
                            "x": goal[0], "y": goal[1], "z": 0.0, "yaw": math.degrees(goal[2])})
    store.upsert_parameter({"model_name": "zx200", "type": "static", "record_name": "sample_swing",
                            "zx200_swing_goal_pos": 20.0})
    store.close()
    plant = _plant(procs, tmp_path, {"zx200": "zx200"}, {"zx200": "zx200_base", "ic120": "ic120_start"},
                   {"ic120": "ic120"})
    pc = _container(procs, "zx200_pc", _stack("zx200", arm=True))
    server = _container(procs, "site_server", [_node("zx200_subtasks", "tms_ts", "tms_ts_subtasks", "zx200",
                                                     model_name="zx200", db_path=db)])
    truth = _Truth(ros_node, "zx200")
    _wait_estimate(ros_node, "zx200", plant, pc)
    outcomes: dict[bytes, SubtaskOutcome] = {}
    from tms_common.goals import OUTCOME_QOS

    ros_node.create_subscription(SubtaskOutcome, "/zx200/subtask_outcome",
                                 lambda m: outcomes.__setitem__(bytes(m.goal_id.uuid), m), OUTCOME_QOS)
    assert server.wait_for("subtask servers for /zx200", 60.0), server.output[-3000:]
    call = ActionCall(ros_node, LeafNodeBase, "/zx200/st_zx200_navigate_anywhere_deg",
                      LeafNodeBase.Goal(model_name="zx200", record_name="zx200_goal"), server_timeout=60.0)
    status, result = call.wait(120.0)
    assert status == 4 and result.result, (server.output[-2000:], pc.output[-3000:], plant.output[-1500:])
    e_xy, e_yaw = _err(truth.pose, goal)
    print(f"zx200 at {truth.pose}: error {e_xy:.3f} m {e_yaw:.3f} rad")
    assert e_xy < 0.25 and e_yaw < 0.12
    # its pose in map is passed through: no filter gates its azimuth (it gated every one against a stale heading)
    assert "passed through (the EKF" in pc.output and "azimuth rejected" not in pc.output, pc.output[-2000:]
    # one joint: the swing to 20 deg, the others where they were
    before = dict(truth.joints)
    call = ActionCall(ros_node, LeafNodeBase, "/zx200/st_zx200_sample_swing",
                      LeafNodeBase.Goal(model_name="zx200", record_name="sample_swing"))
    status, result = call.wait(90.0)
    assert status == 4 and result.result, (server.output[-2000:], pc.output[-3000:])
    assert spin_until(ros_node, lambda: abs(truth.joints.get("swing_joint", 9.0) - math.radians(20.0)) < 0.05, 5.0), \
        truth.joints
    for j in ("boom_joint", "arm_joint", "bucket_joint"):
        assert abs(truth.joints[j] - before[j]) < 0.05, (j, before[j], truth.joints[j])
    # a record without the field: RECORD_INVALID naming the record and the field
    call = ActionCall(ros_node, LeafNodeBase, "/zx200/st_zx200_sample_boom",
                      LeafNodeBase.Goal(model_name="zx200", record_name="sample_swing"))
    status, result = call.wait(20.0)
    assert status == 6 and not result.result
    key = bytes(call.handle.goal_id.uuid)
    assert spin_until(ros_node, lambda: key in outcomes, 5.0)
    assert outcomes[key].error_code == SubtaskOutcome.RECORD_INVALID
    assert "'sample_swing'" in outcomes[key].error_msg and "zx200_boom_goal_pos" in outcomes[key].error_msg
    print(f"zx200: {time.monotonic() - t0:.1f} s")
