"""Helpers for tests and benchmarks that run real ROS 2 processes.

* :func:`isolated_domain` picks a ROS_DOMAIN_ID no other test on this machine holds (a flock per id
  under /tmp), so parallel runs and leftovers never cross-talk; discovery stays on localhost.
* :class:`Proc` starts an executable exactly as ``ros2 run`` resolves it, captures its output, and
  is always killed at teardown.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VENV = Path(sys.prefix)
_LOCK_DIR = Path("/tmp/tms-ros-domains")


@contextlib.contextmanager
def isolated_domain() -> Iterator[int]:
    """Hold a free ROS_DOMAIN_ID (1..200) for the duration of the block."""
    _LOCK_DIR.mkdir(exist_ok=True)
    ids = list(range(1, 201))
    random.shuffle(ids)
    for domain in ids:
        fd = os.open(_LOCK_DIR / f"{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        try:
            yield domain
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        return
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..200")


#: udp_multicast CAN test ports live below DDS's port space: Fast DDS uses 7400 + 250 * domain + offsets
#: (domains 1..200 here -> 7650..57700), and a socket bound to a port hears every datagram sent to it, so a
#: CAN bus on, say, port 47196 received the SPDP announcements a left-over participant of domain 159 kept
#: sending to its dead peers (and the plant crashed on them).
CAN_PORT_BASE = 3000
CAN_PORTS_PER_DOMAIN = 20


def can_port(domain: int, k: int = 0) -> int:
    """The ``k``-th (0..19) udp_multicast CAN port of a test holding ``domain``: unique per domain, never a DDS port."""
    if not 0 <= k < CAN_PORTS_PER_DOMAIN:
        raise ValueError(f"can_port: k={k} outside 0..{CAN_PORTS_PER_DOMAIN - 1}")
    port = CAN_PORT_BASE + CAN_PORTS_PER_DOMAIN * domain + k
    assert port < 7400, f"can_port({domain}, {k}) = {port} would be inside DDS's port range"
    return port


def _port_unbound(port: int) -> bool:
    """True when no UDP socket on this host holds ``port`` now (a bind without SO_REUSEADDR succeeds)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("", port))
        except OSError:
            return False
    return True


def free_can_ports(domain: int, count: int, rng: random.Random | None = None) -> list[int]:
    """``count`` distinct udp_multicast CAN ports of ``domain`` that no socket on this host holds now.

    The domain's flock does not cover processes of an earlier test on the same domain that are still
    closing (a clean-clone CI run once failed with EADDRINUSE on ``can_port(domain, 0)``), so ports are
    probed, in random order, and a held one is passed over.
    """
    ks = list(range(CAN_PORTS_PER_DOMAIN))
    (rng or random).shuffle(ks)
    ports = [p for p in (can_port(domain, k) for k in ks) if _port_unbound(p)][:count]
    if len(ports) < count:
        raise RuntimeError(f"free_can_ports: only {len(ports)} of domain {domain}'s {CAN_PORTS_PER_DOMAIN} CAN ports "
                           f"are unbound, {count} needed (ss -uapn shows who holds them)")
    return ports


def ros_env(domain: int, **extra: str) -> dict[str, str]:
    """Environment for a node process on ``domain``, discovery limited to this host."""
    env = dict(os.environ)
    # the venv's prefix, after any overlay of this project's data (a worktree's share/tms_common, so its nodes
    # read the worktree's config/ and not the checkout the venv was installed from)
    overlays = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
                if p and Path(p, "share", "tms_common").is_dir() and Path(p).resolve() != VENV.resolve()]
    env.update(
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        AMENT_PREFIX_PATH=os.pathsep.join([*overlays, str(VENV)]),
        PYTHONUNBUFFERED="1",
    )
    env.update(extra)
    return env


def executable(package: str, name: str) -> Path:
    """Resolve ``<prefix>/lib/<package>/<name>`` through ament_index_python, as ``ros2 run`` does."""
    os.environ.setdefault("AMENT_PREFIX_PATH", str(VENV))
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(package)) / "lib" / package / name
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise FileNotFoundError(f"{path} is not an executable file")
    return path


class Proc:
    """A child process with its merged output collected line by line in a background thread."""

    def __init__(self, cmd: list[str], env: dict[str, str], *, name: str | None = None) -> None:
        self.name = name or Path(cmd[0]).name
        self.popen = subprocess.Popen(
            cmd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for raw in iter(self.popen.stdout.readline, b""):
            with self._cond:
                self.lines.append(raw.decode(errors="replace").rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    @property
    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def wait_for(self, text: str, timeout: float) -> bool:
        """True once a line containing ``text`` has been printed, False after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                if any(text in line for line in self.lines):
                    return True
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(min(remaining, 0.2))

    def wait(self, timeout: float) -> int | None:
        try:
            return self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def signal(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, sig)

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.signal(signal.SIGINT)
            if self.wait(3.0) is None:
                self.signal(signal.SIGKILL)
                self.wait(3.0)
        self._thread.join(timeout=1.0)


def start_private_plant(procs, domain: int, config: str | Path, speed: float = 1.0, group: int = 77) -> dict:
    """sim_plant on ``config`` (its zx200 and ic120) on CAN buses of their own: udp_multicast groups
    ``239.<group>.x.y`` picked at random and ports no socket holds (:func:`free_can_ports`), so tests running
    beside each other never share a bus. Returns ``{machine: {"channel", "port"}}`` once the plant runs."""
    rng = random.Random(domain * 7919 + time.monotonic_ns())
    ports = free_can_ports(domain, 2, rng)
    buses = {m: {"channel": f"239.{group}.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}", "port": p}
             for m, p in zip(("zx200", "ic120"), ports, strict=True)}
    args = [executable("sim_bridge", "sim_plant"), "--ros-args", "-p", f"config:={config}", "-p", f"speed:={speed}"]
    for m, b in buses.items():
        args += ["-p", f"{m}_can_interface:=udp_multicast", "-p", f"{m}_can_channel:={b['channel']}",
                 "-p", f"{m}_can_port:={b['port']}"]
    plant = procs(args, name="sim_plant")
    assert plant.wait_for("sim_plant: running", 60), plant.output
    return buses
