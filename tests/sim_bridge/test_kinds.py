"""The kinds beyond the paper's (MST-110CR, MST-2200VD, D37PXi) over COM3 CAN into the MuJoCo plant.

One world from ``config/sim/kinds_plant.yaml`` (the paper's ZX200 and IC120 plus the three kinds). Each kind's
converter core (com3_can) and the plant (sim_bridge) talk over real python-can buses (``virtual`` interface, one
channel per machine, as the composed layout's plant container links them) and MuJoCo computes the kinematics. The
tests command as a controller would (ROS commands into the converter at 10 Hz) and check the machine through the
converter's outputs and the plant's truth: it drives, the MSTs swing and dump where the swung vessel points, the
dozer's blade lifts and cuts, and every kind comes to rest when the commands stop (converter watchdog) and when the
converter falls silent (plant watchdog).
"""

from __future__ import annotations

import math
import uuid
from pathlib import Path

import can
import pytest

from com3_can.bridge_core import POSITION, BridgeConfig, BridgeCore, JointStateOut, OdomOut
from com3_can.bus import load_bus_config, open_bus
from com3_can.profiles import converter_profile
from sim_bridge.can_io import PlantCanIO
from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.plant import Plant
from tms_common.config import config_path

KINDS = ("mst110cr", "mst2200vd", "d37pxi")


class Rig:
    """The plant of ``kinds_plant.yaml`` and one converter core per kind, linked by virtual CAN buses."""

    def __init__(self) -> None:
        self.plant = Plant(load_plant(config_path("sim", "kinds_plant.yaml")))
        self.buses: list[can.BusABC] = []
        plant_buses, self.conv, self.cores = {}, {}, {}
        for kind in KINDS:
            channel = f"{kind}-{uuid.uuid4().hex}"
            plant_buses[kind] = self._open(channel)
            self.conv[kind] = self._open(channel)
            self.cores[kind] = BridgeCore(BridgeConfig.load(kind, load_bus_config(kind)), 0.0, converter_profile(kind))
        self.io = PlantCanIO(self.plant, plant_buses, watchdog_s=self.plant.spec.watchdog_s)
        self.joints: dict[str, JointStateOut] = {}
        self.odom: dict[str, OdomOut] = {}
        self.converters_on = True

    def _open(self, channel: str) -> can.BusABC:
        bus = open_bus({"interface": "virtual", "channel": channel})
        self.buses.append(bus)
        return bus

    def _send(self, kind: str, txs) -> None:
        for tx in txs:
            self.conv[kind].send(can.Message(arbitration_id=tx.arbitration_id, data=tx.data, is_extended_id=True))

    def run(self, seconds: float, commands=None) -> None:
        """Step the plant ``seconds``; ``commands(core_of, now)`` is called at 10 Hz (a controller's stream)."""
        end = self.plant.time + seconds
        next_cmd = self.plant.time
        while self.plant.time < end - 1e-9:
            now = self.plant.time
            if commands is not None and now + 1e-9 >= next_cmd:
                for kind, txs in commands(self.cores, now).items():
                    self._send(kind, txs)
                next_cmd += 0.1
            if self.converters_on:
                for kind, core in self.cores.items():
                    self._send(kind, core.tick(now))
            self.io.poll()
            self.io.watchdog()
            self.plant.step()
            self.io.emit()
            for kind, bus in self.conv.items():
                while (msg := bus.recv(timeout=0.0)) is not None:
                    for out in self.cores[kind].on_frame(msg.arbitration_id, bytes(msg.data), stamp=self.plant.time):
                        if isinstance(out, JointStateOut):
                            self.joints[kind] = out
                        elif isinstance(out, OdomOut):
                            self.odom[kind] = out

    def joint(self, kind: str, name: str) -> float:
        js = self.joints[kind]
        return js.position[js.name.index(name)]

    def close(self) -> None:
        for bus in self.buses:
            bus.shutdown()


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.close()


