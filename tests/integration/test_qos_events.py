"""tms_common.qos_events: incompatibility handlers leave the wait set, still report, other events stay."""

from __future__ import annotations

import time


def test_deferred_incompatible_qos_events_still_reach_their_callbacks(ros_node):
    from rclpy.duration import Duration
    from rclpy.event_handler import EventHandler, PublisherEventCallbacks, SubscriptionEventCallbacks
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    from tms_common.qos_events import INCOMPATIBILITY_EVENTS, defer_qos_incompatibility_events

    seen: dict[str, int] = {"sub": 0, "pub": 0}
    ros_node.create_publisher(
        Float64, "qos_probe", QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
        event_callbacks=PublisherEventCallbacks(incompatible_qos=lambda _e: seen.__setitem__("pub", seen["pub"] + 1)),
    )
    ros_node.create_subscription(
        Float64,
        "qos_probe",
        lambda _m: None,
        QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, deadline=Duration(seconds=5)),
        event_callbacks=SubscriptionEventCallbacks(
            incompatible_qos=lambda _e: seen.__setitem__("sub", seen["sub"] + 1), deadline=lambda _e: None
        ),
    )

    moved = defer_qos_incompatibility_events(ros_node, period_s=0.2)

    executor = ros_node.executor_for_test
    kinds = [getattr(w.event_type, "name", "") for w in ros_node.waitables
             if isinstance(w, EventHandler) and executor.can_execute(w)]  # what the executor puts in its wait set
    assert moved >= 2, moved
    assert not set(kinds) & set(INCOMPATIBILITY_EVENTS), kinds
    assert "RCL_SUBSCRIPTION_REQUESTED_DEADLINE_MISSED" in kinds, "a deadline handler must stay in the wait set"
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and not (seen["sub"] and seen["pub"]):
        ros_node.executor_for_test.spin_once(timeout_sec=0.1)
    assert seen["sub"] >= 1 and seen["pub"] >= 1, f"incompatible-QoS callbacks not called: {seen}"
    assert defer_qos_incompatibility_events(ros_node) == 0, "a second call finds nothing left to move"
