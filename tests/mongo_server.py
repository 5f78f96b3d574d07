"""A MongoDB wire-protocol server for the tests: SecantusDB (``secantusd-py``, the ``test`` extra), as its own process.

SecantusDB is GPL-2.0: the project never imports it, the tests only start its server and talk to it with pymongo.
It advertises itself as the primary of a one-node replica set, so transactions and change streams work as on a
MongoDB replica set.

:class:`MongoServer` starts one on a free loopback port (the tests run in a network namespace with only ``lo``)
with its storage in a temporary directory, waits until it answers ``ping``, and can be killed (SIGKILL) and
restarted on the same port and storage; :meth:`MongoServer.stop` ends it and removes the directory. A server that
does not start raises :class:`MongoServerError` with the tail of its output.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

__all__ = ["MongoServer", "MongoServerError", "SERVER_EXE", "with_database", "unique_database"]

#: the server's console script, next to this interpreter (the venv's)
SERVER_EXE = Path(sys.executable).with_name("secantusd-py")
_START_TIMEOUT_S = 60.0


class MongoServerError(RuntimeError):
    """The test server could not be started (message: the command and the tail of its output)."""


def unique_database() -> str:
    """A database name no other test uses (each test gets its own, dropped afterwards)."""
    return f"tms_test_{uuid.uuid4().hex[:12]}"


def with_database(uri: str, database: str) -> str:
    """``uri`` naming ``database`` (replacing the one it names), its options kept: the URI a worker process opens."""
    head, sep, query = uri.partition("?")
    scheme, _, rest = head.partition("://")
    hosts = rest.split("/", 1)[0]
    return f"{scheme}://{hosts}/{database}" + (f"?{query}" if sep else "")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _answers_ping(uri: str, timeout_s: float) -> bool:
    import pymongo
    import pymongo.errors

    client = pymongo.MongoClient(uri, serverSelectionTimeoutMS=int(timeout_s * 1000), connectTimeoutMS=1000)
    try:
        client.admin.command("ping")
        return True
    except pymongo.errors.PyMongoError:
        return False
    finally:
        client.close()


class MongoServer:
    """One SecantusDB server process on ``127.0.0.1:port`` with storage under a temporary directory."""

    def __init__(self, *, port: int | None = None) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="tms-mongo-"))
        self.storage = self.dir / "data"
        self.log_path = self.dir / "server.log"
        self._auto_port = port is None  # a port chosen here may be taken before the server binds it: choose again
        self.port = port or _free_port()
        self.proc: subprocess.Popen | None = None
        # an empty configuration file: the server would otherwise read ./secantusd.toml or ~/.secantus/ if present
        self.config = self.dir / "secantusd.toml"
        self.config.write_text("")

    @property
    def uri(self) -> str:
        return f"mongodb://127.0.0.1:{self.port}"

    def command(self) -> list[str]:
        return [str(SERVER_EXE), "--config", str(self.config), "--host", "127.0.0.1", "--port", str(self.port),
                "--storage-path", str(self.storage), "--log-level", "INFO"]

    def log_tail(self, chars: int = 3000) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-chars:]
        except OSError:
            return ""

    def start(self) -> MongoServer:
        """Start the server and wait until it answers ``ping``; MongoServerError with its output otherwise."""
        for _attempt in range(3):
            try:
                return self._start()
            except MongoServerError as exc:
                if not (self._auto_port and "in use" in str(exc)):
                    raise
                self.port = _free_port()
        return self._start()

    def _start(self) -> MongoServer:
        if not SERVER_EXE.exists():
            raise MongoServerError(f"{SERVER_EXE} not found: install the test extra (pip install -e '.[test]' with "
                                   "constraints.txt; it holds SecantusDB)")
        start = self.log_path.stat().st_size if self.log_path.exists() else 0
        with open(self.log_path, "ab") as log:
            self.proc = subprocess.Popen(self.command(), stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                         cwd=self.dir, start_new_session=True)
        deadline = time.monotonic() + _START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise MongoServerError(f"{' '.join(self.command())} exited with {self.proc.returncode} before "
                                       f"answering ping; its output ends:\n{self.log_tail()}")
            # its own "listening" line first: another process may hold the port and answer the ping
            if self._said_listening(start) and _answers_ping(self.uri, 0.5):
                return self
            time.sleep(0.1)
        self.kill()
        raise MongoServerError(f"{' '.join(self.command())} did not answer ping within {_START_TIMEOUT_S:.0f} s; its "
                               f"output ends:\n{self.log_tail()}")

    def _said_listening(self, offset: int) -> bool:
        with open(self.log_path, "rb") as log:
            log.seek(offset)
            return f"listening on 127.0.0.1:{self.port}".encode() in log.read()

    def kill(self) -> None:
        """SIGKILL the server (a crash: nothing flushed), and wait for it."""
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(10)

    def restart(self) -> MongoServer:
        """Start it again on the same port and storage (after :meth:`kill`)."""
        self.kill()
        return self.start()

    def stop(self) -> None:
        """End the server (SIGTERM, SIGKILL after 10 s) and remove its directory."""
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> MongoServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
