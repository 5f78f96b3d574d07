"""``config/launch/tms_db_manager.yaml`` composed by tms-launch: every node of the original's DB boundary comes up,
a machine's joint states reach ``tms_db_reader`` through ``tms_sp_machine`` and ``tms_db_writer``, Ctrl-C stops it."""

from __future__ import annotations

import os
import signal

import pytest

from tests.rosproc import ROOT, VENV
from tests.tms_db.test_boundary_nodes import _get_data, _publisher, _until
from tms_model.site import load_site

pytestmark = pytest.mark.integration

LAUNCH = ROOT / "config" / "launch" / "tms_db_manager.yaml"


def test_launch_file_serves_the_boundary(procs, ros_node, tmp_path) -> None:
    from sensor_msgs.msg import JointState

    from tms_msg_db.srv import TmsdbGetData

    machine = sorted(load_site().machines)[0]
    launcher = procs([VENV / "bin" / "tms-launch", str(LAUNCH)], name="tms-launch", TMS_DB_PATH=str(tmp_path / "db"))
    assert launcher.wait_for("are up; Ctrl-C stops them (3 process(es), composed layout)", 180), launcher.output
    nodes = {"tms_db_writer", "tms_db_reader", "tms_db_writer_query", "tms_db_param_reader", "tms_db_writer_collision",
             "tms_db_writer_gridfs", "tms_db_reader_gridfs", "tms_sp_machine"}
    _until(ros_node, lambda: nodes <= {n for n, _ in ros_node.get_node_names_and_namespaces()}, 30, "every node")
    services = {"/tms_db_reader", "/tms_db_param_reader", "/tms_db_reader_task", "/tms_db_reader_parameter",
                "/tms_db_reader_gridfs/_action/send_goal"}
    _until(ros_node, lambda: services <= {n for n, _ in ros_node.get_service_names_and_types()}, 30, "every service")
    joints = _publisher(ros_node, JointState, f"/{machine}/joint_states", launcher)
    get = ros_node.create_client(TmsdbGetData, "/tms_db_reader")

    def stored() -> list:
        joints.publish(JointState(name=["j"], position=[0.25]))
        return _get_data(ros_node, get, "machine_joints", 3012, machine, latest_only=True)

    row = _until(ros_node, stored, 30, f"{machine}'s joints in the DB", launcher)[0]
    assert row[4]["position"] == [0.25] and row[3] == machine
    os.kill(launcher.popen.pid, signal.SIGINT)
    assert launcher.wait(30) == 0, launcher.output
