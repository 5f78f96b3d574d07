"""The CAN layer on real SocketCAN, checked by a raw AF_CAN socket (not by the code under test).

Runs where a SocketCAN interface exists: inside the VM that tests/vcan/test_vm.py boots (TMS_CAN_TEST_CHANNEL
=vcan0), or on a developer machine with vcan0 up. Elsewhere it is skipped saying which of the two is missing.

Expected ids and bytes are written out from the published COM3 layout (tests/com3_can/data/com3_frames.csv:
Velocity_Cmd_1 = 0x18FF670A, four little-endian uint16 at 0.0005 rad/s per bit, offset -16 rad/s;
Front_Angle = 0x18FF7DE8, 0.0004 rad per bit, offset -10 rad), so neither cantools nor the converter grades
its own output.
"""

from __future__ import annotations

import socket
import struct
import time

import pytest

from tests.rosproc import executable
from tests.vcan.conftest import socketcan_missing, vcan_channel

pytestmark = [pytest.mark.vcan, pytest.mark.skipif(bool(socketcan_missing()), reason=socketcan_missing() or "-")]

CAN_EFF_FLAG = 0x80000000
CAN_EFF_MASK = 0x1FFFFFFF
CAN_FRAME = struct.Struct("=IB3x8s")  # struct can_frame: id, dlc, pad, data

VELOCITY_CMD_1 = 0x18FF670A
FRONT_ANGLE = 0x18FF7DE8


def velocity_cmd_1_bytes(boom: float, arm: float, bucket: float, swing: float) -> bytes:
    """Velocity_Cmd_1 payload by hand: boom @0, arm @16, bucket @32, swing @48, raw = (v + 16) / 0.0005."""
    return struct.pack("<4H", *(round((v + 16.0) / 0.0005) for v in (boom, arm, bucket, swing)))


def front_angle_bytes(boom: float, arm: float, bucket: float, swing: float) -> bytes:
    """Front_Angle payload by hand: same layout, raw = (angle + 10) / 0.0004."""
    return struct.pack("<4H", *(round((a + 10.0) / 0.0004) for a in (boom, arm, bucket, swing)))


def raw_recv(sock: socket.socket) -> tuple[int, bool, bytes] | None:
    """One frame from the raw socket as (29/11-bit id, extended?, data), or None after the socket timeout."""
    try:
        can_id, dlc, data = CAN_FRAME.unpack(sock.recv(CAN_FRAME.size))
    except TimeoutError:
        return None
    return can_id & CAN_EFF_MASK, bool(can_id & CAN_EFF_FLAG), data[:dlc]


def raw_send(sock: socket.socket, arbitration_id: int, data: bytes) -> None:
    sock.send(CAN_FRAME.pack(arbitration_id | CAN_EFF_FLAG, len(data), data.ljust(8, b"\0")))


def test_codec_frame_sent_through_open_bus_is_on_the_wire_bit_exact(raw_can):
    """com3_can's codec + socketcan bus -> kernel -> raw reader: right id, extended flag, DLC and bytes."""
    import can

    from com3_can.bus import open_bus
    from com3_can.codec import load_codec

    codec = load_codec("zx200")
    assert codec.frame_id("Velocity_Cmd_1") & CAN_EFF_MASK == VELOCITY_CMD_1
    command = {"boom_target_anguler_velocity": -0.2, "arm_target_anguler_velocity": 0.3,
               "bucket_target_anguler_velocity": 0.0, "swing_target_anguler_velocity": 0.1}
    bus = open_bus({"interface": "socketcan", "channel": vcan_channel()})
    try:
        bus.send(can.Message(arbitration_id=VELOCITY_CMD_1, is_extended_id=True,
                             data=codec.encode("Velocity_Cmd_1", command)))
        got = raw_recv(raw_can)
    finally:
        bus.shutdown()
    assert got == (VELOCITY_CMD_1, True, velocity_cmd_1_bytes(-0.2, 0.3, 0.0, 0.1))


def test_frame_written_by_raw_socket_is_decoded_through_open_bus(raw_can):
    """Raw writer -> kernel -> com3_can socketcan bus + codec: the state frame decodes to what was written."""
    from com3_can.bus import open_bus
    from com3_can.codec import load_codec

    codec = load_codec("zx200")
    bus = open_bus({"interface": "socketcan", "channel": vcan_channel()})
    try:
        raw_send(raw_can, FRONT_ANGLE, front_angle_bytes(0.5, -1.0, 0.25, 0.0))
        msg = bus.recv(timeout=5.0)
    finally:
        bus.shutdown()
    assert msg is not None, f"nothing received on {vcan_channel()} within 5 s"
    assert (msg.arbitration_id, msg.is_extended_id) == (FRONT_ANGLE, True)
    name, values = codec.decode(msg.arbitration_id, bytes(msg.data))
    assert name == "Front_Angle"
    assert values["boom_relative_angle"] == pytest.approx(0.5, abs=1e-3)
    assert values["arm_relative_angle"] == pytest.approx(-1.0, abs=1e-3)
    assert values["bucket_relative_angle"] == pytest.approx(0.25, abs=1e-3)
    assert values["swing_relative_angle"] == pytest.approx(0.0, abs=1e-3)


