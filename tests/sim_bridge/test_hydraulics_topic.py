"""The running ``sim_plant`` publishes the digging excavator's chamber and pump pressures on
``/sim/truth/<excavator>/hydraulics`` (labelled Float64MultiArray, MPa), and they follow the machine: the boom's bottom
chamber holds the front at rest, and raising the boom over CAN puts the pump above that holding pressure (load-sensing:
the fed chamber's pressure plus the margin)."""

from __future__ import annotations

import time

import pytest
from std_msgs.msg import Float64MultiArray

from sim_bridge.config import load_plant

pytestmark = pytest.mark.integration

SPEC = load_plant()
ZX = SPEC.description(SPEC.excavator)
LABELS = "boom_bottom,boom_rod,arm_bottom,arm_rod,bucket_bottom,bucket_rod,swing_a,swing_b,pump,relief".split(",")


def test_hydraulics_topic_is_labelled_and_follows_the_boom(start_plant, ros_node):
    plant = start_plant(speed=1.0)
    got: list[tuple[str, list[float]]] = []
    ros_node.create_subscription(
        Float64MultiArray, f"/sim/truth/{SPEC.excavator}/hydraulics",
        lambda m: got.append((m.layout.dim[0].label if m.layout.dim else "", list(m.data))), 10)

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ros_node.executor_for_test.spin_once(timeout_sec=0.02)

    deadline = time.monotonic() + 30
    while not got and time.monotonic() < deadline:
        spin(0.1)
    assert got, f"no /sim/truth/{SPEC.excavator}/hydraulics within 30 s; sim_plant said:\n{plant.proc.output}"
    spin(2.0)  # the front settles on its cylinders from the start pose
    label, data = got[-1]
    assert label.split(",") == LABELS
    assert len(data) == len(LABELS)
    rest = dict(zip(LABELS, data, strict=True))
    relief = ZX.cylinders.relief_mpa
    print("\nat rest [MPa]: " + ", ".join(f"{k} {v:.2f}" for k, v in rest.items()))
    assert rest["relief"] == pytest.approx(relief)
    # the boom's bottom chamber carries the front's weight; its rod side is at tank
    assert 1.0 < rest["boom_bottom"] < relief, rest
    assert rest["boom_rod"] < rest["boom_bottom"], rest
    assert all(0.0 < v <= relief + 1e-6 for v in data), rest

    # raise the boom (negative boom speed: up) through COM3 CAN: the pump follows the fed bottom chamber
    plant.zx200.command("Velocity_Cmd_1", boom_target_anguler_velocity=-0.08)
    got.clear()
    spin(3.0)
    plant.zx200.silence()
    assert got, "no hydraulics while the boom moved"
    moving = [dict(zip(LABELS, d, strict=True)) for _, d in got]
    peak = max(moving, key=lambda v: v["pump"])
    print(f"raising: pump {peak['pump']:.2f} MPa, boom bottom {peak['boom_bottom']:.2f} MPa")
    assert peak["pump"] > peak["boom_bottom"] > 1.0, peak
    assert peak["pump"] > rest["pump"] + 1.0, (peak, rest)
