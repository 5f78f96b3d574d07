"""tms_sp.site_tf (ROS-free): the site's transform tree from joint states, odometry and localisation."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_model.geometry import quaternion_from_yaw
from tms_model.site import load_site
from tms_model.transform import Transform
from tms_model.urdf import load_tree, machine_tree
from tms_sp.site_tf import MAP, WORLD, SiteTf, StampedTransform

FRONT = ("swing_joint", "boom_joint", "arm_joint", "bucket_joint")


@pytest.fixture(scope="module")
def site_tf() -> SiteTf:
    return SiteTf([load_tree("zx200"), load_tree("ic120")], load_site())


def lookup(edges: list[StampedTransform], target: str, source: str) -> Transform:
    """``target_T_source`` composed from edges (each child has one parent), as a tf listener does."""
    parent = {e.child: e for e in edges}
    out = Transform()
    frame = source
    while frame != target:
        assert frame in parent, f"no path from {source!r} to {target!r}: stuck at {frame!r}"
        out = parent[frame].transform * out
        frame = parent[frame].parent
    return out


def test_static_world_map_and_fixed_joints(site_tf: SiteTf) -> None:
    edges = {(e.parent, e.child): e for e in site_tf.static(12.5)}
    assert set(edges) == {(WORLD, MAP), ("base_link", "track_link"), ("bucket_link", "bucket_end_link"),
                          ("ic120_tf/base_link", "ic120_tf/body_link")}
    assert edges[(WORLD, MAP)].transform.translation == load_site().origin_plane
    assert np.allclose(edges[("bucket_link", "bucket_end_link")].transform.translation, (1.2, 0.0, 1.0))
    assert all(e.stamp == 12.5 for e in edges.values())


def test_map_to_bucket_tip_is_the_kinematics_on_the_excavator_pose(site_tf: SiteTf) -> None:
    kin = load_kinematics("zx200")
    x, y, yaw = 3.0, -4.0, 0.7
    swing_origin = np.array(kin.machine.joint("swing_joint").origin_xyz)
    # com3_bridge's ZX200 odom_pose is the swing centre (COM3 Swing_Center_Position) in map
    centre = Transform.from_yaw(x, y, 0.0, yaw).apply(swing_origin)
    odom = site_tf.odometry("zx200", "map", centre, quaternion_from_yaw(yaw), 5.0)
    assert [(e.parent, e.child) for e in odom] == [(MAP, "odom"), ("odom", "base_link")]
    assert odom[0].transform == Transform()
    rng = np.random.default_rng(1)
    for i in range(50):
        q = rng.uniform([-math.pi, -1.1, 0.6, -0.6], [math.pi, -0.1, 2.6, 2.3])
        joints = site_tf.joint_states("zx200", [*FRONT, "left_track"], [*q, 9.0], 5.01 + 0.01 * i)
        assert [(e.parent, e.child) for e in joints] == [
            ("track_link", "body_link"),
            ("body_link", "boom_link"),
            ("boom_link", "arm_link"),
            ("arm_link", "bucket_link"),
        ]
        tip = lookup(site_tf.static(0.0) + odom + joints, MAP, "bucket_end_link").translation
        expected = Transform.from_yaw(x, y, 0.0, yaw).apply(kin.tip_position(q))
        assert np.linalg.norm(np.array(tip) - expected) < 1e-9


def test_ic120_odom_and_localisation_compose_to_the_map_pose(site_tf: SiteTf) -> None:
    odom_pose = Transform.from_yaw(2.0, 1.0, 0.0, 0.3)  # odometry: drifted
    correction = Transform.from_yaw(10.0, -3.0, 0.0, -0.1)  # localisation: map -> odom
    edges = site_tf.odometry("ic120", "odom", odom_pose.translation, odom_pose.rotation, 1.0)
    assert [(e.parent, e.child) for e in edges] == [("ic120_tf/odom", "ic120_tf/base_link")]
    edges += site_tf.map_to_odom("ic120", "map", correction.translation, correction.rotation, 1.0)
    edges += site_tf.joint_states("ic120", ["vessel_joint", "left_track", "right_track"], [0.5, 1.0, 2.0], 1.0)
    edges += site_tf.static(0.0)
    base = lookup(edges, MAP, "ic120_tf/base_link")
    want = correction * odom_pose
    assert np.allclose(base.translation, want.translation) and np.allclose(base.matrix(), want.matrix())
    vessel = lookup(edges, "ic120_tf/base_link", "ic120_tf/vessel_pin_link")
    assert np.allclose(vessel.translation, load_tree("ic120").machine.vessel.hinge_xyz)
    assert vessel.apply((3.0, 0.0, 0.0))[2] > 2.0  # raised 0.5 rad: the vessel's front end is up


def test_an_edge_is_given_once_per_stamp_as_tf2_keeps_it(site_tf: SiteTf) -> None:
    """Two odometry messages at one stamp (the converter stamps with the last /clock): the second gives nothing,
    as tf2's buffer keeps the first; a new stamp, or an edge not yet given at that stamp, is given."""
    first = site_tf.odometry("ic120", "odom", (1.0, 0.0, 0.0), (0, 0, 0, 1), 3.0)
    assert [e.transform.translation for e in first] == [(1.0, 0.0, 0.0)]
    assert site_tf.odometry("ic120", "odom", (1.02, 0.0, 0.0), (0, 0, 0, 1), 3.0) == []
    assert site_tf.map_to_odom("ic120", "map", (0, 0, 0), (0, 0, 0, 1), 3.0) != []  # another edge, same stamp
    later = site_tf.odometry("ic120", "odom", (1.02, 0.0, 0.0), (0, 0, 0, 1), 3.02)
    assert [e.transform.translation for e in later] == [(1.02, 0.0, 0.0)]
    # the excavator's pose in map: both its edges at a stamp once
    assert len(site_tf.odometry("zx200", "map", (0, 0, 0), (0, 0, 0, 1), 3.0)) == 2
    assert site_tf.odometry("zx200", "map", (0.01, 0, 0), (0, 0, 0, 1), 3.0) == []
    # a sim reset (time back) is a new stamp
    assert len(site_tf.odometry("ic120", "odom", (0.0, 0.0, 0.0), (0, 0, 0, 1), 0.5)) == 1


