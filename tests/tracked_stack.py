"""Start the IC120 stack as real processes: sim_plant + com3_bridge (over COM3 CAN) + our three nodes."""

from __future__ import annotations

import os
import random
import time

from tests.rosproc import executable, free_can_ports


def can_groups(domain: int) -> dict[str, dict]:
    """A unique udp_multicast group/port per machine bus for this test (never shared with other tests)."""
    rng = random.Random(os.getpid() * 7919 + domain + time.monotonic_ns())
    return {
        m: {"interface": "udp_multicast", "channel": f"239.75.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
            "port": port}
        for m, port in zip(("zx200", "ic120"), free_can_ports(domain, 2, rng), strict=True)
    }


def start_plant_and_bridge(procs, domain: int, *, speed: float = 1.0, extra_plant: list[str] = (),
                           bridge_sim_time: bool = False):
    """The plant and the IC120 bridge (wall clock by default, as on a machine; ``bridge_sim_time`` -> /clock)."""
    buses = can_groups(domain)
    plant_cmd = [executable("sim_bridge", "sim_plant"), "--ros-args", "-p", f"speed:={speed}"]
    for m, cfg in buses.items():
        plant_cmd += ["-p", f"{m}_can_interface:={cfg['interface']}", "-p", f"{m}_can_channel:={cfg['channel']}",
                      "-p", f"{m}_can_port:={cfg['port']}"]
    plant_cmd += list(extra_plant)
    plant = procs(plant_cmd, name="sim_plant")
    ic = buses["ic120"]
    bridge = procs([executable("com3_can", "com3_bridge"), "--ros-args", "-r", "__ns:=/ic120", "-p", "machine:=ic120",
                    "-p", f"can_interface:={ic['interface']}", "-p", f"can_channel:={ic['channel']}",
                    "-p", f"can_port:={ic['port']}", "-p", f"use_sim_time:={str(bridge_sim_time).lower()}"],
                   name="com3_bridge")
    return plant, bridge


def start_ours(procs, *, nodes=("ic120_localization", "ic120_navigator", "ic120_vessel"), params=()):
    pkgs = {"ic120_localization": "tms_rp", "ic120_navigator": "tms_rp", "ic120_vessel": "tms_rc"}
    out = {}
    for n in nodes:
        out[n] = procs([executable(pkgs[n], n), "--ros-args", "-r", "__ns:=/ic120", *params], name=n)
    return out
