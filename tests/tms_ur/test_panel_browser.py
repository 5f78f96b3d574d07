"""The web panel in a real headless browser, and its access control over a real network namespace."""

from __future__ import annotations

import subprocess
import time
import uuid

import pytest

from tests.rosproc import executable
from tests.tms_ur.conftest import free_port

pytestmark = pytest.mark.integration


def _spin_until(node, predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        node.executor_for_test.spin_once(timeout_sec=0.05)
        if predicate():
            return True
    return False


def test_buttons_publish_start_cancel_confirm_and_escape_is_emergency(procs, ros_node, browser_page, tmp_path):
    from std_msgs.msg import Bool, Int32, String

    from tms_msg.msg import TaskIds

    port = free_port()
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", f"port:={port}",
                   "-p", f"db_path:={tmp_path / 'db'}"])
    assert panel.wait_for("serving http://127.0.0.1", timeout=60), panel.output
    got: dict[str, list] = {"start": [], "cancel": [], "emergency": [], "confirm": []}
    ros_node.create_subscription(TaskIds, "/tms_ts/start", lambda m: got["start"].append(list(m.task_ids)), 10)
    ros_node.create_subscription(Int32, "/tms_ts/cancel", lambda m: got["cancel"].append(m.data), 10)
    ros_node.create_subscription(Bool, "/emergency_signal", lambda m: got["emergency"].append(m.data), 10)
    ros_node.create_subscription(String, "/tms_ts/confirm", lambda m: got["confirm"].append(m.data), 10)
    page = browser_page
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_selector("#conn.ok", timeout=20000)
    # Wait until the panel's publishers are matched by our subscriptions (DDS discovery).
    assert _spin_until(ros_node, lambda: ros_node.count_publishers("/tms_ts/start") > 0, 20)
    _spin_until(ros_node, lambda: False, 1.0)
    page.fill("#task-ids", "3 4")
    page.click("#start")
    page.click("#confirm")
    page.keyboard.press("Escape")
    assert _spin_until(ros_node, lambda: got["start"] and got["emergency"] and got["confirm"], 20), got
    assert got["start"][0] == [3, 4]
    assert got["emergency"][0] is True and got["confirm"][0] == "yes"
    page.wait_for_selector("#events li:has-text('EMERGENCY STOP sent')", timeout=10000)
    # A malformed id is refused with the reason, nothing published.
    page.fill("#task-ids", "x")
    page.click("#start")
    page.wait_for_selector("#events li.error:has-text('must be an integer')", timeout=10000)
    _spin_until(ros_node, lambda: False, 1.0)
    assert len(got["start"]) == 1


@pytest.mark.parametrize("machines", [["zx200", "ic120"], ["ic120", "ic120_1", "mst110cr", "zx200"]],
                         ids=["paper", "three_carriers_and_excavator"])
