"""sim_bridge fixtures: a running ``sim_plant`` process and COM3 peers that command it and read its state.

Each test gets its own ROS domain and, on udp_multicast (default ``TMS_CAN_TEST_BACKEND``), its own
multicast groups and ports for the two machine buses. ``socketcan`` puts both machines on vcan0
(or ``TMS_CAN_TEST_CHANNEL``); each side then ignores the other machine's ids (counted).
"""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from com3_can.bus import open_bus, socketcan_available
from com3_can.codec import load_codec
from tests.rosproc import executable, free_can_ports
from tms_common.config import config_path


def _bus_cfgs(domain: int) -> dict[str, dict[str, Any]]:
    backend = os.environ.get("TMS_CAN_TEST_BACKEND", "udp_multicast")
    if backend == "socketcan":
        channel = os.environ.get("TMS_CAN_TEST_CHANNEL", "vcan0")
        if not socketcan_available() or not Path("/sys/class/net", channel).exists():
            pytest.skip(f"SocketCAN interface {channel} is not available in this kernel")
        return {m: {"interface": "socketcan", "channel": channel} for m in ("zx200", "ic120")}
    rng = random.Random(os.getpid() * 7919 + domain + time.monotonic_ns())
    ports = free_can_ports(domain, 2, rng)
    return {
        m: {"interface": "udp_multicast", "channel": f"239.75.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
            "port": port}
        for m, port in zip(("zx200", "ic120"), ports, strict=True)
    }


class Machine:
    """A COM3 peer of one machine: sends command frames every 10 ms and decodes the state frames."""

    def __init__(self, machine: str, cfg: dict[str, Any]) -> None:
        self._can = can
        self.machine = machine
        self.codec = load_codec(machine)
        self.bus = open_bus(cfg)
        self.latest: dict[str, dict[str, float]] = {}
        self.history: list[tuple[float, str, dict[str, float]]] = []
        self.commands: dict[str, dict[str, float]] = {}  # frame -> values, sent every 10 ms while present
        self.raw: list[tuple[int, bytes]] = []  # raw frames to send once
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._rx, daemon=True), threading.Thread(target=self._tx, daemon=True)]
        for t in self._threads:
            t.start()

    def _rx(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None:
                continue
            try:
                name, values = self.codec.decode(msg.arbitration_id, bytes(msg.data))
            except Exception:  # noqa: BLE001 - other machine's ids on a shared vcan0
                continue
            if self.codec.is_command(name):
                continue
            with self._lock:
                self.latest[name] = values
                self.history.append((time.monotonic(), name, values))

    def _tx(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            with self._lock:
                frames = [(n, dict(v)) for n, v in self.commands.items()]
                raw, self.raw = self.raw, []
            for name, values in frames:
                self.bus.send(self._can.Message(arbitration_id=self.codec.frame_id(name),
                                                data=self.codec.encode(name, values), is_extended_id=True))
            for arb, data in raw:
                self.bus.send(self._can.Message(arbitration_id=arb, data=data, is_extended_id=True))
            next_t += 0.01
            time.sleep(max(0.0, next_t - time.monotonic()))

    def command(self, frame: str, **values: float) -> None:
        """Send ``frame`` every 10 ms from now on (neutral values for signals not given)."""
        full = self.codec.neutral(frame)
        full.update(values)
        with self._lock:
            self.commands[frame] = full

    def silence(self) -> None:
        """Stop sending every command frame (the plant's watchdog must then stop the machine)."""
        with self._lock:
            self.commands.clear()

    def send_raw(self, arbitration_id: int, data: bytes) -> None:
        with self._lock:
            self.raw.append((arbitration_id, data))

    def get(self, frame: str, timeout: float = 10.0) -> dict[str, float]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if frame in self.latest:
                    return dict(self.latest[frame])
            time.sleep(0.01)
        raise TimeoutError(f"{self.machine}: no {frame} frame within {timeout} s")

    def wait_until(self, frame: str, predicate: Callable[[dict[str, float]], bool], timeout: float) -> float | None:
        """Monotonic time of the first ``frame`` (received from now on) satisfying ``predicate``."""
        t0 = time.monotonic()
        start = len(self.history)
        while time.monotonic() - t0 < timeout:
            with self._lock:
                fresh = self.history[start:]
                start = len(self.history)
            for t, name, values in fresh:
                if name == frame and predicate(values):
                    return t
            time.sleep(0.01)
        return None

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=1.0)
        self.bus.shutdown()


class PlantUnderTest:
    def __init__(self, proc: Any, machines: dict[str, Machine]) -> None:
        self.proc = proc
        self.zx200 = machines["zx200"]
        self.ic120 = machines["ic120"]


@pytest.fixture
def start_plant(procs, domain: int, tmp_path: Path) -> Iterator[Callable[..., PlantUnderTest]]:
    """``start_plant(speed=1.0, ic120_pose="ic120_start", front=None, **params)`` runs sim_plant and opens both
    peers."""
    machines_open: list[Machine] = []

    def start(*, speed: float = 1.0, ic120_pose: str = "ic120_start", front: dict[str, float] | None = None,
              **params: Any) -> PlantUnderTest:
        text = config_path("sim", "plant.yaml").read_text().replace("ic120: ic120_start", f"ic120: {ic120_pose}")
        if front is not None:  # the ZX200's front at start (default: its home pose, the bucket in the mound)
            text = "initial_front: {" + ", ".join(f"{j}: {q}" for j, q in front.items()) + "}\n" + text
        cfg_file = tmp_path / "plant.yaml"
        cfg_file.write_text(text)
        cfgs = _bus_cfgs(domain)
        args = [
            str(executable("sim_bridge", "sim_plant")),
            "--ros-args",
            "-p",
            f"speed:={speed}",
            "-p",
            f"config:={cfg_file}",
        ]
        for m, cfg in cfgs.items():
            args += ["-p", f"{m}_can_interface:={cfg['interface']}", "-p", f"{m}_can_channel:={cfg['channel']}"]
            if "port" in cfg:
                args += ["-p", f"{m}_can_port:={cfg['port']}"]
        for k, v in params.items():
            args += ["-p", f"{k}:={v}"]
        machines = {m: Machine(m, cfg) for m, cfg in cfgs.items()}
        machines_open.extend(machines.values())
        proc = procs(args, name="sim_plant")
        assert proc.wait_for("sim_plant: running", 60), proc.output
        return PlantUnderTest(proc, machines)

    yield start
    for m in machines_open:
        m.close()
