"""The converter's frame order across its threads: a cyclic command frame the sender thread computed before an
emg_stop latched never reaches the wire after the emg_stop's neutral frame.

The converter node runs in this process on python-can's in-process ``virtual`` bus (the plant container's link);
the race is made certain, not left to chance: the sender thread's ``core.tick`` is held right after it built its
frames (a thread preempted there) while ``emg_stop`` arrives on the executor.
"""

from __future__ import annotations

import threading
import time
import uuid

import can
import pytest

from com3_can.codec import load_codec

ZX = load_codec("zx200")
NEUTRAL_V1 = ZX.encode("Velocity_Cmd_1", ZX.neutral("Velocity_Cmd_1"))


def test_frames_built_before_emg_stop_do_not_follow_its_neutral_frame(domain: int) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter
    from std_msgs.msg import Bool

    from com3_can.nodes.com3_bridge import Com3Bridge
    from com3_msgs.msg import JointCmd
    from tms_model.com3 import VELOCITY

    channel = f"send_order_{uuid.uuid4().hex}"
    peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    node = Com3Bridge(context=ctx, parameter_overrides=[
        Parameter("machine", value="zx200"), Parameter("can_interface", value="virtual"),
        Parameter("can_channel", value=channel)])
    v1 = ZX.frame_id("Velocity_Cmd_1")
    try:
        node._on_front(JointCmd(joint_name=["swing_joint", "boom_joint", "arm_joint", "bucket_joint"],
                                control_type=VELOCITY, velocity=[0.5, 0.1, -0.2, 0.0]))
        built, release = threading.Event(), threading.Event()
        tick = node.core.tick

        def held_tick(now: float):  # the sender thread, preempted after building its frames
            txs = tick(now)
            if any(tx.arbitration_id == v1 and tx.data != NEUTRAL_V1 for tx in txs) and not built.is_set():
                built.set()
                release.wait(5.0)
            return txs

        node.core.tick = held_tick
        assert built.wait(5.0), "the sender thread never built a moving Velocity_Cmd_1"
        while peer.recv(0.0) is not None:  # what went out before: the neutral frames before the command, ...
            pass
        emg = threading.Thread(target=node._on_emg, args=(Bool(data=True),))
        emg.start()
        time.sleep(0.2)  # emg_stop is in, the sender thread still holds its moving frame
        release.set()
        emg.join(5.0)
        assert not emg.is_alive()
        time.sleep(0.3)
        frames = []
        while (msg := peer.recv(0.0)) is not None:
            if msg.arbitration_id == v1:
                frames.append(bytes(msg.data))
        first_neutral = frames.index(NEUTRAL_V1)
        assert first_neutral < len(frames) - 1, frames  # the sender went on after the latch
        assert all(f == NEUTRAL_V1 for f in frames[first_neutral:]), [f.hex() for f in frames[first_neutral:]]
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        peer.shutdown()


if __name__ == "__main__":
    pytest.main([__file__, "-q"])
