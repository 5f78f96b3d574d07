"""Shared fixtures: an isolated ROS domain per test and processes that are always cleaned up."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest

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
