"""Every new machine kind over COM3 CAN in the MuJoCo plant, driven by the original's subtask names, as real processes:
MST110CR (``mst110cr_2``), MST2200VD (``mst2200``), D37PXi (``d37pxi_24``) and the ZX120, each by the name the
original's
trees use (the ZX200 and the IC120: tests/tms_rp/test_fleet_integration.py).

Per kind: drives to a pose (``st_<prefix>_navigate_anywhere_deg``: subtask server -> navigator -> converter -> plant);
for the MSTs swings the vessel (``st_<prefix>_swing``), dumps (``st_<prefix>_release_soil``: the DumpUp service) and
swings back to the nearer of ahead/behind (``st_<prefix>_swing_align_to_heading``); then, driving again, its onboard
PC dies (SIGKILL): the converter's watchdog sends neutral frames and the machine comes to rest.
"""

from __future__ import annotations

import math
import signal
import time

import pytest

from tests.rosutil import ActionCall, spin_until
from tests.tms_rp.test_fleet_integration import (
    _container,
    _err,
    _node,
    _plant,
    _stack,
    _Truth,
    _wait_estimate,
)

pytestmark = pytest.mark.integration

#: name -> (kind, subtask prefix, start pose, goal pose, vessel swing)
KINDS = {
    "mst110cr_2": ("mst110cr", "mst110cr", [24.0, -8.0, 0.0], (30.0, -8.0, 0.0), True),
    "mst2200": ("mst2200vd", "mst2200", [24.0, -8.0, 0.0], (30.0, -8.0, 0.0), True),
    "d37pxi_24": ("d37pxi", "d37pxi", [-10.0, 12.0, 0.0], (-4.0, 12.0, 0.0), False),
    # the ZX120 travels on its tracks too (our st_zx120_* travel rows; the original has its sample subtasks only)
    "zx120": ("zx120", "zx120", [-12.0, -12.0, 0.0], (-6.0, -12.0, 0.0), False),
}
WATCHDOG_S = 0.5  # config/can/<kind>.yaml bridge.watchdog_s


def _speed(samples: list[tuple[float, float, float]]) -> float:
    (t0, x0, y0), (t1, x1, y1) = samples[-2], samples[-1]
    return math.hypot(x1 - x0, y1 - y0) / max(t1 - t0, 1e-3)


@pytest.mark.parametrize("name", sorted(KINDS))
def test_kind_drives_swings_dumps_and_rests_on_the_watchdog(procs, domain, ros_node, tmp_path, name):
    from geometry_msgs.msg import PoseStamped

    from tms_db import open_store
    from tms_model.fleet import load_named
    from tms_msg_ts.action import LeafNodeBase

    kind, prefix, start, goal, swings = KINDS[name]
    t0 = time.monotonic()
    db = str(tmp_path / "db")
    store = open_store(path=db)
    far = (goal[0] + 12.0, goal[1], 0.0)
    for record, fields in (("GOAL", {"x": goal[0], "y": goal[1], "z": 0.0, "yaw": math.degrees(goal[2])}),
                           ("FAR", {"x": far[0], "y": far[1], "z": 0.0, "yaw": 0.0}),
                           ("SWING_ANGLE_LEFT", {"target_angle": math.pi / 2}),
                           ("release_angle_1", {"target_angle": 0.6}),
                           ("release_angle_2", {"target_angle": 0.0})):
        store.upsert_parameter({"model_name": name, "type": "static", "record_name": record, **fields})
    store.close()
    parked = {"zx200": "zx200", "ic120": "ic120"}
    plant = _plant(procs, tmp_path, {name: kind}, {name: start, "zx200": "zx200_base", "ic120": "ic120_start"}, parked)
    pc = _container(procs, f"{name}_pc", _stack(name, vessel=swings))
    server = _container(procs, "site_server", [_node(f"{name}_subtasks", "tms_ts", "tms_ts_subtasks", name,
                                                     model_name=name, db_path=db)])
    truth = _Truth(ros_node, name)
    _wait_estimate(ros_node, name, plant, pc)
    assert server.wait_for(f"subtask servers for /{name}", 60.0), server.output[-3000:]

    def subtask(verb: str, record: str, timeout: float = 120.0) -> None:
        call = ActionCall(ros_node, LeafNodeBase, f"/{name}/st_{prefix}_{verb}",
                          LeafNodeBase.Goal(model_name=name, record_name=record), server_timeout=30.0)
        status, result = call.wait(timeout)
        assert status == 4 and result.result, (verb, server.output[-2000:], pc.output[-3000:], plant.output[-1500:])

    subtask("navigate_anywhere_deg", "GOAL")
    e_xy, e_yaw = _err(truth.pose, goal)
    print(f"{name} ({kind}): at {tuple(round(v, 3) for v in truth.pose)}, error {e_xy:.3f} m {e_yaw:.3f} rad")
    assert e_xy < 0.25 and e_yaw < 0.12
    if swings:
        subtask("swing", "SWING_ANGLE_LEFT")
        assert spin_until(ros_node, lambda: abs(truth.joints.get("rotate_joint", 9.0) - math.pi / 2) < 0.05, 5.0), \
            truth.joints
        subtask("release_soil", "release_angle_1")
        assert spin_until(ros_node, lambda: abs(truth.joints.get("vessel_joint", 9.0) - 0.6) < 0.05, 5.0), truth.joints
        subtask("release_soil", "release_angle_2")
        subtask("swing_align_to_heading", "none")  # reads no record: the nearer of 0 and pi from pi/2 - e
        assert spin_until(ros_node, lambda: min(abs(truth.joints.get("rotate_joint", 9.0)),
                                                abs(abs(truth.joints.get("rotate_joint", 9.0)) - math.pi)) < 0.05, 5.0)
        print(f"{name}: swung to pi/2, dumped at 0.6 rad, aligned to {truth.joints['rotate_joint']:.3f} rad")

    # the watchdog: driving towards FAR, the onboard PC dies; the converter stops the machine
    samples: list[tuple[float, float, float]] = []
    ros_node.create_subscription(PoseStamped, f"/sim/truth/{name}/pose",
                                 lambda m: samples.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                                                           m.pose.position.x, m.pose.position.y)), 50)
    ActionCall(ros_node, LeafNodeBase, f"/{name}/st_{prefix}_navigate_anywhere_deg",
               LeafNodeBase.Goal(model_name=name, record_name="FAR"))
    assert spin_until(ros_node, lambda: len(samples) > 5 and _speed(samples) > 0.3, 30.0), \
        (samples[-3:], pc.output[-2000:])
    pc.signal(signal.SIGKILL)
    killed_at = samples[-1][0]
    assert spin_until(ros_node, lambda: samples[-1][0] > killed_at + WATCHDOG_S + 2.0, 30.0)
    moving = [t for (t, *_), nxt in zip(samples, samples[1:], strict=False) if t > killed_at
              and math.hypot(nxt[1] - _[0], nxt[2] - _[1]) / max(nxt[0] - t, 1e-3) > 0.02]
    rest_after = (max(moving) - killed_at) if moving else 0.0
    # the converter neutralises after WATCHDOG_S; the tracks then stop with their hydraulics' dead time and lag
    drive = load_named(name).track_drive
    bound = WATCHDOG_S + drive.dead_time + 4.0 * drive.time_constant + 0.2
    print(f"{name}: at rest {rest_after:.2f} s (simulated) after its PC died (bound {bound:.2f} s); "
          f"{time.monotonic() - t0:.1f} s")
    assert rest_after < bound, rest_after
    assert f"{name}: watchdog: no cmd_vel" in plant.output, plant.output[-2000:]
