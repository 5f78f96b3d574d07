"""com3_can figures: codec encode+decode throughput, and converter latency ROS message -> frame on the bus.

* Throughput: every frame of both DBCs round-robin, encode then decode, one thread; frames/s per core
  from CPU time (and wall time). Goal >= 100,000 (13x the ~7,600 extended frames/s of 1 Mbit/s).
* Latency: com3_bridge in its own process (udp_multicast, own group/port, own ROS domain); this process
  publishes ``front_cmd`` at 50 Hz with a distinct velocity each time and a raw python-can peer thread
  timestamps the first Velocity_Cmd_1 carrying those bytes. Goal p99 < 2 ms.
"""

from __future__ import annotations

import random
import threading
import time

from tests.bench.stats import summary_ms
from tests.rosproc import Proc, executable, free_can_ports, isolated_domain, ros_env

N_CODEC = 200_000
N_LATENCY = 1000


def _throughput() -> str:
    from com3_can.codec import load_codec

    rng = random.Random(0)
    work = []
    for machine in ("zx200", "ic120"):
        codec = load_codec(machine)
        for name in codec.frame_names:
            values = {s.name: rng.uniform(s.minimum, s.maximum) for s in codec.signals(name)}
            work.append((codec, name, codec.frame_id(name), values))
    for codec, name, fid, values in work:  # warm-up
        codec.decode(fid, codec.encode(name, values))
    n = 0
    c0, w0 = time.process_time(), time.perf_counter()
    while n < N_CODEC:
        for codec, name, fid, values in work:
            codec.decode(fid, codec.encode(name, values))
        n += len(work)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return (f"codec encode+decode, {len(work)} frames of both DBCs round-robin: {n / cpu:,.0f} frames/s per core "
            f"(CPU time; {n / wall:,.0f} frames/s wall, n={n})")


def _latency() -> str:
    import can
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from com3_can.bus import open_bus
    from com3_can.codec import load_codec
    from com3_msgs.msg import JointCmd
    from tms_model.com3 import VELOCITY

    codec = load_codec("zx200")
    vid = codec.frame_id("Velocity_Cmd_1")
    with isolated_domain() as domain:
        group = f"239.74.{random.randrange(1, 255)}.{random.randrange(1, 255)}"
        port = free_can_ports(domain, 1)[0]
        bridge = Proc(
            [
                str(executable("com3_can", "com3_bridge")),
                "--ros-args",
                "-r",
                "__ns:=/zx200",
                "-p",
                "machine:=zx200",
                "-p",
                "can_interface:=udp_multicast",
                "-p",
                f"can_channel:={group}",
                "-p",
                f"can_port:={port}",
            ],
            ros_env(domain),
        )
        if not bridge.wait_for("com3_bridge ready", 30):
            bridge.kill()
            raise RuntimeError(f"com3_bridge did not start:\n{bridge.output}")
        bus = open_bus({"interface": "udp_multicast", "channel": group, "port": port})
        seen: dict[bytes, float] = {}
        stop = threading.Event()

        def listen() -> None:
            while not stop.is_set():
                msg: can.Message | None = bus.recv(0.05)
                if msg is not None and msg.arbitration_id == vid:
                    seen.setdefault(bytes(msg.data), time.monotonic())

        thread = threading.Thread(target=listen, daemon=True)
        thread.start()
        ctx = Context()
        rclpy.init(context=ctx, domain_id=domain)
        node = rclpy.create_node("bench_com3", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        pub = node.create_publisher(JointCmd, "/zx200/front_cmd", 10)
        sent: list[tuple[bytes, float]] = []
        try:
            deadline = time.monotonic() + 20
            while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.05)
            time.sleep(1.0)
            for i in range(N_LATENCY + 50):
                boom = 0.001 * ((i % 2000) + 1)  # distinct bytes each command (0.0005 rad/s LSB)
                values = codec.neutral("Velocity_Cmd_1")
                values["boom_target_anguler_velocity"] = boom
                data = codec.encode("Velocity_Cmd_1", values)
                msg = JointCmd(joint_name=["boom_joint"], control_type=VELOCITY, velocity=[boom])
                t = time.monotonic()
                pub.publish(msg)
                sent.append((data, t))
                ex.spin_once(timeout_sec=0.0)
                time.sleep(0.02)
            time.sleep(0.5)
        finally:
            stop.set()
            thread.join(timeout=1)
            bus.shutdown()
            ex.shutdown()
            node.destroy_node()
            rclpy.shutdown(context=ctx)
            bridge.kill()
        lat = [seen[d] - t for d, t in sent[50:] if d in seen]
        lost = len(sent) - 50 - len(lat)
        return f"converter latency front_cmd -> Velocity_Cmd_1 on udp_multicast: {summary_ms(lat)}, missing {lost}"


def main() -> None:
    print(_throughput(), flush=True)
    print(_latency(), flush=True)


if __name__ == "__main__":
    main()
