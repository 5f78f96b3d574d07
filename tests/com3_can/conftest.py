"""com3_can fixtures: the CAN backend under test and a raw python-can peer on it.

The backend comes from ``TMS_CAN_TEST_BACKEND``: ``udp_multicast`` (default; every test gets its own
multicast group and port so parallel tests never hear each other) or ``socketcan`` (``vcan0``, or
``TMS_CAN_TEST_CHANNEL``); a socketcan request on a kernel without SocketCAN skips with that reason.
Tests that run on either backend are marked ``can_backend`` (issue 11 runs them in a VM with vcan0:
``TMS_CAN_TEST_BACKEND=socketcan pytest -m can_backend tests/com3_can``).
"""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.rosproc import free_can_ports


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "can_backend: runs on the CAN backend chosen by TMS_CAN_TEST_BACKEND (udp_multicast | socketcan)"
    )


@pytest.fixture
def can_cfg(domain: int) -> dict[str, Any]:
    """Bus config (interface, channel[, port]) for this test, isolated per test on udp_multicast."""
    backend = os.environ.get("TMS_CAN_TEST_BACKEND", "udp_multicast")
    if backend == "socketcan":
        from com3_can.bus import socketcan_available

        channel = os.environ.get("TMS_CAN_TEST_CHANNEL", "vcan0")
        if not socketcan_available():
            pytest.skip("SocketCAN is not available in this kernel")
        if not Path("/sys/class/net", channel).exists():
            pytest.skip(f"SocketCAN is available but interface {channel} does not exist")
        return {"interface": "socketcan", "channel": channel}
    if backend != "udp_multicast":
        raise ValueError(f"TMS_CAN_TEST_BACKEND={backend!r}: expected udp_multicast or socketcan")
    rng = random.Random(os.getpid() * 1000 + domain + time.monotonic_ns())
    return {
        "interface": "udp_multicast",
        "channel": f"239.74.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
        "port": free_can_ports(domain, 1, rng)[0],
    }


class Peer:
    """A raw python-can bus in the test process that records every frame it hears (monotonic time, msg)."""

    def __init__(self, cfg: dict[str, Any]) -> None:
        from com3_can.bus import open_bus

        self.bus = open_bus(cfg)
        self.frames: list[tuple[float, Any]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is not None:
                with self._lock:
                    self.frames.append((time.monotonic(), msg))

    def since(self, t0: float, arbitration_id: int | None = None) -> list[tuple[float, Any]]:
        with self._lock:
            return [
                (t, m)
                for t, m in self.frames
                if t >= t0 and (arbitration_id is None or m.arbitration_id == arbitration_id)
            ]

    def send(self, arbitration_id: int, data: bytes, **kw: Any) -> None:
        import can

        self.bus.send(
            can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=kw.pop("is_extended_id", True), **kw)
        )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)
        self.bus.shutdown()


@pytest.fixture
def peer(can_cfg: dict[str, Any]) -> Iterator[Peer]:
    p = Peer(can_cfg)
    yield p
    p.close()
