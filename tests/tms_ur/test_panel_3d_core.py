"""The 3-D view's and the replay's pure parts of tms_ur.panel_core, without ROS: link poses in map composed from
/tf edges, terrain layers, the replay clock and its command; and which installed npm files the panel serves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tms_model.fleet import load_named
from tms_model.transform import quaternion_from_axis_angle
from tms_model.urdf import machine_tree
from tms_sp.terrain import TerrainError
from tms_ur.nodes.tms_ur_panel import WEB3D_DIR, _module_file
from tms_ur.panel_core import CommandError, ReplayClock, SiteTfView, TfError, parse_command, terrain_layer


@pytest.fixture
def view():
    return SiteTfView([machine_tree(load_named("zx200")), machine_tree(load_named("ic120"))])


def _frames(view, name):
    t = view.trees[name]
    return t.frame("odom"), t.frame("base_link"), t


def test_links_are_composed_into_map_with_the_base_stamp(view):
    odom, base, tree = _frames(view, "ic120")
    assert view.snapshot() == {}  # nothing reaches map yet
    view.set("map", odom, (10.0, 0.0, 0.0), quaternion_from_axis_angle((0, 0, 1), math.pi / 2), 5.0)
    assert view.snapshot() == {}
    view.set(odom, base, (1.0, 2.0, 0.5), (0.0, 0.0, 0.0, 1.0), 7.25)
    pose = view.machine_links("ic120")
    assert pose["stamp"] == 7.25
    assert pose["chain"] == {base: 7.25, odom: 5.0}  # the stamp of each edge drawn, base up to map
    # map_T_base = (10,0,0, yaw 90) * (1,2,0.5): x = 10 - 2, y = 1
    assert pose["links"][base][:3] == pytest.approx([8.0, 1.0, 0.5], abs=1e-5)
    # a child link reaches map once its fixed joint (static) is known
    child = next(j for j in tree.fixed if j.parent == "base_link")
    assert tree.frame(child.child) not in pose["links"]
    view.set(base, tree.frame(child.child), child.xyz, (0.0, 0.0, 0.0, 1.0), 0.0)
    assert tree.frame(child.child) in view.machine_links("ic120")["links"]
    assert "zx200" not in view.snapshot()


def test_bad_transforms_are_refused_naming_the_frames_and_unknown_frames_ignored(view):
    odom, base, _ = _frames(view, "zx200")
    with pytest.raises(TfError, match=f"{odom} -> {base}.*norm"):
        view.set(odom, base, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 2.0), 1.0)
    with pytest.raises(TfError, match="non-finite"):
        view.set(odom, base, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 1.0)
    v0 = view.version
    view.set("map", "other_site/base_link", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 1.0)
    assert view.version == v0 and view.machine_links("zx200") is None


def test_terrain_layer_is_row_major_in_image_order_and_checks_its_input():
    z = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    layer = terrain_layer("dynamic", "abc", z, 0.0, 10.0, 3.0, 12.0)
    assert (layer["rows"], layer["cols"], layer["z"][:3], layer["id"]) == (2, 3, [1.0, 2.0, 3.0], "abc")
    with pytest.raises(TerrainError, match="terrain dynamic abc: heights"):
        terrain_layer("dynamic", "abc", np.array([[np.nan]]), 0.0, 0.0, 1.0, 1.0)
    with pytest.raises(TerrainError, match="empty extent"):
        terrain_layer("static", "x", z, 1.0, 0.0, 1.0, 1.0)


def test_replay_clock_applies_messages_up_to_the_time_and_restarts_on_a_seek_back():
    clock = ReplayClock([1_000_000_000, 1_500_000_000, 2_000_000_000, 3_000_000_000])
    assert (clock.start, clock.end) == (1.0, 3.0)
    assert list(clock.due()) == [0]
    assert clock.seek(2.0) is False and list(clock.due()) == [1, 2]
    assert clock.seek(1.2) is True and list(clock.due()) == [0]  # back: refill from the first message
    clock.playing = True
    clock.advance(5.0)
    assert clock.t == 3.0 and not clock.playing and list(clock.due()) == [1, 2, 3]
    assert clock.seek(99.0) is False and clock.t == 3.0
    with pytest.raises(CommandError, match="no message"):
        ReplayClock([])
    with pytest.raises(CommandError, match="log-time order"):
        ReplayClock([2, 1])


def test_replay_command_is_parsed_and_bad_values_named():
    assert parse_command('{"op": "replay", "seek": 12.5}').seek == 12.5
    assert parse_command('{"op": "replay", "play": false}').play is False
    with pytest.raises(CommandError, match="'seek' must be a time"):
        parse_command('{"op": "replay", "seek": "soon"}')
    with pytest.raises(CommandError, match="'play' must be true or false"):
        parse_command('{"op": "replay", "play": 1}')
    with pytest.raises(CommandError, match="needs 'seek'"):
        parse_command('{"op": "replay"}')


def test_the_panel_serves_only_javascript_of_the_installed_packages_folders():
    assert (WEB3D_DIR / "node_modules" / "three").is_dir(), "npm ci in tms_ur/web3d (scripts/bootstrap.sh) not run"
    assert _module_file("three/build/three.module.js") is not None
    assert _module_file("urdf-loader/src/URDFLoader.js") is not None
    assert _module_file("three/package.json") is None  # not .js
    assert _module_file("three/build/../../urdf-loader/package.json") is None
    assert _module_file("three/examples/jsm/../../../../../pyproject.js") is None
    assert _module_file("three/build/no_such_file.js") is None
