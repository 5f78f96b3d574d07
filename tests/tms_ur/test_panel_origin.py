"""The panel's websocket takes commands only from its own page (and with the token when one is set), and task
ids only inside int32: real panel node, real headless chromium, rclpy subscriptions over DDS (issue 38).

A page served by a second HTTP server on another loopback port is another origin: a page of another site
open in the operator's browser. Before, its start, cancel and emergency stop all reached the machines.
"""

from __future__ import annotations

import http.server
import json
import threading
import time

import pytest

from tests.rosproc import executable
from tests.tms_ur.conftest import free_port

pytestmark = pytest.mark.integration

TOKEN = "t0k3n-for-this-test"


def _spin_until(node, predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        node.executor_for_test.spin_once(timeout_sec=0.05)
        if predicate():
            return True
    return False


def _listen(ros_node) -> dict[str, list]:
    """Subscribe to every topic the panel commands on, and wait until the panel's publishers are matched, so
    a message the panel published from now on is received (reliable QoS) and an empty list means none was."""
    from std_msgs.msg import Bool, Int32, String

    from tms_msg.msg import TaskIds

    got: dict[str, list] = {"start": [], "cancel": [], "emergency": [], "confirm": []}
    ros_node.create_subscription(TaskIds, "/tms_ts/start", lambda m: got["start"].append(list(m.task_ids)), 10)
    ros_node.create_subscription(Int32, "/tms_ts/cancel", lambda m: got["cancel"].append(m.data), 10)
    ros_node.create_subscription(Bool, "/emergency_signal", lambda m: got["emergency"].append(m.data), 10)
    ros_node.create_subscription(String, "/tms_ts/confirm", lambda m: got["confirm"].append(m.data), 10)
    topics = ("/tms_ts/start", "/tms_ts/cancel", "/emergency_signal", "/tms_ts/confirm")
    assert _spin_until(ros_node, lambda: all(ros_node.count_publishers(t) > 0 for t in topics), 20)
    _spin_until(ros_node, lambda: False, 1.0)  # let the readers match the writers both ways
    return got


def _panel(procs, tmp_path, port: int, *extra: str):
    panel = procs([executable("tms_ur", "tms_ur_panel"), "--ros-args", "-p", f"port:={port}",
                   "-p", f"db_path:={tmp_path / 'db'}", *extra])
    assert panel.wait_for("tms_ur_panel: serving http://", timeout=60), panel.output
    return panel


@pytest.fixture
def foreign_site():
    """A second HTTP server on another loopback port: its pages are another origin than the panel's.
    Yields ``serve(html) -> url``."""
    pages: dict[str, bytes] = {}

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # http.server's name
            body = pages.get(self.path.split("?")[0])
            self.send_response(200 if body else 404)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.end_headers()
            self.wfile.write(body or b"")

        def log_message(self, *args) -> None:  # keep pytest's output clean
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()

    def serve(html: str) -> str:
        pages["/"] = html.encode()
        return f"http://127.0.0.1:{server.server_address[1]}/"

    yield serve
    server.shutdown()
    server.server_close()


# Opens a websocket to the panel, sends the given commands once it is open, records every message received.
ATTACK_PAGE = """<!doctype html><meta charset="utf-8"><title>some other site</title><script>
window.got = []; window.wsClosed = null;
const ws = new WebSocket("ws://127.0.0.1:%(port)d/ws%(query)s");
ws.onmessage = (e) => window.got.push(JSON.parse(e.data));
ws.onclose = (e) => { window.wsClosed = e.code; };
ws.onopen = () => { for (const c of %(commands)s) ws.send(JSON.stringify(c)); };
</script>"""

ATTACK = [{"op": "start", "task_ids": [5]}, {"op": "emergency"}, {"op": "cancel", "task_id": 1},
          {"op": "confirm"}]


def _acks(page, count: int) -> list[dict]:
    page.wait_for_function(f"window.got.filter(m => m.type === 'ack').length >= {count}", timeout=15000)
    return [m for m in page.evaluate("window.got") if m["type"] == "ack"]


def test_page_from_another_origin_is_refused_and_own_page_still_works(procs, ros_node, browser_page, tmp_path,
                                                                       foreign_site):
    port = free_port()
    panel = _panel(procs, tmp_path, port)
    got = _listen(ros_node)
    page = browser_page

    attack_url = foreign_site(ATTACK_PAGE % {"port": port, "query": "", "commands": json.dumps(ATTACK)})
    attacker_origin = attack_url.rstrip("/")
    page.goto(attack_url)
    acks = _acks(page, len(ATTACK))
    # Every command refused with one message naming why; the connection stays open (no close event).
    for ack in acks:
        assert ack["ok"] is False and ack["refused"] == "bad origin", ack
        assert ack["text"].startswith(f"refused: bad origin '{attacker_origin}'"), ack
        assert f"http://127.0.0.1:{port}" in ack["text"]  # names the panel's own origin
    assert page.evaluate("window.wsClosed") is None
    # Two more live-view periods (5 Hz): another site does not get the site's state either.
    page.wait_for_timeout(600)
    assert [m["type"] for m in page.evaluate("window.got")] == ["ack"] * len(ATTACK)
    # Nothing reached ROS: the subscriptions were matched before the page sent anything.
    _spin_until(ros_node, lambda: False, 2.0)
    assert got == {"start": [], "cancel": [], "emergency": [], "confirm": []}, got

    # The panel's own page, in the same browser, still commands; the operator sees the refusal in the log.
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_selector("#conn.ok", timeout=20000)
    page.fill("#task-ids", "3")
    page.click("#start")
    assert _spin_until(ros_node, lambda: got["start"], 20), got
    page.wait_for_selector(f"#events li.error:has-text('(Origin: {attacker_origin}): bad origin')", timeout=10000)
    _spin_until(ros_node, lambda: False, 0.5)
    # Only the own page's start: the attack's [5], its emergency stop and its cancel of task 1 never came.
    assert got == {"start": [[3]], "cancel": [], "emergency": [], "confirm": []}, got
    # Logged once for the connection, not once per refused command.
    assert panel.output.count("refused commands from 127.0.0.1") == 1, panel.output


def test_out_of_range_ids_are_refused_and_the_connection_stays_usable(procs, ros_node, browser_page, tmp_path):
    port = free_port()
    _panel(procs, tmp_path, port)
    got = _listen(ros_node)
    page = browser_page
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_selector("#conn.ok", timeout=20000)
    # One websocket from the panel's own page, as its buttons use: two out-of-range ids, then two good commands.
    acks = page.evaluate("""async () => {
        const ws = new WebSocket(`ws://${location.host}/ws`);
        const acks = [];
        await new Promise((ok) => { ws.onopen = ok; });
        // all four acks, or what came before the socket closed or 15 s passed (the failure to report)
        const done = new Promise((ok) => { ws.onmessage = (e) => {
            const m = JSON.parse(e.data); if (m.type === "ack") { acks.push(m); if (acks.length === 4) ok(); } };
            ws.onclose = ok; setTimeout(ok, 15000); });
        for (const c of [{op: "cancel", task_id: 4294967297}, {op: "start", task_ids: [2 ** 31]},
                         {op: "start", task_ids: [7]}, {op: "cancel", task_id: 2}]) ws.send(JSON.stringify(c));
        await done;
        return {acks, open: ws.readyState === WebSocket.OPEN};
    }""")
    a = acks["acks"]
    assert len(a) == 4 and acks["open"], acks
    assert a[0]["ok"] is False and a[0]["text"] == "task_id: 4294967297 is out of range 1..2147483647 " \
        "(task ids are positive int32)", a[0]
    assert a[1]["ok"] is False and a[1]["text"].startswith("task_ids: 2147483648 is out of range 1..2147483647"), a[1]
    # The same socket took the next commands: the errors did not end the connection.
    assert a[2]["ok"] is True and a[3]["ok"] is True and acks["open"] is True, acks
    assert _spin_until(ros_node, lambda: got["start"] and got["cancel"], 20), got
    _spin_until(ros_node, lambda: False, 0.5)
    # 4294967297 did not wrap to a cancel of task 1; 2**31 did not become a start of task -2147483648.
    assert got["start"] == [[7]] and got["cancel"] == [2], got
    page.wait_for_selector("#events li.error:has-text('4294967297 is out of range')", timeout=10000)


def test_non_browser_client_without_origin_is_allowed_on_loopback(procs, ros_node, tmp_path):
    """The documented choice: no Origin header = not a browser (a page cannot omit it); on a loopback panel
    without a token such a client commands, as any local program could publish on the topics directly."""
    from websockets.sync.client import connect

    port = free_port()
    _panel(procs, tmp_path, port)
    got = _listen(ros_node)
    with connect(f"ws://127.0.0.1:{port}/ws", open_timeout=10) as ws:
        ws.send(json.dumps({"op": "start", "task_ids": [8]}))
        ack = _recv_ack(ws)
        assert ack["ok"] is True, ack
    # A client that forges a foreign Origin is treated as the page it pretends to be.
    with connect(f"ws://127.0.0.1:{port}/ws", origin="http://evil.example", open_timeout=10) as ws:
        ws.send(json.dumps({"op": "emergency"}))
        ack = _recv_ack(ws)
        assert ack["refused"] == "bad origin", ack
    assert _spin_until(ros_node, lambda: got["start"], 20), got
    _spin_until(ros_node, lambda: False, 1.0)
    assert got["start"] == [[8]] and got["emergency"] == [], got


def _recv_ack(ws) -> dict:
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        msg = json.loads(ws.recv(timeout=10))
        if msg["type"] == "ack":
            return msg
    raise AssertionError("no ack within 10 s")


def test_off_loopback_panel_commands_only_with_the_token(procs, ros_node, browser_page, tmp_path):
    """Bound off loopback (0.0.0.0; the test runs in a loopback-only namespace under scripts/isolated.sh), the
    own page without the token sees the live view but its commands are refused as 'missing token'."""
    port = free_port()
    panel = _panel(procs, tmp_path, port, "-p", "host:=0.0.0.0", "-p", f"token:={TOKEN}")
    assert TOKEN not in panel.output  # the log says a token is needed, it does not give it away
    got = _listen(ros_node)
    page = browser_page
    page.goto(f"http://127.0.0.1:{port}/")
    page.wait_for_selector("#conn.ok", timeout=20000)
    page.wait_for_function("last !== null && last.type === 'state'", timeout=10000)  # the view is open
    page.fill("#task-ids", "4")
    page.click("#start")
    page.keyboard.press("Escape")
    page.wait_for_selector("#events li.error:has-text('refused: missing token')", timeout=10000)
    # A wrong token is named as such.
    wrong = page.evaluate("""async () => {
        const ws = new WebSocket(`ws://${location.host}/ws?token=guess`);
        await new Promise((ok) => { ws.onopen = ok; });
        const ack = new Promise((ok) => { ws.onmessage = (e) => { const m = JSON.parse(e.data);
            if (m.type === "ack") ok(m); }; });
        ws.send(JSON.stringify({op: "emergency"}));
        return await ack;
    }""")
    assert wrong["refused"] == "wrong token", wrong
    _spin_until(ros_node, lambda: False, 2.0)
    assert got == {"start": [], "cancel": [], "emergency": [], "confirm": []}, got
    # The same page opened with the token commands.
    page.goto(f"http://127.0.0.1:{port}/?token={TOKEN}")
    page.wait_for_selector("#conn.ok", timeout=20000)
    page.fill("#task-ids", "4")
    page.click("#start")
    assert _spin_until(ros_node, lambda: got["start"], 20), got
    assert got["start"] == [[4]] and got["emergency"] == [], got
