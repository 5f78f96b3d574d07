"""tms_common.sim_clock: a simulated-time node's clock is fed by the relay thread; its executor wakes for timers
only."""

from __future__ import annotations

import threading
import time


def test_relayed_clock_fires_timers_at_simulated_times_without_waking_per_clock_message(ros_node):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    from tms_common import rclpy_compat
    from tms_common.sim_clock import relay_clock

    node = rclpy.create_node("sim_node", context=ros_node.context,
                             parameter_overrides=[Parameter("use_sim_time", value=True)])
    fired: list[float] = []
    node.create_timer(0.1, lambda: fired.append(node.get_clock().now().nanoseconds * 1e-9))
    relay = relay_clock(node)
    assert relay is not None
    own = [s for s in node.subscriptions if s.topic_name == "/clock"]
    assert own and all(rclpy_compat.is_parked(s) for s in own), (
        "the node's /clock subscription is still in its executor"
    )
    pub = ros_node.create_publisher(Clock, "/clock", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + 10
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert pub.get_subscription_count() >= 1, "the relay's /clock subscription was not discovered"

    steps = 200  # 10 ms of simulated time every 5 ms of wall time: 2 s simulated

    def publish() -> None:
        for k in range(1, steps + 1):
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(k * 10_000_000, 1_000_000_000)
            # the last stamp three times, as a simulator keeps publishing its clock: the relay's best-effort,
            # keep-last subscription may lose a message, and the check below needs the last one
            for _ in range(3 if k == steps else 1):
                pub.publish(msg)
                time.sleep(0.005)

    executor = SingleThreadedExecutor(context=ros_node.context)
    executor.add_node(node)
    feeder = threading.Thread(target=publish, daemon=True)
    wakes = 0
    try:
        feeder.start()
        end = time.monotonic() + 15
        while (feeder.is_alive() or node.get_clock().now().nanoseconds < steps * 10_000_000) and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.5)
            wakes += 1
        now = node.get_clock().now().nanoseconds * 1e-9
        assert abs(now - 2.0) < 1e-6, f"the node's clock stopped at {now} s (relay received {relay.received})"
        assert relay.received >= steps * 0.9, relay.received  # best effort: a few may be dropped locally
        assert 18 <= len(fired) <= 21, fired
        # the k-th call is due at k * 0.1 s simulated: never before, and before the (k+1)-th is due. How far the clock
        # ran on while the executor woke is the machine's scheduling (CI saw 0.06 s simulated = 30 ms wall); a timer
        # on wall time would fall behind by k * 0.1 s here, since simulated time runs at twice wall time
        late = [(k, t) for k, t in enumerate(fired, 1) if not k * 0.1 - 1e-6 <= t < (k + 1) * 0.1]
        assert not late, f"timer calls off their simulated due times (k, t): {late}"
        # without the relay every /clock message wakes the executor (>= 200); now timers (20) and timeouts do
        assert wakes < steps / 4, f"{wakes} executor wakes for {steps} /clock messages"
        # no helper node on the graph: `ros2 node list` shows the nodes a user started
        names = ros_node.get_node_names()
        assert "sim_node" in names and not [n for n in names if n.startswith("sim_node_")], names
    finally:
        executor.shutdown()
        relay.close()
        relay.close()  # idempotent
        node.destroy_node()


def test_shared_time_source_drives_every_node_of_an_events_container_from_one_clock_subscription(ros_node):
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.task import Future
    from rosgraph_msgs.msg import Clock

    from tms_common.node import make_executor
    from tms_common.sim_clock import on_simulated_time, share_time_source

    sim = [Parameter("use_sim_time", value=True)]
    leader = rclpy.create_node("clock_leader", context=ros_node.context, parameter_overrides=sim)
    follower = rclpy.create_node("clock_follower", context=ros_node.context, parameter_overrides=sim)
    walltime = rclpy.create_node("wall_node", context=ros_node.context)
    try:
        assert not share_time_source(leader, walltime), "a node on wall time must keep system time"
        assert not share_time_source(leader, leader)
        assert share_time_source(leader, follower)
        assert on_simulated_time(leader) and not on_simulated_time(follower), "the follower kept its /clock reader"
        fired: list[float] = []
        follower.create_timer(0.1, lambda: fired.append(follower.get_clock().now().nanoseconds * 1e-9))
        pub = ros_node.create_publisher(Clock, "/clock", QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pub.get_subscription_count() == 1, "one /clock subscription for the two simulated-time nodes"

        executor = make_executor("events", context=ros_node.context)
        for n in (leader, follower, walltime):
            executor.add_node(n)
        done = Future()
        spinner = threading.Thread(target=lambda: executor.spin_until_future_complete(done, timeout_sec=20),
                                   daemon=True)
        spinner.start()
        for k in range(1, 101):  # 10 ms of simulated time every 5 ms: 1 s simulated
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(k * 10_000_000, 1_000_000_000)
            for _ in range(3 if k == 100 else 1):
                pub.publish(msg)
                time.sleep(0.005)
        end = time.monotonic() + 5
        while follower.get_clock().now().nanoseconds < 1_000_000_000 and time.monotonic() < end:
            time.sleep(0.02)
        assert abs(follower.get_clock().now().nanoseconds * 1e-9 - 1.0) < 1e-6
        assert abs(leader.get_clock().now().nanoseconds * 1e-9 - 1.0) < 1e-6
        assert walltime.get_clock().now().nanoseconds > 1e18, "the wall-time node left system time"
        time.sleep(0.2)
        assert 9 <= len(fired) <= 11, fired
        late = [(k, t) for k, t in enumerate(fired, 1) if not k * 0.1 - 1e-6 <= t < (k + 1) * 0.1]
        assert not late, f"timer calls off their simulated due times (k, t): {late}"
        done.set_result(None)
        spinner.join(timeout=5)
        executor.shutdown()
    finally:
        for n in (follower, walltime, leader):
            n.destroy_node()