def test_the_page_shows_the_machines_the_server_names(procs, ros_node, browser_page, tmp_path, machines):
    """The machine list is a node parameter; the page draws and describes whatever machines the snapshot names:
    each one's pose, the excavator's arm, each carrier's vessel (the MST's upper body too) and load."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    port = free_port()
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", f"port:={port}",
                   "-p", f"db_path:={tmp_path / 'db'}", "-p", f"machines:={machines!r}".replace("'", '"')])
    assert panel.wait_for("serving http://127.0.0.1", timeout=60), panel.output
    poses = {m: ros_node.create_publisher(PoseStamped, f"/sim/truth/{m}/pose", 10) for m in machines}
    joints = {m: ros_node.create_publisher(JointState, f"/{m}/joint_states", 10) for m in machines}
    soil = {m: ros_node.create_publisher(Float64MultiArray, f"/sim/truth/{m}/soil", 10) for m in machines}
    assert _spin_until(ros_node, lambda: all(p.get_subscription_count() > 0 for p in poses.values()), 30)
    page = browser_page
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_selector("#conn.ok", timeout=20000)

    def publish() -> None:
        for i, m in enumerate(machines):
            pose = PoseStamped()
            pose.pose.position.x, pose.pose.orientation.w = 5.0 * i, 1.0
            poses[m].publish(pose)
            js = JointState(name=["swing_joint", "boom_joint", "arm_joint", "bucket_joint", "vessel_joint",
                                  "rotate_joint"], position=[0.3, -0.5, 1.2, 0.4, -0.2, 1.5])
            joints[m].publish(js)
            load = Float64MultiArray(data=[0.5 * i, 0.5 * i, 0.0])
            load.layout.dim = [MultiArrayDimension(label="vessel,loaded,dumped", size=3, stride=3)]
            soil[m].publish(load)

    def shown() -> bool:
        publish()
        return all(page.query_selector(f"#pose-{m}") and page.query_selector(f"#state-{m}") for m in machines)

    assert _spin_until(ros_node, shown, 30), page.inner_text("body")
    assert "zx200 swing 0.30 rad" in page.inner_text("#state-zx200")
    for m in machines:
        if m != "zx200":
            assert page.inner_text(f"#state-{m}").startswith(f"{m} vessel -0.20 rad"), page.inner_text(f"#state-{m}")
            assert "load" in page.inner_text(f"#state-{m}")
    if "mst110cr" in machines:  # its vessel rides a rotating upper body
        assert "upper body 1.50 rad" in page.inner_text("#state-mst110cr")
    assert "upper body" not in page.inner_text(f"#state-{machines[1]}")


@pytest.fixture
def netns_client():
    """A second host in a network namespace (veth 10.231.x.0/24); yields (host_ip, run_in_ns)."""
    ns = f"tmsur{uuid.uuid4().hex[:6]}"
    octet = int(uuid.uuid4().int % 200) + 20
    host_if, ns_if = f"vh{ns[-6:]}", f"vn{ns[-6:]}"
    host_ip, ns_ip = f"10.231.{octet}.1", f"10.231.{octet}.2"
    try:
        for cmd in (["ip", "netns", "add", ns], ["ip", "link", "add", host_if, "type", "veth", "peer", "name", ns_if],
                    ["ip", "link", "set", ns_if, "netns", ns], ["ip", "addr", "add", f"{host_ip}/24", "dev", host_if],
                    ["ip", "link", "set", host_if, "up"],
                    ["ip", "netns", "exec", ns, "ip", "addr", "add", f"{ns_ip}/24", "dev", ns_if],
                    ["ip", "netns", "exec", ns, "ip", "link", "set", ns_if, "up"],
                    ["ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up"]):
            subprocess.run(cmd, check=True, capture_output=True, timeout=10)
    except (subprocess.CalledProcessError, FileNotFoundError, PermissionError) as exc:
        subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        pytest.skip(f"network namespaces unavailable (needs root and iproute2): {exc}")

    def run_in_ns(*cmd: str) -> subprocess.CompletedProcess:
        return subprocess.run(["ip", "netns", "exec", ns, *cmd], capture_output=True, text=True, timeout=20)

    yield host_ip, run_in_ns
    subprocess.run(["ip", "link", "del", host_if], capture_output=True)
    subprocess.run(["ip", "netns", "del", ns], capture_output=True)


def test_non_local_request_without_token_is_refused(procs, netns_client, tmp_path):
    host_ip, run_in_ns = netns_client
    port = free_port()
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", f"port:={port}", "-p", f"host:={host_ip}",
                   "-p", "token:=let-me-in", "-p", f"db_path:={tmp_path / 'db'}"])
    assert panel.wait_for(f"serving http://{host_ip}", timeout=60), panel.output
    url = f"http://{host_ip}:{port}/"
    refused = run_in_ns("curl", "-s", "-o", "/dev/null", "-w", "%{http_code}", url)
    assert refused.stdout == "403", refused
    wrong = run_in_ns("curl", "-s", "-o", "/dev/null", "-w", "%{http_code}", url + "?token=nope")
    assert wrong.stdout == "403"
    allowed = run_in_ns("curl", "-s", url + "?token=let-me-in")
    assert "EMERGENCY STOP" in allowed.stdout


def test_non_loopback_bind_without_token_refuses_to_start(procs, tmp_path):
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", "host:=0.0.0.0",
                   "-p", f"db_path:={tmp_path / 'db'}"])
    assert panel.wait(60) == 2, panel.output
    assert "bind address '0.0.0.0' is not loopback; set a 'token'" in panel.output
