"""Shared fixtures: an isolated ROS domain per test, processes that are always cleaned up, a MongoDB server; the
per-backend counts of the store's tests at the end of the run."""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterator

import pytest

from tests.mongo_server import MongoServer, MongoServerError
from tests.rosproc import VENV, Proc, isolated_domain, ros_env
from tms_common.dds import use_platform_profiles

# every rclpy context of the test process, and every process a test starts, use the platform's DDS profiles
use_platform_profiles()


@pytest.fixture
def domain() -> Iterator[int]:
    """A ROS_DOMAIN_ID held exclusively by this test."""
    with isolated_domain() as d:
        yield d


@pytest.fixture
def procs(domain: int) -> Iterator[callable]:
    """``start(cmd, **env)`` runs a process on the test's domain; all are killed at teardown."""
    started: list[Proc] = []

    def start(cmd: list[str], name: str | None = None, **env: str) -> Proc:
        proc = Proc([str(c) for c in cmd], ros_env(domain, **env), name=name)
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.kill()


@pytest.fixture
def ros_node(domain: int):
    """An rclpy node in this test process, in its own Context on the test's domain."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("AMENT_PREFIX_PATH", str(VENV))
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("test_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    node.executor_for_test = executor
    yield node
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)


@pytest.fixture(scope="session")
def mongodb_uri() -> Iterator[str]:
    """The URI of a MongoDB server for the session: ``$TMS_MONGODB_URI`` (the user's server) when set, else a
    SecantusDB server this fixture starts on a free loopback port with temporary storage and stops at the end.
    A server that cannot start fails every test that needs it, with the server's output: it is part of the test
    extra, so its absence is a broken install, not a missing capability."""
    uri = os.environ.get("TMS_MONGODB_URI", "")
    if uri:
        yield uri
        return
    server = MongoServer()
    try:
        server.start()
        problem = ""
    except MongoServerError as exc:
        problem = str(exc)
    if problem:  # outside the except block: the report shows the server's output once
        server.stop()
        pytest.fail(f"the test MongoDB server did not start: {problem}", pytrace=False)
    try:
        yield server.uri
    finally:
        server.stop()


#: the params that name a store backend: the ``store`` fixture of tests/tms_db, ``backend`` of cross-process tests
_BACKEND_PARAMS = ("store", "backend")
_BACKENDS = ("embedded", "mongodb")
_backend_of: dict[str, str] = {}
_OUTCOMES = ("passed", "failed", "error", "skipped", "xfailed", "xpassed", "deselected")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        params = getattr(getattr(item, "callspec", None), "params", {})
        for name in _BACKEND_PARAMS:
            if params.get(name) in _BACKENDS:
                _backend_of[item.nodeid] = params[name]


def pytest_terminal_summary(terminalreporter) -> None:
    """``tms_db on embedded: N passed, ...; on mongodb: M passed, ...``: the store's tests per backend (by the test
    ids' params), so a run where one backend only skipped or failed shows it."""
    counts: dict[str, Counter] = {b: Counter() for b in _BACKENDS}
    for outcome, reports in terminalreporter.stats.items():
        for report in reports:
            backend = _backend_of.get(getattr(report, "nodeid", ""))
            # one outcome per test: the call's, or the setup's / teardown's when that is what failed or skipped
            if backend and outcome in _OUTCOMES and (getattr(report, "when", "call") == "call"
                                                     or outcome in ("error", "skipped")):
                counts[backend][outcome] += 1
    if any(counts.values()):
        parts = [f"{b}: " + (", ".join(f"{n} {o}" for o, n in sorted(counts[b].items())) or "none run")
                 for b in _BACKENDS]
        terminalreporter.write_line(f"tms_db on {parts[0]}; on {parts[1]}")
