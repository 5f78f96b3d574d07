"""Pure core of the web panel: config, access control, commands, arm geometry."""

import pytest

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_ur.panel_core import CommandError, PanelConfig, SiteState, arm_side_view, authorize, parse_command


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
    for bad, msg in [("nope", "not JSON"), ('{"op": "fly"}', "unknown op 'fly'"), ('{"op": "start"}', "non-empty"),
                     ('{"op": "cancel", "task_id": true}', "must be an integer"), ('{"op": "start", "task_ids": [0]}', "positive")]:
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
    import json

    s = SiteState()
    s.set_pose("ic120", 0, 0, 0)
    s.set_pose("ic120", 0.05, 0, 0)
    s.set_pose("ic120", 1.0, 0, 0)
    assert s.trails["ic120"] == [[0, 0], [1.0, 0]]
    s.event("error", "task 99: FAILURE: task 99 not found")
    assert json.loads(json.dumps(s.snapshot()))["events"][0]["text"].startswith("task 99")