def test_bad_input_is_refused_naming_machine_and_field(site_tf: SiteTf) -> None:
    with pytest.raises(ValueError, match="zx200: joint_states boom_joint position is not finite"):
        site_tf.joint_states("zx200", list(FRONT), [0.0, math.nan, 1.0, 1.0], 0.0)
    with pytest.raises(ValueError, match="zx200: joint_states has 4 names but 3 positions"):
        site_tf.joint_states("zx200", list(FRONT), [0.0, 1.0, 1.0], 0.0)
    with pytest.raises(ValueError, match="ic120: odometry frame 'earth' is neither"):
        site_tf.odometry("ic120", "earth", (0, 0, 0), (0, 0, 0, 1), 0.0)
    with pytest.raises(ValueError, match="ic120: odometry orientation quaternion has norm 0.0000"):
        site_tf.odometry("ic120", "odom", (0, 0, 0), (0, 0, 0, 0), 0.0)
    with pytest.raises(ValueError, match="ic120: odometry position is not finite"):
        site_tf.odometry("ic120", "odom", (math.inf, 0, 0), (0, 0, 0, 1), 0.0)
    with pytest.raises(ValueError, match="ic120: map_to_odom parent frame 'odom' is not 'map'"):
        site_tf.map_to_odom("ic120", "odom", (0, 0, 0), (0, 0, 0, 1), 0.0)
    with pytest.raises(KeyError, match="no machine 'zx120' in the site tree"):
        site_tf.joint_states("zx200".replace("200", "120"), list(FRONT), [0.0] * 4, 0.0)


def test_two_machines_with_the_same_frames_are_refused() -> None:
    zx = load_tree("zx200")
    twin = machine_tree(dataclasses.replace(zx.machine, name="zx200b"))
    with pytest.raises(
        ConfigError, match="frame 'odom' of zx200b is also a frame of zx200; give one of them a tf_prefix"
    ):
        SiteTf([zx, twin], load_site())
    prefixed = machine_tree(dataclasses.replace(zx.machine, name="zx200b", tf_prefix="zx200b_tf"))
    assert SiteTf([zx, prefixed], load_site()).trees["zx200b"].frame("odom") == "zx200b_tf/odom"
    with pytest.raises(ConfigError, match="machine 'zx200' is given twice"):
        SiteTf([zx, zx], load_site())


def test_machines_of_one_kind_are_one_tree_each_with_their_own_frames() -> None:
    """Three machines of one kind (names of config/site.yaml): three trees keyed by name, frames prefixed by name,
    each moved only by its own joint_states."""
    names = ("ic120", "ic120_1", "ic120_2")
    site = SiteTf([load_tree(n) for n in names], load_site())
    assert set(site.trees) == set(names) and {t.kind for t in site.trees.values()} == {"ic120"}
    assert {n: site.tree(n).frame("vessel_pin_link") for n in names} == {n: f"{n}_tf/vessel_pin_link" for n in names}
    static = {(e.parent, e.child) for e in site.static(0.0)}
    assert {(f"{n}_tf/base_link", f"{n}_tf/body_link") for n in names} <= static
    for angle, name in zip((0.1, 0.4, 0.7), names, strict=True):
        (edge,) = site.joint_states(name, ["vessel_joint"], [angle], 1.0)
        assert (edge.parent, edge.child) == (f"{name}_tf/base_link", f"{name}_tf/vessel_pin_link")
        assert edge.transform == site.tree(name).joint("dump_joint").transform(angle)
        (odom,) = site.odometry(name, "odom", (1.0, 2.0, 0.0), (0, 0, 0, 1), 1.0)
        assert (odom.parent, odom.child) == (f"{name}_tf/odom", f"{name}_tf/base_link")
