"""A running tms_ts system for integration tests: DB on disk, planning stub, subtask servers, manager."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import pytest

from tests.rosproc import ROOT, executable


@dataclass
class TsSystem:
    node: object
    store: object
    db: str
    #: a mongodb:// URI: the nodes open it instead of ``db`` (a test sets it and ``store`` before ``start``)
    db_uri: str = ""
    procs: dict = field(default_factory=dict)
    statuses: list = field(default_factory=list)

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.node.executor_for_test.spin_once(timeout_sec=0.05)

    def task(self, task_id: int):
        """Latest TaskState of ``task_id`` (None if never reported)."""
        for status in reversed(self.statuses):
            for t in status.tasks:
                if t.task_id == task_id:
                    return t
        return None

    def wait(self, predicate, timeout: float, what: str):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.node.executor_for_test.spin_once(timeout_sec=0.05)
            value = predicate()
            if value:
                return value
        out = "\n".join(f"--- {n}\n{p.output[-3000:]}" for n, p in self.procs.items())
        raise AssertionError(f"timed out after {timeout} s waiting for {what}\n{out}")

    def publish(self, topic: str, msg) -> None:
        pub = self.pubs[topic]
        self.wait(lambda: pub.get_subscription_count() > 0, 20, f"a subscriber on {topic}")
        pub.publish(msg)


@pytest.fixture
def ts_system(tmp_path, procs, ros_node):
    """``start(stub_duration_s=..., ignore_cancel=False, server_wait_s=..., manager_args=("-p", "k:=v"))`` -> TsSystem
    (seed the DB first)."""
    from std_msgs.msg import Bool, Int32, String

    from tms_db import open_store
    from tms_msg.msg import TaskIds, TaskStatus

    db = str(tmp_path / "db")
    store = open_store(path=db)
    system = TsSystem(node=ros_node, store=store, db=db)
    ros_node.create_subscription(TaskStatus, "/tms_ts/status", system.statuses.append, 50)
    system.pubs = {
        "/tms_ts/start": ros_node.create_publisher(TaskIds, "/tms_ts/start", 50),
        "/tms_ts/cancel": ros_node.create_publisher(Int32, "/tms_ts/cancel", 50),
        "/emergency_signal": ros_node.create_publisher(Bool, "/emergency_signal", 50),
        "/tms_ts/confirm": ros_node.create_publisher(String, "/tms_ts/confirm", 50),
    }

    def start(stub_duration_s: float = 0.3, ignore_cancel: bool = False, server_wait_s: float = 20.0,
              halt_timeout_s: float = 5.0, stop_timeout_s: float = 5.0, manager_args: tuple[str, ...] = ()) -> TsSystem:
        db_params = ["-p", f"db_path:={db}", *(["-p", f"db_uri:={system.db_uri}"] if system.db_uri else [])]
        system.procs["stub"] = procs(
            [sys.executable, "-m", "tests.tms_ts.planning_stub", "--ros-args", "-p", f"duration_s:={stub_duration_s}",
             "-p", f"ignore_cancel:={'true' if ignore_cancel else 'false'}"], name="stub", PYTHONPATH=str(ROOT))
        for machine in ("zx200", "ic120"):
            system.procs[machine] = procs(
                [
                    executable("tms_ts", "tms_ts_subtasks"),
                    "--ros-args",
                    "-p",
                    f"machine:={machine}",
                    *db_params,
                    "-p",
                    f"stop_timeout_s:={stop_timeout_s}",
                    "-p",
                    "planning_wait_s:=20.0",
                ],
                name=machine,
            )
        system.procs["manager"] = procs(
            [executable("tms_ts", "tms_ts_manager"), "--ros-args", *db_params,
             "-p", f"server_wait_s:={server_wait_s}", "-p", f"halt_timeout_s:={halt_timeout_s}",
             "-p", "tick_rate_hz:=20.0", "-p", "status_rate_hz:=4.0",
             # as every launch file: the original's 1 s default tripped on a loaded 2-core CI machine ("did not
             # accept the goal ... within 1 s" for a server that accepted it)
             "-p", "accept_timeout_s:=5.0", *manager_args], name="manager")
        for name, text in (("stub", "planning stub ready"), ("zx200", "subtask servers"),
                           ("ic120", "subtask servers"), ("manager", "tms_ts_manager ready")):
            assert system.procs[name].wait_for(text, 60), f"{name} did not start:\n{system.procs[name].output}"
        return system

    system.start = start
    yield system
    store.close()
