"""Fixtures of the SocketCAN tests: the vcan channel to use and a raw AF_CAN socket on it."""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "vcan: needs a real SocketCAN interface (vcan0); runs inside the VM on CI")


def vcan_channel() -> str:
    """The SocketCAN interface under test: TMS_CAN_TEST_CHANNEL (set in the VM), default vcan0."""
    return os.environ.get("TMS_CAN_TEST_CHANNEL", "vcan0")


def socketcan_missing() -> str:
    """Why SocketCAN cannot be used here ('' when it can): no AF_CAN in the kernel, or no such interface."""
    from com3_can.bus import socketcan_available

    channel = vcan_channel()
    if not socketcan_available():
        return ("SocketCAN is not available in this kernel (no AF_CAN sockets); these tests run inside the VM "
                "(tests/vcan/test_vm.py) or on a machine with vcan0")
    if not Path("/sys/class/net", channel).exists():
        return (f"SocketCAN interface {channel} does not exist here (sudo modprobe vcan && "
                f"sudo ip link add dev {channel} type vcan && sudo ip link set up {channel})")
    return ""


@pytest.fixture
def raw_can() -> Iterator[socket.socket]:
    """A raw AF_CAN/CAN_RAW socket bound to the test channel: sees every frame on the wire, no python-can involved."""
    sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    sock.bind((vcan_channel(),))
    sock.settimeout(0.5)
    yield sock
    sock.close()
