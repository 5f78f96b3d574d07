"""Pure core of the web panel: config, access control, commands, arm geometry."""

import json
from pathlib import Path

import pytest

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import ExcavatorKinematics, load_kinematics
from tms_model.fleet import load_named
from tms_model.machines import CRAWLER_DUMP, DOZER, EXCAVATOR
from tms_model.site import load_site
from tms_ur.panel_core import (
    INT32_MAX,
    INT32_MIN,
    TASK_ID_RANGE,
    CommandError,
    PanelConfig,
    SiteState,
    arm_side_view,
    authorize,
    check_origin,
    check_token,
    machine_info,
    parse_command,
    websocket_access,
)
from tms_ur.site_map import order_machines


def test_non_loopback_bind_requires_a_token():
    with pytest.raises(ConfigError, match="not loopback; set a 'token'"):
        PanelConfig(host="0.0.0.0")
    assert PanelConfig(host="0.0.0.0", token="s3cret").token == "s3cret"


def test_authorize_local_and_token():
    local = PanelConfig()
    assert authorize(local, "127.0.0.1", None) == (True, "local")
    assert authorize(local, "10.0.0.5", None)[0] is False
    remote = PanelConfig(host="0.0.0.0", token="s3cret")
    assert authorize(remote, "10.0.0.5", "s3cret") == (True, "token")
    ok, reason = authorize(remote, "10.0.0.5", "wrong")
    assert not ok and "without a valid token" in reason


def test_parse_commands_and_errors():
    assert parse_command('{"op": "start", "task_ids": [1, "2"]}').task_ids == (1, 2)
    assert parse_command('{"op": "cancel", "task_id": 7}').task_ids == (7,)
    assert parse_command('{"op": "emergency"}').op == "emergency"
    for bad, msg in [
        ("nope", "not JSON"),
        ('{"op": "fly"}', "unknown op 'fly'"),
        ('{"op": "start"}', "non-empty"),
        ('{"op": "cancel", "task_id": true}', "must be an integer"),
        ('{"op": "start", "task_ids": [0]}', r"out of range 1\.\.2147483647 \(task ids are positive int32\)"),
    ]:
        with pytest.raises(CommandError, match=msg):
            parse_command(bad)


def test_arm_side_view_zero_pose_matches_reference_geometry():
    kin = load_kinematics("zx200")
    pts = arm_side_view({}, kin)
    # zx200_ros2 URDF: at q = 0 the tip is at (10.435, ., 1.957) in base_link.
    assert pts[-1] == pytest.approx([10.435, 1.957], abs=0.01)
    # Boom up (-) raises the tip; the view is the model's forward kinematics in the front's plane.
    assert arm_side_view({"boom_joint": -0.5}, kin)[-1][1] > pts[-1][1]
    q = {"swing_joint": 0.7, "boom_joint": -0.5, "arm_joint": 1.2, "bucket_joint": 0.4}
    view = arm_side_view(q, kin)
    tip = kin.tip_position([0.0, -0.5, 1.2, 0.4])
    assert view[-1] == pytest.approx([tip[0], tip[2]], abs=1e-3)


def test_site_state_trail_thins_close_points_and_snapshot_is_json_ready():
    s = SiteState()
    s.set_pose("ic120", 0, 0, 0)
    s.set_pose("ic120", 0.05, 0, 0)
    s.set_pose("ic120", 1.0, 0, 0)
    assert s.trails["ic120"] == [[0, 0], [1.0, 0]]
    s.event("error", "task 99: FAILURE: task 99 not found")
    assert json.loads(json.dumps(s.snapshot()))["events"][0]["text"].startswith("task 99")


def _machines(names):
    site = load_site()
    return [load_named(name, site=site) for name in names]


@pytest.mark.parametrize("names", [["zx200", "ic120"], ["ic120", "ic120_1", "mst110cr", "zx200", "d37pxi_24"]],
                         ids=["paper", "three_carriers_excavator_dozer"])
