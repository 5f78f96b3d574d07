"""tms_model.urdf: OPERA's link and joint names, a URDF that urdfdom (through pinocchio) parses, and the same
geometry as the kinematics: pinocchio's forward kinematics of the URDF puts the bucket tip where
tms_model's kinematics put it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from tms_common.config import config_path
from tms_common.errors import ConfigError
from tms_model.excavator.kinematics import load_kinematics
from tms_model.machines import parse_machine
from tms_model.transform import Transform, quaternion_from_axis_angle
from tms_model.urdf import load_tree


def _random_front(kin, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(kin.limits.lower), kin.limits.lower, -math.pi)
    hi = np.where(np.isfinite(kin.limits.upper), kin.limits.upper, math.pi)
    return rng.uniform(lo, hi)


def test_zx200_names_are_zx200_ros2s() -> None:
    tree = load_tree("zx200")
    assert tree.links == (
        "base_link",
        "track_link",
        "body_link",
        "boom_link",
        "arm_link",
        "bucket_link",
        "bucket_end_link",
    )
    assert [(j.name, j.kind) for j in tree.joints] == [
        ("base_joint", "fixed"), ("swing_joint", "continuous"), ("boom_joint", "revolute"), ("arm_joint", "revolute"),
        ("bucket_joint", "revolute"), ("bucket_end_joint", "fixed")]
    assert tree.frame("base_link") == "base_link"  # zx200_ros2 publishes its frames unprefixed


def test_ic120_names_are_ic120_ros2s_with_its_tf_prefix() -> None:
    tree = load_tree("ic120")
    assert tree.links == ("base_link", "body_link", "vessel_pin_link")
    assert [(j.name, j.kind) for j in tree.joints] == [("base_joint", "fixed"), ("dump_joint", "revolute")]
    dump = tree.joint("dump_joint")
    assert (dump.axis, dump.lower, dump.upper) == ((0.0, 1.0, 0.0), pytest.approx(-1.134464), 0.0)
    assert dump.state == "vessel_joint" and dump.sign == -1.0
    urdf = tree.urdf()
    assert '<link name="ic120_tf/base_link"' in urdf and '<child link="ic120_tf/vessel_pin_link"/>' in urdf


@pytest.mark.parametrize("kind", ["zx200", "zx120"])
def test_pinocchio_fk_of_the_urdf_puts_the_tip_where_the_kinematics_do(kind: str) -> None:
    tree = load_tree(kind)
    model = pin.buildModelFromXML(tree.urdf())  # urdfdom parses it
    data = model.createData()
    frame = model.getFrameId(tree.frame("bucket_end_link"))
    assert frame < model.nframes, [f.name for f in model.frames]
    kin = load_kinematics(kind)
    names = [model.names[i] for i in range(1, model.njoints)]
    assert names == list(kin.joints), names
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = _random_front(kin, rng)
        # a continuous joint is (cos, sin) in pinocchio's configuration
        q_pin = pin.neutral(model)
        for i, name in enumerate(names):
            jid = model.getJointId(name)
            idx, nq = model.joints[jid].idx_q, model.joints[jid].nq
            q_pin[idx:idx + nq] = [math.cos(q[i]), math.sin(q[i])] if nq == 2 else [q[i]]
        pin.framesForwardKinematics(model, data, q_pin)
        urdf_tip = data.oMf[frame].translation
        assert np.linalg.norm(urdf_tip - kin.tip_position(q)) < 1e-9, (q, urdf_tip, kin.tip_position(q))
        # and the tree's own transforms (what /tf carries) agree too
        pose = tree.pose("bucket_end_link", dict(zip(names, q, strict=True)))
        assert np.linalg.norm(np.array(pose.translation) - kin.tip_position(q)) < 1e-9
        assert np.allclose(pose.matrix(), data.oMf[frame].rotation, atol=1e-9)


def test_ic120_vessel_raised_turns_about_minus_y_at_the_hinge() -> None:
    tree = load_tree("ic120")
    model = pin.buildModelFromXML(tree.urdf())
    data = model.createData()
    jid = model.getJointId("dump_joint")
    assert model.lowerPositionLimit[model.joints[jid].idx_q] == pytest.approx(-1.134464)
    angle = 0.8  # our interface: + = raised
    q = pin.neutral(model)
    q[model.joints[jid].idx_q] = -angle  # the URDF's dump_joint position
    pin.forwardKinematics(model, data, q)
    expected = Transform(tree.machine.vessel.hinge_xyz, quaternion_from_axis_angle((0.0, -1.0, 0.0), angle))
    pose = tree.pose("vessel_pin_link", {"vessel_joint": angle})
    assert np.allclose(pose.translation, expected.translation) and np.allclose(pose.matrix(), expected.matrix())
    assert np.allclose(data.oMi[jid].rotation, expected.matrix(), atol=1e-12)
    # raising lifts the vessel's front end: a point 3 m ahead of the hinge goes up
    assert pose.apply((3.0, 0.0, 0.0))[2] > tree.machine.vessel.hinge_xyz[2] + 2.0


def test_a_bad_tf_prefix_names_file_line_and_key(tmp_path: Path) -> None:
    text = config_path("machines", "ic120.yaml").read_text()
    assert "tf_prefix: ic120_tf\n" in text
    path = tmp_path / "ic120.yaml"
    path.write_text(text.replace("tf_prefix: ic120_tf\n", "tf_prefix: /ic120_tf/\n"))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if t.startswith("tf_prefix"))
    with pytest.raises(ConfigError, match=rf"ic120.yaml:{line}: tf_prefix: expected a frame name prefix"):
        parse_machine(path)
