"""Baseline across processes: pub/sub latency at 100 Hz and action goal->result round trip.

The talker and the subtask server run as separate processes (resolved as ``ros2 run`` does); this
process subscribes / acts as the client. Both sides use the same host clock, so latency is
``receive time - header stamp``.
"""

from __future__ import annotations

import time

from tests.bench.stats import summary_ms
from tests.rosproc import Proc, executable, isolated_domain, ros_env

N_MESSAGES = 1000
N_GOALS = 100


def _pubsub(domain: int) -> str:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.time import Time
    from std_msgs.msg import Header

    talker = Proc([str(executable("tms_launch", "demo_talker")), "--ros-args", "-p", "rate_hz:=100.0"], ros_env(domain))
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("bench_listener", context=ctx)
    latencies: list[float] = []

    def on_msg(msg: Header) -> None:
        now = node.get_clock().now()
        latencies.append((now - Time.from_msg(msg.stamp)).nanoseconds * 1e-9)

    node.create_subscription(Header, "chatter", on_msg, 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 60
        while len(latencies) < N_MESSAGES + 50 and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)
    finally:
        talker.kill()
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    sample = latencies[50:]  # skip discovery warm-up
    return f"pub/sub latency, std_msgs/Header at 100 Hz across processes: {summary_ms(sample)}"


def _action(domain: int) -> str:
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tms_msg_ts.action import LeafNodeBase

    server = Proc(
        [str(executable("tms_launch", "demo_subtask_server")), "--ros-args", "-p", "duration_s:=0.0"], ros_env(domain)
    )
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = rclpy.create_node("bench_client", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    client = ActionClient(node, LeafNodeBase, "demo_subtask")
    rtts: list[float] = []
    try:
        if not client.wait_for_server(timeout_sec=30):
            raise RuntimeError("demo_subtask server did not come up")
        for i in range(N_GOALS + 5):
            start = time.perf_counter()
            fut = client.send_goal_async(LeafNodeBase.Goal(model_name="bench", record_name=f"r{i}"))
            ex.spin_until_future_complete(fut, timeout_sec=10)
            res_fut = fut.result().get_result_async()
            ex.spin_until_future_complete(res_fut, timeout_sec=10)
            if not res_fut.result().result.result:
                raise RuntimeError(f"goal {i} failed (status {res_fut.result().status})")
            rtts.append(time.perf_counter() - start)
    finally:
        server.kill()
        client.destroy()
        ex.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    return (
        f"action goal->result round trip (tms_msg_ts/LeafNodeBase, 0 s work) across processes: {summary_ms(rtts[5:])}"
    )


def main() -> None:
    with isolated_domain() as domain:
        print(_pubsub(domain), flush=True)
    with isolated_domain() as domain:
        print(_action(domain), flush=True)


if __name__ == "__main__":
    main()
