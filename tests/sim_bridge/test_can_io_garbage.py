"""The plant's CAN I/O survives a datagram that is not a CAN frame on its udp_multicast port.

A socket bound to a UDP port hears every datagram sent to it; in a CI run a left-over DDS participant's
announcements reached a test's CAN port and ``python-can`` raised ``CanOperationError`` from ``recv``, which
crashed the plant loop. Real udp_multicast bus, real datagrams.
"""

from __future__ import annotations

import os
import random
import socket
import time

import can

from com3_can.codec import load_codec
from sim_bridge.can_io import PlantCanIO
from sim_bridge.config import load_plant
from sim_bridge.plant import Plant


def test_non_can_datagram_is_counted_and_valid_frames_still_apply():
    rng = random.Random(os.getpid())
    group, port = f"239.73.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}", 2000 + rng.randrange(900)
    bus = can.Bus(interface="udp_multicast", channel=group, port=port, receive_own_messages=False)
    sender = can.Bus(interface="udp_multicast", channel=group, port=port)
    try:
        plant = Plant(load_plant())
        io = PlantCanIO(plant, {"zx200": bus})
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        raw.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        raw.sendto(b"RTPS\x02\x03not a can frame at all", (group, port))
        raw.close()
        codec = load_codec("zx200")
        data = codec.encode(
            "Velocity_Cmd_1", {f"{j}_target_anguler_velocity": 0.0 for j in ("swing", "boom", "arm", "bucket")}
        )
        sender.send(can.Message(arbitration_id=codec.frame_id("Velocity_Cmd_1"), data=data, is_extended_id=True))
        side = io.sides["zx200"]
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and not side.counters["received"]:
            io.poll()  # must not raise
            time.sleep(0.01)
        assert side.counters["ignored_undecodable"] == 1, dict(side.counters)
        assert side.counters["received"] == 1, dict(side.counters)
    finally:
        sender.shutdown()
        bus.shutdown()