def test_one_world_holds_every_kind_each_on_its_dbc(rig: Rig) -> None:
    spec = rig.plant.spec
    assert spec.types == {"zx200": "excavator", "ic120": "crawler_dump", "mst110cr": "crawler_dump",
                          "mst2200vd": "crawler_dump", "d37pxi": "dozer"}
    assert spec.dbcs["d37pxi"] == "dozer_com3.dbc" and spec.dbcs["mst110cr"] == "crawler_carrier_com3.dbc"
    assert (spec.excavator, spec.carrier) == ("zx200", "ic120")  # the paper's soil experiment is unchanged
    xml = rig.plant.model.xml
    for joint in ("mst110cr_rotate_joint", "mst110cr_vessel_joint", "mst2200vd_rotate_joint", "d37pxi_lift_joint",
                  "ic120_vessel_joint"):
        assert f'name="{joint}"' in xml
    assert 'name="ic120_rotate_joint"' not in xml
    assert rig.io.sides["d37pxi"].codec.frame_names == rig.cores["d37pxi"].codec.frame_names


@pytest.mark.parametrize("kind", KINDS)
def test_drives_turns_and_comes_to_rest_on_both_watchdogs(rig: Rig, kind: str) -> None:
    m = rig.plant.machines[kind]
    x0, y0, yaw0 = m.base.x, m.base.y, m.base.yaw
    rig.run(4.0, lambda cores, now: {kind: cores[kind].cmd_vel(0.8, 0.0, now)})
    assert m.base.x - x0 > 0.8 * 0.8 * (4.0 - 1.5) and abs(m.base.y - y0) < 0.05  # forward along +x (yaw 0)
    assert rig.odom[kind].v == pytest.approx(0.8, abs=0.02)  # the converter's odometry from Track_Velocity
    js = rig.joints[kind]
    assert js.name[-2:] == ("left_track", "right_track") and js.velocity[-1] == pytest.approx(0.8, abs=0.02)
    # a left turn on the spot
    rig.run(3.0, lambda cores, now: {kind: cores[kind].cmd_vel(0.0, 0.3, now)})
    assert m.base.yaw - yaw0 > 0.3
    # commands stop: the converter's watchdog sends neutral frames, the tracks stop
    rig.run(0.3)
    assert not rig.cores[kind].counters["watchdog_travel"]
    rig.run(3.5)
    assert rig.cores[kind].counters["watchdog_travel"] == 1 and m.base.at_rest()
    assert "watchdog: no cmd_vel" in rig.cores[kind].diagnostics(10.0).message
    # again, and now the converter itself falls silent: the plant's watchdog stops the machine
    rig.run(2.0, lambda cores, now: {kind: cores[kind].cmd_vel(0.5, 0.0, now)})
    assert not m.base.at_rest()
    rig.converters_on = False
    rig.run(3.5)
    assert rig.io.counters()[kind]["watchdog_trips"] >= 1 and m.base.at_rest()


@pytest.mark.parametrize("kind", ["mst110cr", "mst2200vd"])
def test_mst_swings_to_the_commanded_angle_and_dumps_where_the_vessel_points(rig: Rig, kind: str) -> None:
    plant = rig.plant
    mst = plant.machines[kind]
    target = math.pi / 2  # the vessel to the right of the tracks' rear: it tips toward -y
    rig.run(10.0, lambda cores, now: {kind: cores[kind].rot_dump_cmd(["rotate_joint", "dump_joint"], POSITION,
                                                                    [target, 0.0], now)})
    assert rig.joint(kind, "rotate_joint") == pytest.approx(target, abs=0.02)  # over CAN, from Swing_Angle
    assert mst.swing_angle == pytest.approx(target, abs=0.02) and abs(mst.swing_rate) < 0.01
    assert plant.machines["ic120"].swing_angle == 0.0  # the IC120 has no swing and was not commanded
    # load the vessel, then raise it with the swing held: the soil leaves onto a pile where the swung vessel points
    plant.soil.vessels[kind] = 3.0
    before = plant.total_volume()
    px, py = plant.dump_point(kind)
    s = mst.vessel
    assert (px, py) == pytest.approx((mst.base.x, mst.base.y + s.hinge_xyz[0] - s.dump_distance), abs=0.05)
    h0 = plant.ground.height(px, py)
    unswung = (mst.base.x + s.hinge_xyz[0] - s.dump_distance, mst.base.y)
    top = s.max_angle
    rig.run(8.0, lambda cores, now: {kind: cores[kind].rot_dump_cmd(["dump_joint"], POSITION, [top], now)})
    assert rig.joint(kind, "vessel_joint") == pytest.approx(top, abs=0.02)
    assert plant.soil.vessels[kind] == pytest.approx(0.0, abs=1e-9)  # all of it left the vessel
    assert plant.ground.height(px, py) - h0 > 0.3  # 3 m^3 on a 1.2 m disc
    assert plant.ground.height(*unswung) == pytest.approx(0.0, abs=1e-9)  # nothing where the unswung vessel points
    assert plant.total_volume() == pytest.approx(before, abs=1e-6)
    # the swing held while only dump_joint was commanded
    assert mst.swing_angle == pytest.approx(target, abs=0.02)