@pytest.mark.integration
def test_converter_node_frames_on_vcan0_read_by_raw_socket(procs, ros_node, raw_can):
    """com3_bridge on socketcan: a front_cmd becomes Velocity_Cmd_1 with the right id and bytes on vcan0; when
    commands stop, the watchdog puts neutral bytes on the wire; garbled raw frames do not kill it and a valid
    Front_Angle written raw then reaches joint_states; once emg_stop is latched, commands never reach the wire.

    One bridge process serves all three checks (its start-up under software emulation costs tens of seconds).
    """
    from sensor_msgs.msg import JointState

    from com3_msgs.msg import JointCmd
    from tms_model.com3 import VELOCITY

    bridge = procs([executable("com3_can", "com3_bridge"), "--ros-args", "-r", "__ns:=/zx200",
                    "-p", "machine:=zx200", "-p", "can_interface:=socketcan", "-p", f"can_channel:={vcan_channel()}",
                    "-p", "watchdog_s:=0.5"], name="com3_bridge")
    pub = ros_node.create_publisher(JointCmd, "/zx200/front_cmd", 10)
    states: list[JointState] = []
    ros_node.create_subscription(JointState, "/zx200/joint_states", states.append, 10)
    spin = ros_node.executor_for_test.spin_once

    cmd = JointCmd(joint_name=["swing_joint", "boom_joint", "arm_joint", "bucket_joint"],
                   control_type=VELOCITY, velocity=[0.1, -0.2, 0.3, 0.0])
    wanted = velocity_cmd_1_bytes(boom=-0.2, arm=0.3, bucket=0.0, swing=0.1)
    seen_ids: set[int] = set()

    def wait_for_frame(arbitration_id: int, data: bytes, timeout: float, publish: bool) -> bool:
        deadline = time.monotonic() + timeout
        next_pub = 0.0
        while time.monotonic() < deadline and bridge.popen.poll() is None:
            if publish and time.monotonic() >= next_pub:
                pub.publish(cmd)
                next_pub = time.monotonic() + 0.1
            spin(timeout_sec=0.01)
            frame = raw_recv(raw_can)
            if frame is None:
                continue
            seen_ids.add(frame[0])
            if frame == (arbitration_id, True, data):
                return True
        return False

    # 1. command direction: ROS front_cmd -> converter -> vcan0 -> raw reader
    assert wait_for_frame(VELOCITY_CMD_1, wanted, timeout=120.0, publish=True), (
        f"no Velocity_Cmd_1 {wanted.hex()} on {vcan_channel()}; ids seen {sorted(map(hex, seen_ids))}\n{bridge.output}")
    # 2. watchdog: commands stop -> neutral (0 rad/s = raw 32000) on the wire
    neutral = velocity_cmd_1_bytes(0.0, 0.0, 0.0, 0.0)
    assert wait_for_frame(VELOCITY_CMD_1, neutral, timeout=30.0, publish=False), (
        f"no neutral Velocity_Cmd_1 after commands stopped\n{bridge.output}")
    # 3. garbled frames from the wire (unknown id, wrong DLC, standard id), paced, must not kill the converter
    for i in range(30):
        raw_send(raw_can, 0x18FFFFF0 + (i % 8), bytes([i] * 8))
        raw_send(raw_can, FRONT_ANGLE, bytes([0xFF] * 3))
        raw_can.send(CAN_FRAME.pack(0x123, 8, bytes(8)))
        spin(timeout_sec=0.02)
    assert bridge.popen.poll() is None, f"com3_bridge died on garbled frames\n{bridge.output}"
    # 4. state direction: raw writer -> vcan0 -> converter -> joint_states
    deadline = time.monotonic() + 60.0
    got: dict[str, float] = {}
    while time.monotonic() < deadline and not got:
        raw_send(raw_can, FRONT_ANGLE, front_angle_bytes(boom=0.5, arm=-1.0, bucket=0.25, swing=0.0))
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            spin(timeout_sec=0.05)
        for msg in states:
            pos = dict(zip(msg.name, msg.position, strict=False))
            if pos.get("boom_joint") == pytest.approx(0.5, abs=1e-3):
                got = pos
    assert got, f"no joint_states with boom_joint=0.5 after raw Front_Angle frames\n{bridge.output}"
    assert got["arm_joint"] == pytest.approx(-1.0, abs=1e-3)
    assert got["bucket_joint"] == pytest.approx(0.25, abs=1e-3)
    assert got["swing_joint"] == pytest.approx(0.0, abs=1e-3)
    # 5. emg_stop latch: after it is set, commands are refused and only neutral frames are on the wire
    from std_msgs.msg import Bool

    emg = ros_node.create_publisher(Bool, "/zx200/emg_stop", 10)
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and not bridge.wait_for("emg_stop latched", 0.2):
        emg.publish(Bool(data=True))
        spin(timeout_sec=0.05)
    assert bridge.wait_for("emg_stop latched", 1.0), f"emg_stop never latched\n{bridge.output}"
    drain_end = time.monotonic() + 1.0  # drop what was queued before the latch took effect
    while time.monotonic() < drain_end and raw_recv(raw_can) is not None:
        pass
    leaked: list[bytes] = []
    neutral_seen = 0
    end = time.monotonic() + 5.0
    while time.monotonic() < end:
        pub.publish(cmd)
        spin(timeout_sec=0.02)
        frame = raw_recv(raw_can)
        if frame and frame[0] == VELOCITY_CMD_1:
            neutral_seen += frame[2] == neutral
            if frame[2] != neutral:
                leaked.append(frame[2])
    assert not leaked, f"motion frames on the wire while emg_stop is latched: {[d.hex() for d in leaked[:5]]}"
    assert neutral_seen > 0, "no Velocity_Cmd_1 at all while emg_stop is latched"