def test_site_state_shows_each_machine_after_its_type(names):
    """The paper's two, and three carriers (two of one kind, one with a rotating upper body), an excavator and a
    dozer: the snapshot names them (what the page draws them with) and gives each the view its type has."""
    machines = order_machines(_machines(names))
    s = SiteState(machines=[machine_info(m) for m in machines])
    for i, m in enumerate(machines):
        kin = ExcavatorKinematics(m) if m.type == EXCAVATOR else None
        joints = {"swing_joint": 0.3, "boom_joint": -0.5, "arm_joint": 1.2, "bucket_joint": 0.4,
                  "vessel_joint": -0.2, "rotate_joint": 1.5, "lift_joint": 0.1}
        s.set_joints(m, {j: v for j, v in joints.items() if j in m.joint_names}, kin)
        s.set_pose(m.model_name, float(i), 0.0, 0.0)
        if m.type == CRAWLER_DUMP:
            s.set_load(m.model_name, 0.25 * i)
    snap = json.loads(json.dumps(s.snapshot()))
    assert [m["name"] for m in snap["machines"]] == [m.model_name for m in machines]
    assert snap["machines"][0]["type"] == EXCAVATOR  # excavators first: the page colours them first
    excavators = {m.model_name for m in machines if m.type == EXCAVATOR}
    carriers = {m.model_name for m in machines if m.type == CRAWLER_DUMP}
    dozers = {m.model_name for m in machines if m.type == DOZER}
    assert set(snap["arms"]) == excavators and set(snap["vessels"]) == carriers and set(snap["blades"]) == dozers
    for name in excavators:
        assert snap["arms"][name]["swing"] == pytest.approx(0.3) and len(snap["arms"][name]["side"]) == 4
    for m in machines:
        if m.type == CRAWLER_DUMP:
            vessel = snap["vessels"][m.model_name]
            assert vessel["angle"] == pytest.approx(-0.2) and "load" in vessel
            # a carrier whose vessel rides a rotating upper body shows its slew angle too
            assert ("swing" in vessel) == (m.swing is not None)
            if m.swing is not None:
                assert vessel["swing"] == pytest.approx(1.5)
    for name in dozers:
        assert snap["blades"][name]["lift"] == pytest.approx(0.1)
    sizes = {m["name"]: (m["length"], m["width"]) for m in snap["machines"]}
    assert all(length > 0 and width > 0 for length, width in sizes.values())


def test_site_state_plans_per_machine_are_thinned():
    s = SiteState()
    s.set_plan("ic120_1", [[float(i), 0.0] for i in range(2000)])
    assert 400 <= len(s.snapshot()["plans"]["ic120_1"]) <= 800


def test_panel_assets_name_no_machine():
    """The page draws whatever machines the server sends: no machine name in its script or markup."""
    web = Path(__file__).resolve().parents[2] / "tms_ur" / "web"
    names = set(load_site().machines) | {m.kind for m in load_site().machines.values()}
    for asset in ("panel.js", "index.html", "panel.css"):
        text = (web / asset).read_text().lower()
        assert not [n for n in names if n in text], asset


# -- websocket access: origin and token ---------------------------------------------------------------------

LOCAL = PanelConfig(port=8088)


def test_own_origin_is_accepted_under_every_loopback_name():
    # The panel's page opens ws://<its own address>/ws, so Origin == "http://" + Host.
    for host in ("127.0.0.1:8088", "localhost:8088", "[::1]:8088", "LOCALHOST:8088"):
        assert check_origin(LOCAL, [f"http://{host}"], host) == (True, "own origin"), host


def test_every_foreign_origin_is_refused_as_bad_origin():
    hostile = [
        "http://127.0.0.1:9999",  # another port on this host: another origin
        "http://127.0.0.2:8088",  # another loopback address than the one in Host
        "https://127.0.0.1:8088",  # another scheme
        "http://evil.example:8088",  # another site
        "null",  # sandboxed iframe, file:// page, data: URL
        "",
        "file://",
        "ws://127.0.0.1:8088",
        "http://127.0.0.1:8088/path",
        "http://127.0.0.1:8088?x",
        "http://user@127.0.0.1:8088",
        "http://127.0.0.1:notaport",
        "http://127.0.0.1:99999",
        "http://127.0.0.1",  # default port 80, not the panel's
        "http://127.0.0.1:8088\x00",
        "http://\u0127.0.0.1:8088",
        "http://" + "a" * 10_000 + ":8088",
    ]
    for origin in hostile:
        ok, reason = check_origin(LOCAL, [origin], "127.0.0.1:8088")
        assert not ok and reason.startswith("bad origin"), (origin, reason)
        assert len(reason) < 200  # one short line, whatever the client sent


def test_dns_rebinding_name_is_refused_on_a_loopback_panel():
    # evil.example resolved to 127.0.0.1: Host and Origin agree, but a loopback panel answers loopback names only.
    ok, reason = check_origin(LOCAL, ["http://evil.example:8088"], "evil.example:8088")
    assert not ok and "loopback name" in reason
    # Off loopback the name is the operator's to choose; the token is what a rebinding page lacks.
    remote = PanelConfig(host="0.0.0.0", port=8088, token="s3cret")
    assert check_origin(remote, ["http://site-server.lan:8088"], "site-server.lan:8088")[0] is True
    assert websocket_access(remote, ["http://site-server.lan:8088"], "site-server.lan:8088", None).commands is False


def test_origin_edge_cases_missing_repeated_host():
    # No Origin: a non-browser client (a browser always sends one); allowed, the token rule still applies.
    assert check_origin(LOCAL, [], "127.0.0.1:8088")[0] is True
    assert check_origin(LOCAL, ["http://127.0.0.1:8088", "http://127.0.0.1:8088"], "127.0.0.1:8088")[0] is False
    for host in (None, "", "127.0.0.1:8088/x", "a@127.0.0.1:8088", "127.0.0.1:x", "\u0127.0.0.1:8088"):
        assert check_origin(LOCAL, ["http://127.0.0.1:8088"], host)[0] is False, host
    # Host names another port than the panel's (a forwarded port): not the panel's own scheme://host:port.
    assert check_origin(LOCAL, ["http://127.0.0.1:80"], "127.0.0.1:80")[0] is False