def test_d37pxi_blade_lifts_over_can_and_cuts_the_mound(rig: Rig) -> None:
    plant = rig.plant
    dz = plant.machines["d37pxi"]
    lo, hi = dz.lift.lower, dz.lift.upper
    rig.run(3.0, lambda cores, now: {"d37pxi": cores["d37pxi"].blade_cmd(["lift_joint"], POSITION, [lo], [], now)})
    assert rig.joint("d37pxi", "lift_joint") == pytest.approx(lo, abs=0.01)  # raised (URDF: - = up)
    assert plant.blade_edge("d37pxi")[2] > 0.5
    # blade down 0.1 rad (edge ~0.16 m below the ground) and drive into the mound
    before = plant.total_volume()
    rig.run(12.0, lambda cores, now: {"d37pxi": cores["d37pxi"].blade_cmd(["lift_joint"], POSITION, [0.1], [], now)
                                      + cores["d37pxi"].cmd_vel(0.5, 0.0, now)})
    assert 0.0 < hi and rig.joint("d37pxi", "lift_joint") == pytest.approx(0.1, abs=0.01)
    assert plant.soil.blades["d37pxi"] > 0.5  # soil cut by the blade
    # lift and back out of the mound: once the edge is above the surface the load stays ahead of it
    rig.run(6.0, lambda cores, now: {"d37pxi": cores["d37pxi"].blade_cmd(["lift_joint"], POSITION, [lo], [], now)
                                     + cores["d37pxi"].cmd_vel(-0.5, 0.0, now)})
    assert plant.soil.blades["d37pxi"] == 0.0 and plant.soil.pushed > 0.5
    assert plant.total_volume() == pytest.approx(before, abs=1e-6)


def _plant_yaml(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "plant.yaml"
    base = config_path("sim", "kinds_plant.yaml").read_text()
    soil = base[base.index("site: site.yaml"):].split("initial_poses:")[0]
    tail = base[base.index("soil:"):]
    path.write_text(body + soil + tail)
    return path


def test_a_plant_of_one_kind_is_valid_only_without_the_soil_experiment(tmp_path: Path) -> None:
    body = "machines: {d37pxi: machines/d37pxi.yaml}\n"
    poses = "initial_poses: {d37pxi: [0.0, 0.0, 0.0]}\n"
    with pytest.raises(SimConfigError, match=r"plant.yaml:1: machines: the site needs an excavator and a crawler "
                                             r"carrier.*experiment: none"):
        load_plant(_plant_yaml(tmp_path, body + poses))
    spec = load_plant(_plant_yaml(tmp_path, body + "experiment: none\n" + poses))
    assert spec.types == {"d37pxi": "dozer"} and spec.excavator == spec.carrier == ""
    plant = Plant(spec)
    for _ in range(20):
        plant.step()
    assert math.isnan(plant.bucket_tip()[0]) and plant.total_volume() == pytest.approx(plant.initial_volume)
    with pytest.raises(SimConfigError, match=r"experiment: expected one of \['dig_and_carry', 'none'\]"):
        load_plant(_plant_yaml(tmp_path, body + "experiment: dig\n" + poses))
