"""A second excavator type, the ZX120, through the converter, the plant and the kinematics.

Nothing ZX120-specific exists in code: config/machines/zx120.yaml (``type: excavator``), its COM3 bus
(config/can/zx120.yaml) and a plant YAML that places it (config/sim/zx120_plant.yaml). The test builds the
plant from that YAML, opens the ZX120's bus on python-can's ``virtual`` interface (one end for the plant,
one for the converter), drives the converter core with a ``front_cmd``, steps the plant, feeds every
state frame the plant puts on the bus back through the converter and checks: the arm moved in MuJoCo, the
converter's joint states are the plant's joints, and the ZX120 kinematics (tms_model) of those joint
states puts the bucket tip where MuJoCo has it, while the ZX200's kinematics would not.
"""

from __future__ import annotations

import math
import uuid

import can
import numpy as np
import pytest

from com3_can.bridge_core import VELOCITY, BridgeConfig, BridgeCore, JointStateOut
from com3_can.bus import load_bus_config, open_bus
from com3_can.profiles import PROFILES, converter_profile, profile_for
from sim_bridge.can_io import PlantCanIO
from sim_bridge.config import load_plant
from sim_bridge.plant import Plant
from sim_bridge.profiles import PLANT_PROFILES
from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics

FRONT = ["swing_joint", "boom_joint", "arm_joint", "bucket_joint"]
COMMAND = [0.3, -0.25, 0.35, 0.4]  # swing left, boom up, arm crowd, bucket curl [rad/s]


def test_zx120_is_an_excavator_by_its_description_only() -> None:
    assert profile_for("zx120") is profile_for("zx200") is PROFILES.get("excavator")
    cfg = BridgeConfig.load("zx120")
    assert cfg.machine_type == "excavator" and cfg.track_gauge == pytest.approx(1.99)
    assert BridgeCore(cfg, 0.0, converter_profile("zx120")).topics == frozenset({"front_cmd", "tracks_cmd", "cmd_vel"})
    spec = load_plant(config_path("sim", "zx120_plant.yaml"))
    assert spec.types == {"zx200": "excavator", "ic120": "crawler_dump", "zx120": "excavator"}
    assert spec.excavator == "zx200"  # the ZX200 still digs the soil


def test_registries_refuse_duplicates_and_name_the_known_types() -> None:
    for registry in (PROFILES, PLANT_PROFILES):
        with pytest.raises(ValueError, match="'excavator' is already registered"):
            registry.register("excavator", object)  # type: ignore[arg-type]
        with pytest.raises(ConfigError, match=r"unknown .*profile 'd61'; known: crawler_dump, dozer, excavator"):
            registry.get("d61")


def test_zx120_arm_moves_over_can_and_its_kinematics_match_the_plant() -> None:
    plant = Plant(load_plant(config_path("sim", "zx120_plant.yaml")))
    zx120 = plant.machines["zx120"]
    q0 = np.array(zx120.front.q)
    channel = f"zx120-{uuid.uuid4().hex}"
    plant_bus = open_bus({"interface": "virtual", "channel": channel})
    conv_bus = open_bus({"interface": "virtual", "channel": channel})
    try:
        io = PlantCanIO(plant, {"zx120": plant_bus}, watchdog_s=plant.spec.watchdog_s)
        core = BridgeCore(BridgeConfig.load("zx120", load_bus_config("zx120")), plant.time, converter_profile("zx120"))

        def send(txs) -> None:
            for tx in txs:
                conv_bus.send(can.Message(arbitration_id=tx.arbitration_id, data=tx.data, is_extended_id=True))

        joints: list[tuple[float, JointStateOut]] = []
        next_cmd = 0.0
        while plant.time < 3.5:  # the swing's dead time, then its inertia against the relief torque
            if plant.time + 1e-9 >= next_cmd:  # a controller's command stream (the converter's watchdog is 0.5 s)
                send(core.front_cmd(FRONT, VELOCITY, COMMAND, [], plant.time))
                next_cmd += 0.1
            send(core.tick(plant.time))
            io.poll()
            io.watchdog()
            plant.step()
            io.emit()
            while (msg := conv_bus.recv(timeout=0.0)) is not None:
                for out in core.on_frame(msg.arbitration_id, bytes(msg.data), stamp=plant.time):
                    if isinstance(out, JointStateOut):
                        joints.append((plant.time, out))
    finally:
        plant_bus.shutdown()
        conv_bus.shutdown()

    counters = io.counters()["zx120"]
    assert counters["received"] > 200 and counters["sent"] > 200, counters
    assert core.counters["rx_ok"] > 200 and not core.counters["cmd_rejected"], core.counters
    q = np.array(zx120.front.q)
    moved = q - q0
    # every joint moved its way, past the dead time: at least 0.8 s of the 3.5 s at the commanded speed
    for name, dq, v in zip(FRONT, moved, COMMAND, strict=True):
        assert math.copysign(1.0, dq) == math.copysign(1.0, v) and abs(dq) > 0.8 * abs(v), (name, moved)
    # the ZX200 on the same site did not move: the frames went to the ZX120 only
    digger = plant.excavator
    home = [digger.description.home_pose[n] for n in FRONT]
    assert digger.name == "zx200" and np.allclose(digger.front.q, home, atol=1e-3)

    t_js, js = joints[-1]
    assert js.name == tuple(FRONT)
    # the last state frame left the plant within one 10 ms cycle of the end; COM3 angle resolution 1e-4 rad
    q_bus = np.array(js.position)
    assert np.allclose(q_bus, q, atol=0.02), (q_bus, q)

    base = zx120.base
    c, s = math.cos(base.yaw), math.sin(base.yaw)

    def to_map(p: np.ndarray) -> np.ndarray:
        return np.array([base.x + c * p[0] - s * p[1], base.y + s * p[0] + c * p[1], zx120.z + p[2]])

    truth = plant.model.bucket_tip("zx120")
    tip = to_map(load_kinematics("zx120").tip_position(q_bus))
    assert np.linalg.norm(tip - truth) < 0.02, (tip, truth)  # bus quantisation and one 10 ms frame of motion
    wrong = to_map(load_kinematics("zx200").tip_position(q_bus))
    assert np.linalg.norm(wrong - truth) > 0.5, "the ZX200 geometry would fit too: the test proves nothing"
