"""Every excavator kind runs the arm controller with its own figures (no ROS).

The control choices are one file (config/tms_rc/excavator_arm_controller.yaml); the pump flow, each joint's
flow coefficient and the hydraulic delays were identified on the machine over its CAN bus
(config/tms_rc/identified/<name>.yaml, made by tms_rc_identify). The ZX120's controller holds the pumps to its
own identified flow (280 L/min), not the ZX200's (448 L/min); the tests read both figures from those files.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tms_common.config import config_path, load_yaml
from tms_common.errors import ConfigError
from tms_model.excavator import codes
from tms_model.excavator.kinematics import JOINTS, ExcavatorKinematics
from tms_model.excavator.targets import JointTarget
from tms_model.machines import EXCAVATOR, load_machine
from tms_rc.excavator.controller import (
    PLANNED_PUMP_SHARE,
    ArmController,
    load_controller_config,
    load_controller_settings,
    settings_path,
)
from tms_rc.excavator.plant import LagDeadTimePlant


def _excavators():
    machines = [load_machine(p.stem) for p in sorted(config_path("machines").glob("*.yaml"))]
    return [m for m in machines if m.type == EXCAVATOR]


EXCAVATORS = _excavators()


def test_both_excavator_kinds_are_found():
    assert {m.kind for m in EXCAVATORS} >= {"zx200", "zx120"}


@pytest.mark.parametrize("machine", EXCAVATORS, ids=lambda m: m.kind)
def test_the_controller_takes_its_kinds_identified_pump_flow_coefficients_and_delays(machine):
    """The controller's hydraulic figures are its kind's identified ones (config/tms_rc/identified/<kind>.yaml, made
    by tms_rc_identify over CAN), not the plant's description; the identified pump agrees with the spec sheet's."""
    cfg = load_controller_config(machine)
    data, _ = load_yaml(config_path("tms_rc", "identified", f"{machine.kind}.yaml"))
    assert cfg.pump_flow_lpm == data["pump_flow_lpm"]
    assert cfg.pump_flow_lpm == pytest.approx(machine.pump_flow, rel=0.15)  # measured against the spec sheet's pumps
    for i, name in enumerate(JOINTS):
        ident = data["joints"][name]
        assert cfg.lag_s[i] == pytest.approx(ident["lag_s"])
        assert cfg.dead_time_s[i] >= ident["dead_time_s"]  # plus the DDS legs the CAN measurement does not see
        assert cfg.flow_per_rad_s[i] == pytest.approx(max(ident["flow_lpm_per_rad_s"]))


def test_the_zx120_is_held_to_its_own_pump_not_the_zx200s():
    zx120, zx200 = load_machine("zx120"), load_machine("zx200")
    cfg120, cfg200 = load_controller_config(zx120), load_controller_config(zx200)
    assert cfg120.pump_flow_lpm < cfg200.pump_flow_lpm  # each kind's identified pumps
    cfg = dataclasses.replace(cfg120, use_acceleration_limits=False)
    kin = ExcavatorKinematics(zx120)
    ctl = ArmController(kin, cfg)
    # every joint asked at its velocity limit at once: the last guard scales the command to the ZX120's pumps
    u = ctl._enforce_hard_limits(np.array(kin.limits.velocity, dtype=float))
    assert float(np.sum(cfg.flow_per_rad_s * np.abs(u))) == pytest.approx(cfg120.pump_flow_lpm)
    # ... where the ZX200's pumps would let the same machine's joints draw more
    wider = ArmController(kin, dataclasses.replace(cfg, pump_flow_lpm=cfg200.pump_flow_lpm))
    u200 = wider._enforce_hard_limits(np.array(kin.limits.velocity, dtype=float))
    assert float(np.sum(cfg.flow_per_rad_s * np.abs(u200))) == pytest.approx(
        min(cfg200.pump_flow_lpm, float(np.sum(cfg.flow_per_rad_s * np.array(kin.limits.velocity)))))


def _identified_pump_lpm(name: str) -> float:
    data, _ = load_yaml(config_path("tms_rc", "identified", f"{name}.yaml"))
    return float(data["pump_flow_lpm"])


def _peak_flow_of_move(kin, cfg, dq):
    """Run one joint move on the lag + dead-time plant; (result, peak flow drawn [L/min], duration [s])."""
    ctl = ArmController(kin, cfg)
    q0 = np.array(kin.home, dtype=float)
    q1 = q0 + np.array(dq)
    assert kin.limits.violation(q1) is None
    plant = LagDeadTimePlant(cfg.dt, cfg.dead_time_s, cfg.lag_s, q0)
    q, v = q0.copy(), np.zeros(len(JOINTS))
    ctl.start([JointTarget(q1, "move")])
    flows = []
    for _ in range(int(20.0 / cfg.dt)):
        u = ctl.step(q, v)
        flows.append(float(np.sum(cfg.flow_per_rad_s * np.abs(ctl.u_prev))))
        q, v = plant.step(u)
        if ctl.status.result is not None:
            break
    return ctl.status, max(flows), len(flows) * cfg.dt


def test_a_zx120_move_of_boom_arm_and_bucket_is_paced_by_its_identified_pump():
    zx120 = load_machine("zx120")
    kin = ExcavatorKinematics(zx120)
    cfg = load_controller_config(zx120)
    pump = _identified_pump_lpm("zx120")  # config/tms_rc/identified/zx120.yaml, not the description's 265
    assert cfg.pump_flow_lpm == pump
    dq = [0.0, 0.3, -0.5, -0.8]  # boom, arm and bucket together: all three share the pumps
    # with pumps that never limit, the joints' own speed limits would draw far more than the ZX120's pump ...
    free, free_peak, free_s = _peak_flow_of_move(kin, dataclasses.replace(cfg, pump_flow_lpm=1.0e5), dq)
    assert free.result == codes.SUCCESS, free
    assert free_peak > 1.5 * pump, free_peak
    # ... so with its own pump the move is planned at PLANNED_PUMP_SHARE of it, never above it, and takes longer
    status, peak, duration = _peak_flow_of_move(kin, cfg, dq)
    assert status.result == codes.SUCCESS, status
    assert peak <= pump * (1 + 1e-3), peak
    assert peak >= 0.95 * PLANNED_PUMP_SHARE * pump, peak  # the pump, not the joints' speeds, paced the move
    assert duration > free_s + 0.5, (duration, free_s)


def test_the_settings_file_refuses_a_machine_figure_and_unknown_keys(tmp_path):
    text = settings_path().read_text()
    for extra, key in (("pump_flow_lpm: 424.0", "pump_flow_lpm"), ("stop_timeout: 3.0", "stop_timeout")):
        path = tmp_path / "ctl.yaml"
        path.write_text(f"{text}\n{extra}\n")
        with pytest.raises(ConfigError, match=rf"ctl.yaml:\d+: {key}: unknown key"):
            load_controller_settings(path)
