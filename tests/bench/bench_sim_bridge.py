"""sim_bridge: plant speed (real-time factor) and the period jitter of its 10 ms COM3 frames.

1. Core plant, both machines and soil, a scripted dig cycle on the ZX200 while the IC120 drives:
   simulated seconds per wall second (goal >= 50x).
2. The same with the COM3 CAN I/O (all state frames encoded at their DBC cycles onto virtual buses).
3. ``sim_plant`` as a separate process in real-time mode on udp_multicast: arrival period of the 10 ms
   ``Front_Angle`` frames measured in this process (p99 |period - 10 ms|; goal < 2 ms).
"""

from __future__ import annotations

import os
import time

from sim_bridge.plant import Plant
from sim_bridge.scenario import DIG_CYCLE, pose_reached, servo_velocity
from tests.bench.stats import percentile, summary_ms
from tests.rosproc import Proc, executable, free_can_ports, isolated_domain, ros_env

SIM_SECONDS = 120.0


def _drive(plant: Plant, io=None) -> float:
    names = plant.excavator.front.names
    plant.carrier.set_centre_velocity(1.0, 0.1)
    steps = int(SIM_SECONDS / plant.dt)
    k = 0
    start = time.perf_counter()
    for _ in range(steps):
        q = dict(zip(names, plant.excavator.front.q, strict=True))
        target = DIG_CYCLE[k % len(DIG_CYCLE)]
        if pose_reached(q, target, tol=0.05):
            k += 1
        plant.excavator.set_front_velocity(servo_velocity(q, target))
        if io is not None:
            io.poll()
            io.watchdog()
        plant.step()
        if io is not None:
            io.emit()
    return time.perf_counter() - start


def _core() -> str:
    plant = Plant()
    plant.set_truth("ic120", 1.2, 6.5, 0.0, {"vessel_joint": 0.0})
    wall = _drive(plant)
    return (f"plant core (ZX200 dig cycle + IC120 driving + soil, dt {plant.dt * 1e3:.0f} ms): "
            f"{SIM_SECONDS:.0f} s simulated in {wall:.2f} s = {SIM_SECONDS / wall:.0f}x real time "
            f"({wall / (SIM_SECONDS / plant.dt) * 1e6:.0f} us/step; dug {plant.soil.dug:.2f} m^3)")


def _with_can() -> str:
    import can

    from sim_bridge.can_io import PlantCanIO

    plant = Plant()
    buses = {m: can.Bus(interface="virtual", channel=f"bench_{m}", ignore_config=True) for m in ("zx200", "ic120")}
    io = PlantCanIO(plant, buses)
    try:
        wall = _drive(plant, io)
    finally:
        for b in buses.values():
            b.shutdown()
    sent = sum(c.get("sent", 0) for c in io.counters().values())
    return (f"plant + COM3 CAN I/O (virtual bus, {sent / SIM_SECONDS:.0f} state frames per simulated s): "
            f"{SIM_SECONDS / wall:.1f}x real time")


def _jitter(seconds: float = 20.0) -> str:
    from com3_can.bus import open_bus
    from com3_can.codec import load_codec

    codec = load_codec("zx200")
    fid = codec.frame_id("Front_Angle")
    with isolated_domain() as domain:
        port = free_can_ports(domain, 1)[0]
        cfg = {"interface": "udp_multicast", "channel": f"239.76.1.{domain}", "port": port}
        bus = open_bus(cfg)
        proc = Proc(
            [
                str(executable("sim_bridge", "sim_plant")),
                "--ros-args",
                "-p",
                "speed:=1.0",
                "-p",
                "realtime_priority:=20",
                "-p",
                f"zx200_can_channel:={cfg['channel']}",
                "-p",
                f"zx200_can_port:={port}",
                "-p",
                f"ic120_can_channel:=239.76.2.{domain}",
                "-p",
                f"ic120_can_port:={port + 1}",
            ],
            ros_env(domain),
        )
        stamps: list[float] = []
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(20))  # the receiver is measured too
        except OSError:
            pass
        try:
            if not proc.wait_for("sim_plant: running", 60):
                raise RuntimeError(f"sim_plant did not start: {proc.output}")
            warm = time.monotonic() + 2.0
            end = warm + seconds
            while time.monotonic() < end:
                msg = bus.recv(0.1)
                if msg is not None and msg.arbitration_id == fid and time.monotonic() >= warm:
                    stamps.append(time.monotonic())
        finally:
            proc.kill()
            bus.shutdown()
    periods = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
    dev = [abs(p - 0.010) for p in periods]
    return (f"real-time mode, Front_Angle (10 ms) arrival period over {seconds:.0f} s: {summary_ms(periods)}; "
            f"|period - 10 ms| p99 {percentile(dev, 99) * 1e3:.3f} ms, max {max(dev) * 1e3:.3f} ms; "
            f"rate {len(stamps) / seconds:.1f} Hz")


def main() -> None:
    print(_core(), flush=True)
    print(_with_can(), flush=True)
    print(_jitter(), flush=True)


if __name__ == "__main__":
    main()
