"""The converter's site watchdog (BridgeCore, no ROS): a machine PC cut off from the site stops its machine.

On a machine PC the controller keeps commanding when the site network is cut, so the per-channel command
watchdog never fires; the site heartbeat (the subtask servers') is what goes silent (docs/deployment.md).
"""

from __future__ import annotations

import pytest

from com3_can.bridge_core import VELOCITY, BridgeConfig, BridgeCore
from com3_can.errors import Com3CommandError
from com3_can.profiles import converter_profile
from tms_common.errors import ConfigError

NEUTRAL_VELOCITY_CMD_1 = "007d" * 4


def zx(site_timeout_s: float) -> BridgeCore:
    return BridgeCore(BridgeConfig.load("zx200", site_timeout_s=site_timeout_s), 0.0, converter_profile("zx200"))


def velocity_frame(txs) -> str | None:
    return next((t.data.hex() for t in txs if t.name == "Velocity_Cmd_1"), None)


def test_silent_site_latches_emg_stop_while_commands_keep_coming() -> None:
    core = zx(0.3)
    core.site_heartbeat(0.0)
    t = 0.0
    while t < 0.29:  # commands every 20 ms, heartbeat stops at 0: within the timeout nothing happens
        core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=t)
        assert core.site_check(t) == []
        t += 0.02
    assert not core.emg_latched
    assert core.site_check(0.31) == [] and not core.emg_latched  # expired once: confirmed at the next check
    txs = core.site_check(0.33)
    assert core.emg_latched and velocity_frame(txs) == NEUTRAL_VELOCITY_CMD_1
    assert core.emg_reason.startswith("site link lost: no site heartbeat for 0.33 s (> 0.3 s)")
    with pytest.raises(Com3CommandError, match="emg_stop is latched"):
        core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.32)
    diag = core.diagnostics(0.4)
    assert diag.level == 2 and diag.message.startswith("site link lost") and ("site_lost", "1") in diag.values


def test_a_heartbeat_handled_between_the_two_checks_prevents_the_latch() -> None:
    core = zx(0.3)
    core.site_heartbeat(0.0)
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.45)
    core.site_check(0.5)  # the executor was starved: the check runs before the queued heartbeats
    core.site_heartbeat(0.5)
    assert core.site_check(0.52) == [] and not core.emg_latched
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.85)
    assert core.site_check(0.9) == [] and core.site_check(0.95) != [] and core.emg_latched


def test_silence_while_idle_does_not_latch_a_command_during_it_does() -> None:
    core = zx(0.3)
    core.site_heartbeat(0.0)
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.0)
    core.tick(0.6)  # the command watchdog: the channel went neutral, the machine is idle
    assert core.site_check(1.0) == [] and core.site_check(1.02) == [] and not core.emg_latched
    core.front_cmd(["arm_joint"], VELOCITY, [0.0], [], now=1.025)  # a controller holding still: not driven
    assert core.site_check(1.026) == [] and not core.emg_latched
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=1.03)  # a controller starts while the site is silent
    assert velocity_frame(core.site_check(1.04)) == NEUTRAL_VELOCITY_CMD_1 and core.emg_latched


def test_heartbeat_return_does_not_clear_only_emg_stop_false_does() -> None:
    core = zx(0.3)
    core.site_heartbeat(0.0)
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.4)
    core.site_check(0.5)
    core.site_check(0.52)
    assert core.emg_latched
    core.site_heartbeat(0.6)  # the link is back: the machine still must not move by itself
    core.site_check(0.7)
    core.site_check(0.72)
    assert core.emg_latched
    core.emg_stop(False, 0.8)
    assert not core.emg_latched and core.emg_reason == ""
    core.front_cmd(["arm_joint"], VELOCITY, [0.3], [], now=0.81)  # accepted again
    core.site_heartbeat(0.8)
    core.site_check(1.0)
    core.site_check(1.02)
    assert not core.emg_latched


def test_unarmed_until_a_first_heartbeat_and_off_by_default() -> None:
    core = zx(0.3)
    core.site_check(5.0)
    core.site_check(5.1)
    assert not core.emg_latched  # a converter started before its site waits for it
    off = zx(0.0)
    off.site_heartbeat(0.0)
    off.site_check(60.0)
    off.site_check(60.1)
    assert not off.emg_latched


def test_bad_site_timeout_is_refused_naming_it() -> None:
    with pytest.raises(ConfigError, match="site_timeout_s must be >= 0"):
        zx(-1.0)