def test_token_required_whenever_configured_and_compared_safely():
    assert check_token(LOCAL, None)[0] is True
    with_token = PanelConfig(host="0.0.0.0", token="s3cret")
    assert check_token(with_token, "s3cret") == (True, "token")
    assert check_token(with_token, None)[1].startswith("missing token")
    assert check_token(with_token, "")[1].startswith("missing token")
    for wrong in ("s3cre", "s3cret ", "S3CRET", "\u00e9", "\udcff", "x" * 100_000):
        assert check_token(with_token, wrong) == (False, "wrong token"), wrong
    # The HTTP-level check took a non-ASCII token to hmac.compare_digest, which raised TypeError.
    assert authorize(with_token, "10.0.0.5", "\u00e9")[0] is False


def test_websocket_access_combines_origin_and_token():
    own, host = ["http://127.0.0.1:8088"], "127.0.0.1:8088"
    assert websocket_access(LOCAL, own, host, None) == websocket_access(LOCAL, own, host, None)
    assert websocket_access(LOCAL, own, host, None).commands is True
    foreign = websocket_access(LOCAL, ["http://127.0.0.1:9999"], host, None)
    # A foreign page gets neither commands nor the live view, and the refusal names why.
    assert (foreign.commands, foreign.view, foreign.kind) == (False, False, "bad origin")
    remote = PanelConfig(host="0.0.0.0", port=8088, token="s3cret")
    no_token = websocket_access(remote, own, host, None)
    assert (no_token.commands, no_token.view, no_token.kind) == (False, True, "missing token")
    assert websocket_access(remote, own, host, "guess").kind == "wrong token"
    assert websocket_access(remote, own, host, "s3cret").commands is True
    # The right token does not make a foreign origin acceptable.
    assert websocket_access(remote, ["http://127.0.0.1:9999"], host, "s3cret").kind == "bad origin"


# -- id ranges -------------------------------------------------------------------------------------------------


def test_range_constants_match_the_generated_interfaces():
    # The panel's range is the interface type's; if a message changed type this must fail, not wrap silently.
    from std_msgs.msg import Int32

    from tms_msg.msg import TaskIds, TaskState
    from tms_msg_db.srv import TmsdbGetTask

    assert TaskIds.get_fields_and_field_types()["task_ids"] == "sequence<int32>"
    assert TaskState.get_fields_and_field_types()["task_id"] == "int32"
    assert Int32.get_fields_and_field_types()["data"] == "int32"
    assert TmsdbGetTask.Request.get_fields_and_field_types()["task_id"] == "int32"
    assert (INT32_MIN, INT32_MAX) == (-(2**31), 2**31 - 1) and TASK_ID_RANGE == (1, INT32_MAX)


def test_task_id_range_edges_and_hostile_values():
    assert parse_command(f'{{"op": "cancel", "task_id": {INT32_MAX}}}').task_ids == (INT32_MAX,)
    assert parse_command('{"op": "start", "task_ids": [1, " 7 ", "+3"]}').task_ids == (1, 7, 3)
    out_of_range = {
        '{"op": "cancel", "task_id": 4294967297}': "task_id: 4294967297 is out of range 1..2147483647",
        '{"op": "start", "task_ids": [2147483648]}': "task_ids: 2147483648 is out of range 1..2147483647",
        '{"op": "start", "task_ids": [1, "2147483648"]}': "task_ids: 2147483648 is out of range",
        '{"op": "cancel", "task_id": -2147483649}': "task_id: -2147483649 is out of range",
        '{"op": "cancel", "task_id": -1}': "task_id: -1 is out of range",
        '{"op": "cancel", "task_id": 1' + "0" * 4000 + "}": "task_id: 1000000000000000000000000000000000000...",
    }
    for text, msg in out_of_range.items():
        with pytest.raises(CommandError) as err:
            parse_command(text)
        assert str(err.value).startswith(msg), str(err.value)
        assert len(str(err.value)) < 120
    not_integers = ['"1_0"', '"\uff13"', '"\u0663"', '"0x10"', '"1e3"', "1e3", "1.0", "1e400", '""', '" "',
                    "null", "[1]", '{"a": 1}', '"' + "9" * 5000 + '"']
    for value in not_integers:
        with pytest.raises(CommandError, match="task id must be an integer"):
            parse_command(f'{{"op": "cancel", "task_id": {value}}}')


def test_json_that_made_the_parser_raise_is_a_command_error():
    # Each of these raised out of parse_command (RecursionError, ValueError) and ended the websocket.
    for text, msg in [("[" * 200_000 + "]" * 200_000, "nested too deep"),
                      ('{"op": "cancel", "task_id": ' + "1" * 5000 + "}", "Exceeds the limit"),
                      ('{"op": "start", "task_ids": [NaN]}', "must be an integer"),
                      ('{"op": "start", "task_ids": [Infinity]}', "must be an integer"),
                      ("\ud800", "not JSON"), ("", "not JSON")]:
        with pytest.raises(CommandError, match=msg):
            parse_command(text)
