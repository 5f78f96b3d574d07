"""change_pose_plan over a carrier parked under the swing path: the subtask server, the DB, the planner, the arm
controller, com3_bridge and the MuJoCo plant, every one its own process (tests/arm_stack.py ``arm_stack``).

The collision objects are the original's record (``collision_objects`` of the record the planner's
``collision_object_record_name`` names); the goals are LeafNodeBase goals naming position_with_angle records, as
the original's leaves send them. Contacts are checked in the plant: its MuJoCo geometry (the zx200 link boxes and
the ic120's boxes) posed from its truth topics, the front links padded as the planner pads them.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.rosproc import executable
from tms_model.excavator.kinematics import JOINTS

pytestmark = [pytest.mark.integration, pytest.mark.timeout(480)]

RECORD = "zx200_collision_objects"
CARRIER = (0.0, 7.5, math.pi / 2)  # [x, y, yaw] in map (= ZX200 base_link): long side radial, 4.5 .. 10.5 m out
CARRIER_BOX = (6.05, 3.37, 2.0)    # IC120 footprint; 2 m covers its vessel (the plant's is at 1.53 m)
GOALS = 10  # each a swing across the carrier: on the physical plant ~8 s simulated apiece
LEFT, RIGHT = 1.0, 2.1             # tip bearings [rad] either side of the carrier, radius 6.5 m, 0.5 m up
PADDING = 0.25                     # the original's link padding (config/tms_rp/zx200_collision.yaml)


def _pwa_record(name: str, p: list[float], theta_w: float = 1.6) -> dict:
    return {"model_name": "zx200", "type": "static", "record_name": name, "position_with_angle": 1,
            "x": p[0], "y": p[1], "z": p[2], "theta_w": theta_w}


def _tip(bearing: float) -> list[float]:
    return [6.5 * math.cos(bearing), 6.5 * math.sin(bearing), 0.5]


class PlantContacts:
    """The plant's own geometry (sim_bridge's MuJoCo model of the same plant file), posed from its truth."""

    def __init__(self, plant_config) -> None:
        import mujoco

        from sim_bridge.config import load_plant
        from sim_bridge.model import SiteModel

        self.mj = mujoco
        self.site = SiteModel(load_plant(plant_config))
        m = self.site.model

        def body(g: int) -> str:
            return mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.geom_bodyid[g])) or ""

        # the link boxes; the bucket's four-bar links lie inside the arm's and the bucket's (and this check sets the
        # joints without closing the linkage)
        linkage = ("zx200_guide_link", "zx200_side_link")
        self.arm = [(g, body(g)) for g in range(m.ngeom)
                    if body(g).startswith("zx200_") and body(g) != "zx200_base" and body(g) not in linkage]
        self.carrier = [g for g in range(m.ngeom) if body(g).startswith("ic120_")]
        assert len(self.arm) == 4 and len(self.carrier) == 2, (self.arm, self.carrier)

    def clearance(
        self, q: np.ndarray, ic_pose: tuple[float, float, float], ic_joints: dict[str, float]
    ) -> tuple[float, float, str]:
        """(smallest distance of any arm link box to the carrier, smallest distance minus the link's padding,
        the body of the latter)."""
        site = self.site
        for name, value in zip(JOINTS, q, strict=True):
            site.set_joint(f"zx200_{name}", float(value))
        site.set_base("zx200", 0.0, 0.0, 0.0, 0.0)
        site.set_base("ic120", ic_pose[0], ic_pose[1], 0.0, ic_pose[2])
        for name, value in ic_joints.items():
            site.set_joint(f"ic120_{name}", value)
        site.forward()
        best_d, best_pad, where = math.inf, math.inf, ""
        for g, body in self.arm:
            pad = 0.0 if body == "zx200_body_link" else PADDING
            for c in self.carrier:
                d = self.mj.mj_geomDistance(site.model, site.data, g, c, 10.0, None)
                best_d = min(best_d, d)
                if d - pad < best_pad:
                    best_pad, where = d - pad, body
        return best_d, best_pad, where


def test_change_pose_plan_swings_over_a_parked_carrier_without_contact(arm_stack, procs, ros_node, tmp_path) -> None:
    from geometry_msgs.msg import PoseStamped
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState

    from tms_common.config import config_path
    from tms_common.goals import OUTCOME_QOS
    from tms_db import open_store
    from tms_msg.msg import SubtaskOutcome
    from tms_msg_ts.action import LeafNodeBase

    db = str(tmp_path / "db")
    store = open_store(path=db)
    x, y, yaw = CARRIER
    store.upsert_parameter({"type": "static", "record_name": RECORD, "collision_objects": [{
        "id": "ic120", "primitive_type": 1, "dimensions": list(CARRIER_BOX),
        "pose": {"position": {"x": x, "y": y, "z": CARRIER_BOX[2] / 2},
                 "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}}}]})
    store.upsert_parameter(_pwa_record("plan_left", _tip(LEFT)))
    store.upsert_parameter(_pwa_record("plan_right", _tip(RIGHT)))
    store.upsert_parameter(_pwa_record("plan_inside", [x, y, 1.5]))  # the tip in the carrier's box
    store.close()

    stack = arm_stack(ic120_pose=f"[{x}, {y}, {yaw}]", speed=3.0, plant="paper_plant.yaml", clock_period_s=0.02,
                      rate_hz=50.0, joint_states_period_s=0.02,
                      planner_args=("-p", f"db_path:={db}", "-p", f"collision_object_record_name:={RECORD}",
                                    "-p", f"collision_config:={config_path('tms_rp', 'zx200_collision.yaml')}"))
    subtasks = procs([executable("tms_ts", "tms_ts_subtasks"), "--ros-args", "-r", "__node:=zx200_subtasks",
                      "-p", "machine:=zx200", "-p", f"db_path:={db}"], name="zx200_subtasks")
    assert subtasks.wait_for("subtask servers", 60), subtasks.output

    truth: list[np.ndarray] = []
    ic: dict = {}

    def on_zx(msg: JointState) -> None:
        idx = {n: i for i, n in enumerate(msg.name)}
        truth.append(np.array([msg.position[idx[n]] for n in JOINTS]))

    def on_ic_pose(msg: PoseStamped) -> None:
        ic["pose"] = (msg.pose.position.x, msg.pose.position.y,
                      2 * math.atan2(msg.pose.orientation.z, msg.pose.orientation.w))

    node = ros_node
    node.create_subscription(JointState, "/sim/truth/zx200/joint_states", on_zx, 100)
    node.create_subscription(JointState, "/sim/truth/ic120/joint_states",
                             lambda m: ic.__setitem__("joints", dict(zip(m.name, m.position, strict=True))), 10)
    node.create_subscription(PoseStamped, "/sim/truth/ic120/pose", on_ic_pose, 10)
    outcomes: dict[bytes, SubtaskOutcome] = {}
    node.create_subscription(SubtaskOutcome, "/zx200/subtask_outcome",
                             lambda m: outcomes.__setitem__(bytes(m.goal_id.uuid), m), OUTCOME_QOS)
    client = ActionClient(node, LeafNodeBase, "/zx200/subtask_zx200_change_pose_plan")
    assert stack.spin_until(client.server_is_ready, 30), subtasks.output
    assert stack.spin_until(lambda: "pose" in ic and "joints" in ic and truth, 10), "no truth from the plant"
    assert np.allclose(ic["pose"], CARRIER, atol=0.05), ic["pose"]

    def run(record: str, timeout: float = 90.0) -> tuple[bool, SubtaskOutcome]:
        sent = client.send_goal_async(LeafNodeBase.Goal(model_name="zx200", record_name=record))
        assert stack.spin_until(sent.done, 10) and sent.result().accepted, record
        handle = sent.result()
        res = handle.get_result_async()
        assert stack.spin_until(res.done, timeout), f"{record}: no result within {timeout} s\n{subtasks.output[-2000:]}"
        key = bytes(handle.goal_id.uuid)
        assert stack.spin_until(lambda: key in outcomes, 5), f"{record}: no SubtaskOutcome"
        return res.result().result.result, outcomes.pop(key)

    ok, out = run("plan_left")  # from the home pose, beside the carrier
    assert ok, out.error_msg
    plant = PlantContacts(stack.plant_config)
    t0 = time.monotonic()
    first = len(truth)
    for k in range(GOALS):
        record = "plan_right" if k % 2 == 0 else "plan_left"
        ok, out = run(record)
        assert ok, f"goal {k + 1} ({record}): {out.error_msg}\n{stack.procs['planner'].output[-3000:]}"
    elapsed = time.monotonic() - t0
    stack.spin(0.3)
    samples = truth[first:]
    # the truth comes every 50 ms of plant time: check 4 configurations between each two (the arm moves < 0.06 rad)
    dense = [a + s * (b - a) for a, b in zip(samples, samples[1:], strict=False) for s in (0.0, 0.25, 0.5, 0.75)]
    results = [plant.clearance(q, ic["pose"], ic["joints"]) for q in dense]
    min_d = min(r[0] for r in results)
    worst = min(results, key=lambda r: r[1])
    contacts = sum(1 for r in results if r[0] <= 0.0)
    padded_contacts = sum(1 for r in results if r[1] < 0.0)
    swings = np.ptp([q[0] for q in samples])
    print(
        f"\n{GOALS} change_pose_plan goals over the carrier in {elapsed:.1f} s wall; "
        f"{len(dense)} plant configurations; "
        f"contacts {contacts}, padded contacts {padded_contacts}; smallest plant distance {min_d:.3f} m, "
        f"smallest beyond padding {worst[1]:.3f} m ({worst[2]}); swing range {swings:.2f} rad"
    )
    assert swings > RIGHT - LEFT - 0.1, "the arm did not swing across the carrier"
    detours = stack.procs["planner"].output.count("over 'ic120' (record 'zx200_collision_objects')")
    assert detours >= GOALS, f"only {detours} of {GOALS} goals went over the carrier"
    assert contacts == 0 and padded_contacts == 0, (
        f"{padded_contacts} configurations with the padded arm in the carrier (worst {worst[1]:.3f} m at {worst[2]})")

    # a target inside the carrier: refused before any motion, naming the object and its record
    before = truth[-1].copy()
    ok, out = run("plan_inside", timeout=30)
    assert not ok
    assert out.error_code == SubtaskOutcome.PLANNING_FAILED, out
    assert "'ic120' (record 'zx200_collision_objects')" in out.error_msg and "target" in out.error_msg, out.error_msg
    assert "99999" in out.error_msg, out.error_msg  # the original's TmsRpErrorCodes.FAILURE
    stack.spin(1.0)
    assert np.max(np.abs(truth[-1] - before)) < 0.01, "the arm moved on a refused goal"
