"""The CPU floor of simulated time: the plant and both CAN converters alone, machines idle, at the paper launch's speed.

What every paper-experiment run pays before any planning, control, localisation or sensing: ``sim_plant``
(MuJoCo, COM3 state frames at their DBC cycle times, ``/clock`` every 20 ms, truth and scans) and the two
``com3_bridge`` converters (state frames -> ROS, cyclic command frames), each its own process on this
benchmark's ROS domain and udp_multicast groups, with the paper launch's parameters. After a warm-up of
``RTF_FLOOR_WARMUP_S``, CPU (``/proc``, all threads) and simulated time (``/clock``) are sampled over
``RTF_FLOOR_S`` seconds. Printed: the real-time factor reached (``RTF_FLOOR_SPEED`` requested, default 3),
each process's and the total CPU in core-seconds per simulated second, and what that total leaves of the
machine's cores for everything else at that speed.

Second figure: python-can's udp_multicast receive cost per frame on this machine (one sender process at
3,000 frames/s in bursts of 12, as the plant sends; CPU of the receiving thread per frame received): every
frame on a bus is received by every other socket in its group, and by the sender's own.
"""

from __future__ import annotations

import os
import random
import sys
import threading
import time

from tests.rosproc import Proc, executable, free_can_ports, isolated_domain, ros_env

SPEED = float(os.environ.get("RTF_FLOOR_SPEED", "3.0"))
SECONDS = float(os.environ.get("RTF_FLOOR_S", "30"))
WARMUP_S = float(os.environ.get("RTF_FLOOR_WARMUP_S", "10"))
RX_FRAMES_PER_S = 3000


def _group(rng: random.Random) -> str:
    return f"239.77.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}"


def _floor() -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from tms_launch.launcher import process_cpu_seconds

    rng = random.Random(time.monotonic_ns())
    with isolated_domain() as domain:
        env = ros_env(domain, RMW_FASTRTPS_PUBLICATION_MODE="ASYNCHRONOUS")  # as the paper launch gives the plant
        ports = free_can_ports(domain, 2, rng)
        buses = {"zx200": (_group(rng), ports[0]), "ic120": (_group(rng), ports[1])}
        plant_args = [str(executable("sim_bridge", "sim_plant")), "--ros-args", "-p", f"speed:={SPEED}",
                      "-p", "clock_period_s:=0.02", "-p", "config:=config/sim/paper_plant.yaml"]
        for machine, (channel, port) in buses.items():
            plant_args += ["-p", f"{machine}_can_interface:=udp_multicast", "-p", f"{machine}_can_channel:={channel}",
                           "-p", f"{machine}_can_port:={port}"]
        procs = {"sim_plant": Proc(plant_args, env, name="sim_plant")}
        for machine, (channel, port) in buses.items():
            extra = ["-p", "odom_period_s:=0.02"] if machine == "ic120" else []
            procs[f"{machine} com3_bridge"] = Proc(
                [str(executable("com3_can", "com3_bridge")), "--ros-args", "-r", f"__ns:=/{machine}",
                 "-p", f"machine:={machine}", "-p", "can_interface:=udp_multicast", "-p", f"can_channel:={channel}",
                 "-p", f"can_port:={port}", "-p", "use_sim_time:=true", "-p", "joint_states_period_s:=0.02", *extra],
                env, name=machine)
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node("rtf_floor_probe", context=context)
        sim_now = [0.0]
        node.create_subscription(
            Clock,
            "/clock",
            lambda m: sim_now.__setitem__(0, m.clock.sec + m.clock.nanosec * 1e-9),
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
        )
        stop = threading.Event()
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin() -> None:
            while not stop.is_set():
                executor.spin_once(timeout_sec=0.1)

        spinner = threading.Thread(target=spin, daemon=True)
        spinner.start()
        try:
            for name, proc in procs.items():
                ready = "sim_plant: running" if name == "sim_plant" else "com3_bridge ready"
                if not proc.wait_for(ready, 90):
                    raise RuntimeError(f"{name} did not start:\n{proc.output[-2000:]}")
            time.sleep(WARMUP_S)
            cpu0 = {name: process_cpu_seconds(p.popen.pid) or 0.0 for name, p in procs.items()}
            sim0, wall0 = sim_now[0], time.monotonic()
            time.sleep(SECONDS)
            cpu1 = {name: process_cpu_seconds(p.popen.pid) or 0.0 for name, p in procs.items()}
            sim1, wall1 = sim_now[0], time.monotonic()
        finally:
            stop.set()
            spinner.join(2.0)
            for proc in procs.values():
                proc.kill()
            executor.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=context)
    sim, wall = sim1 - sim0, wall1 - wall0
    if sim <= 0:
        raise RuntimeError("simulated time did not advance (no /clock)")
    cores = os.cpu_count() or 1
    print(f"plant + 2 converters, machines idle, speed {SPEED:g} requested: real-time factor {sim / wall:.2f} "
          f"({sim:.1f} s simulated in {wall:.1f} s)")
    total = 0.0
    for name in procs:
        used = cpu1[name] - cpu0[name]
        total += used
        print(f"  {name:18s} {used / sim:.3f} core-s per simulated s ({used / wall * 100:5.1f} % of a core)")
    print(f"  {'total':18s} {total / sim:.3f} core-s per simulated s: at {SPEED:g}x that is {total / sim * SPEED:.2f} "
          f"of this machine's {cores} cores, {cores - total / sim * SPEED:.2f} left for the other nodes")


def _sender(channel: str, port: int) -> None:
    import can

    from com3_can.bus import open_bus

    bus = open_bus({"interface": "udp_multicast", "channel": channel, "port": port})
    msg = can.Message(arbitration_id=0x18FF0010, data=bytes(8), is_extended_id=True)
    burst, next_at = 12, time.perf_counter()
    while True:
        for _ in range(burst):
            bus.send(msg)
        next_at += burst / RX_FRAMES_PER_S
        delay = next_at - time.perf_counter()
        if delay > 0:
            time.sleep(delay)


def _receive_cost() -> None:
    from com3_can.bus import open_bus

    rng = random.Random(time.monotonic_ns())
    with isolated_domain() as domain:
        channel, port = _group(rng), free_can_ports(domain, 1, rng)[0]
        bus = open_bus({"interface": "udp_multicast", "channel": channel, "port": port})
        sender = Proc([sys.executable, "-m", "tests.bench.bench_rtf_floor", "send", channel, str(port)],
                      ros_env(domain), name="sender")
        try:
            end = time.monotonic() + 10
            while bus.recv(0.5) is None and time.monotonic() < end:
                pass
            n, cpu0, w0 = 0, time.thread_time(), time.monotonic()
            while time.monotonic() - w0 < 5.0:
                if bus.recv(0.1) is not None:
                    n += 1
            cpu, wall = time.thread_time() - cpu0, time.monotonic() - w0
        finally:
            sender.kill()
            bus.shutdown()
    if n == 0:
        raise RuntimeError("no frames received")
    print(f"python-can udp_multicast receive: {cpu / n * 1e6:.1f} us of CPU per frame ({n / wall:,.0f} frames/s, "
          f"receiving thread at {cpu / wall * 100:.1f} % of a core)")


def main() -> None:
    _floor()
    _receive_cost()


if __name__ == "__main__":
    if sys.argv[1:2] == ["send"]:
        _sender(sys.argv[2], int(sys.argv[3]))
    else:
        main()
