"""CPU per executor wake of a converter-shaped node on simulated time: rclpy's defaults, polled QoS events, relayed
/clock.

A /clock publisher process advances simulated time 10 ms every 5 ms of wall time (200 messages/s); the node
under test (its own process, ``use_sim_time``) has the com3_bridge's shape (5 publishers, 7 subscriptions on
idle topics) and a 20 ms timer, so it wakes about 300 times a second. Its CPU over ``EXEC_BENCH_S`` seconds
is measured from its own rusage, with rclpy's defaults (``default``), after
:func:`tms_common.qos_events.defer_qos_incompatibility_events` (``deferred``), and after that and
:func:`tms_common.sim_clock.relay_clock` (``relayed``: /clock taken by a helper thread, the executor wakes for
the timer only), and on the ``events`` executor (:class:`tms_common.rclpy_compat.SlicedEventsExecutor`, which
serves /clock and the QoS event handlers itself: nothing is parked), alternating ``EXEC_BENCH_ROUNDS`` times so
all see the same machine load. Printed: CPU % of a core, ms per wake (timer callbacks + /clock messages), and
each variant's ratio to the default.

Then the executors alone: the same node shape on wall time with a 100 Hz timer and nothing else, on the
SingleThreadedExecutor (``timer100_single``) and on ``events`` (``timer100_events``): CPU per timer callback and
their ratio.
"""

from __future__ import annotations

import os
import re
import sys
import time

from tests.rosproc import Proc, isolated_domain, ros_env

SECONDS = float(os.environ.get("EXEC_BENCH_S", "10"))
ROUNDS = int(os.environ.get("EXEC_BENCH_ROUNDS", "2"))


def _clock_publisher() -> None:
    import rclpy
    from rosgraph_msgs.msg import Clock

    rclpy.init()
    node = rclpy.create_node("bench_clock")
    pub = node.create_publisher(Clock, "/clock", 10)
    sim_ns = [0]

    def tick() -> None:
        sim_ns[0] += 10_000_000
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(sim_ns[0], 1_000_000_000)
        pub.publish(msg)

    node.create_timer(0.005, tick)
    print("clock publishing", flush=True)
    rclpy.spin(node)


def _node_under_test(variant: str) -> None:
    import resource

    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.task import Future
    from std_msgs.msg import Float64

    from tms_common.node import make_executor
    from tms_common.qos_events import defer_qos_incompatibility_events
    from tms_common.sim_clock import relay_clock

    wall_timer = variant.startswith("timer100")
    rclpy.init()
    node = rclpy.create_node("bench_wake", parameter_overrides=[Parameter("use_sim_time", value=not wall_timer)])
    for i in range(5):
        node.create_publisher(Float64, f"out_{i}", 10)
    for i in range(7):
        node.create_subscription(Float64, f"in_{i}", lambda _msg: None, 10)
    fired = [0]
    node.create_timer(0.01 if wall_timer else 0.02, lambda: fired.__setitem__(0, fired[0] + 1))
    moved = defer_qos_incompatibility_events(node) if variant in ("deferred", "relayed") else 0
    if variant == "relayed":
        relay_clock(node)
    ex = make_executor("events" if variant.endswith("events") else "single")
    ex.add_node(node)

    def spin_for(seconds: float) -> None:
        if variant.endswith("events"):  # as its spin() does: one bounded wait, callbacks run inside it
            ex.spin_until_future_complete(Future(), timeout_sec=seconds)
            return
        end = time.monotonic() + seconds  # as SingleThreadedExecutor.spin() does
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.1)

    spin_for(3.0)  # discovery and the first /clock messages
    r0, f0 = resource.getrusage(resource.RUSAGE_SELF), fired[0]
    w0 = time.monotonic()
    spin_for(SECONDS)
    r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.monotonic() - w0
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    print(f"RESULT {variant} cpu_s={cpu:.4f} wall_s={wall:.3f} timer={fired[0] - f0} moved={moved}", flush=True)
    os._exit(0)  # the measurement is printed; skip rclpy teardown


def main() -> None:
    with isolated_domain() as domain:
        env = ros_env(domain)
        clock = Proc([sys.executable, "-m", "tests.bench.bench_executor_wake", "clock"], env, name="bench_clock")
        try:
            if not clock.wait_for("clock publishing", 30):
                raise RuntimeError(f"/clock publisher did not start:\n{clock.output}")
            totals: dict[str, list[float]] = {"default": [], "deferred": [], "relayed": [], "events": [],
                                              "timer100_single": [], "timer100_events": []}
            per_wake: dict[str, list[float]] = {variant: [] for variant in totals}
            for _ in range(ROUNDS):
                for variant in totals:
                    proc = Proc(
                        [sys.executable, "-m", "tests.bench.bench_executor_wake", "node", variant], env, name=variant
                    )
                    proc.wait(SECONDS + 60)
                    proc.wait_for("RESULT", 10)  # the output thread may still be reading the last line
                    match = re.search(r"RESULT \S+ cpu_s=(\S+) wall_s=(\S+) timer=(\d+) moved=(\d+)", proc.output)
                    if match is None:
                        raise RuntimeError(f"{variant} run printed no result:\n{proc.output}")
                    cpu, wall, timer, moved = float(match[1]), float(match[2]), int(match[3]), int(match[4])
                    clocks = 0 if variant.startswith("timer100") else wall * 200
                    wakes = timer + clocks  # timer callbacks + /clock messages
                    totals[variant].append(cpu / wall)
                    per_wake[variant].append(cpu / wakes)
                    print(f"{variant:15s}: {cpu / wall * 100:5.1f} % of a core, {cpu / wakes * 1e3:.3f} ms per wake "
                          f"({timer} timer callbacks, ~{clocks:.0f} /clock in {wall:.1f} s; {moved} handlers deferred)")
        finally:
            clock.kill()
    mean = {variant: sum(v) / len(v) for variant, v in totals.items()}
    wake = {variant: sum(v) / len(v) for variant, v in per_wake.items()}
    print(f"process CPU relative to the default (mean of {ROUNDS} rounds each): deferred QoS events "
          f"{mean['deferred'] / mean['default']:.2f}, and /clock relayed {mean['relayed'] / mean['default']:.2f}, "
          f"events executor {mean['events'] / mean['default']:.2f} (events / relayed "
          f"{mean['events'] / mean['relayed']:.2f})")
    print(
        f"100 Hz timer alone, CPU per wake: single {wake['timer100_single'] * 1e3:.3f} ms, events "
        f"{wake['timer100_events'] * 1e3:.3f} ms; events/single {wake['timer100_events'] / wake['timer100_single']:.2f}"
    )


if __name__ == "__main__":
    if sys.argv[1:2] == ["clock"]:
        _clock_publisher()
    elif sys.argv[1:2] == ["node"]:
        _node_under_test(sys.argv[2])
    else:
        main()
