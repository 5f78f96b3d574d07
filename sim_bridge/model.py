"""MuJoCo model of the site, generated from the machine YAMLs, and its kinematics.

``build_mjcf(spec)`` writes an MJCF document: the terrain height field, the ZX200 (mocap base ->
swing -> boom -> arm -> bucket with the URDF joint origins, a ``zx200_bucket_tip`` site) and the
IC120 (mocap base -> vessel on its rear hinge). The bases are mocap bodies and the joints are set
from the hydraulic model (kinematic joints): MuJoCo computes the forward kinematics and renders; the
actuator and soil dynamics live in :mod:`sim_bridge.hydraulics` and :mod:`sim_bridge.soil`, which is
what keeps the plant far faster than real time. URDF ``rpy`` is fixed-axis XYZ, hence ``eulerseq="XYZ"``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from sim_bridge.config import PlantSpec

__all__ = ["build_mjcf", "SiteModel"]

_LINK_BOX = {  # visual boxes per ZX200 link: (half sizes, offset in link frame)
    "body_link": ((1.4, 1.3, 0.5), (-0.9, 0.0, 0.2)),
    "boom_link": ((2.8, 0.3, 0.3), (2.75, 0.0, 1.0)),
    "arm_link": ((1.4, 0.2, 0.2), (0.95, 0.0, 1.05)),
    "bucket_link": ((0.6, 0.5, 0.3), (0.6, 0.0, 0.5)),
}


def _v(values: tuple[float, ...] | list[float]) -> str:
    return " ".join(f"{v:.6g}" for v in values)


def build_mjcf(spec: PlantSpec) -> str:
    """The MJCF XML of both machines on the site (pure function of the configuration)."""
    soil = spec.soil
    nrow = int(round(soil.size_y / soil.resolution))
    ncol = int(round(soil.size_x / soil.resolution))
    cx = soil.x_min + soil.size_x / 2
    cy = soil.y_min + soil.size_y / 2
    zx = spec.zx200
    lines = [
        '<mujoco model="tms_site">',
        '  <compiler angle="radian" eulerseq="XYZ"/>',
        f'  <option timestep="{spec.dt}"/>',
        '  <visual><global offwidth="1920" offheight="1080"/><headlight ambient="0.45 0.45 0.45" diffuse="0.6 0.6 0.6"/></visual>',
        "  <asset>",
        f'    <hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{soil.size_x / 2} {soil.size_y / 2} 10 0.5"/>',
        '    <material name="soil" rgba="0.55 0.42 0.28 1"/>',
        '    <material name="zx" rgba="0.9 0.55 0.1 1"/>',
        '    <material name="ic" rgba="0.85 0.75 0.2 1"/>',
        "  </asset>",
        "  <worldbody>",
        '    <light pos="0 0 40" dir="0 0 -1" directional="true"/>',
        f'    <geom name="terrain" type="hfield" hfield="terrain" pos="{cx} {cy} {soil.ground_z - 5.0}" '
        'material="soil" contype="0" conaffinity="0"/>',
        '    <body name="zx200_base" mocap="true">',
        f'      <geom type="box" size="{zx.tracks.length / 2} {zx.tracks.width / 2} 0.45" pos="0 0 0.45" '
        'material="zx" contype="0" conaffinity="0"/>',
    ]
    indent = "      "
    closes = []
    for j in zx.joints:
        half, off = _LINK_BOX.get(j.child, ((0.2, 0.2, 0.2), (0, 0, 0)))
        lines.append(f'{indent}<body name="zx200_{j.child}" pos="{_v(j.origin_xyz)}" euler="{_v(j.origin_rpy)}">')
        rng = "" if j.lower is None else f' range="{j.lower} {j.upper}" limited="true"'
        lines.append(f'{indent}  <joint name="zx200_{j.name}" type="hinge" axis="{_v(j.axis)}"{rng}/>')
        lines.append(
            f'{indent}  <geom type="box" size="{_v(half)}" pos="{_v(off)}" material="zx" contype="0" conaffinity="0" mass="1"/>'
        )
        closes.append(f"{indent}</body>")
        indent += "  "
    lines.append(f'{indent}<site name="zx200_bucket_tip" pos="{_v(zx.bucket_tip_xyz)}" size="0.08"/>')
    lines.extend(reversed(closes))
    lines.append("    </body>")
    ic = spec.ic120
    length, width = ic.inner_length, ic.inner_width
    lines += [
        '    <body name="ic120_base" mocap="true">',
        f'      <geom type="box" size="{ic.tracks.length / 2} {ic.tracks.width / 2} 0.45" pos="0 0 0.45" '
        'material="ic" contype="0" conaffinity="0"/>',
        f'      <body name="ic120_vessel_link" pos="{_v(ic.hinge_xyz)}">',
        '        <joint name="ic120_vessel_joint" type="hinge" axis="0 -1 0"'
        f' range="{ic.vessel.lower} {ic.vessel.upper}" limited="true"/>',
        f'        <geom type="box" size="{length / 2} {width / 2} 0.05" pos="{length / 2} 0 0.53" material="ic" '
        'contype="0" conaffinity="0" mass="1"/>',
        f'        <site name="ic120_vessel_centre" pos="{length / 2} 0 0.53" size="0.1"/>',
        "      </body>",
        "    </body>",
        "  </worldbody>",
        "</mujoco>",
    ]
    return "\n".join(lines)


def yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


class SiteModel:
    """MuJoCo model + data of the site: set base poses and joint angles, read frames and sites."""

    def __init__(self, spec: PlantSpec) -> None:
        self.xml = build_mjcf(spec)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._mocap = {
            name: int(m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{name}_base")])
            for name in ("zx200", "ic120")
        }
        self._qadr = {}
        for j in range(m.njnt):
            self._qadr[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)] = int(m.jnt_qposadr[j])
        self.tip_site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "zx200_bucket_tip")
        self.bucket_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "zx200_bucket_link")
        self.body_ids = {
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b): b for b in range(m.nbody)
        }
        self.spec = spec

    def set_base(self, machine: str, x: float, y: float, z: float, yaw: float) -> None:
        i = self._mocap[machine]
        self.data.mocap_pos[i] = (x, y, z)
        self.data.mocap_quat[i] = yaw_quat(yaw)

    def set_joint(self, name: str, value: float) -> None:
        """Set joint ``name`` (e.g. ``zx200_boom_joint``, ``ic120_vessel_joint``)."""
        self.data.qpos[self._qadr[name]] = value

    def forward(self) -> None:
        """Recompute the kinematics after setting poses and joints."""
        mujoco.mj_kinematics(self.model, self.data)

    def bucket_tip(self) -> np.ndarray:
        return self.data.site_xpos[self.tip_site].copy()

    def body_pos(self, body: str) -> np.ndarray:
        return self.data.xpos[self.body_ids[body]].copy()

    def bucket_rotation(self) -> np.ndarray:
        return self.data.xmat[self.bucket_body].reshape(3, 3).copy()

    def set_terrain(self, heights: np.ndarray, ground_z: float) -> None:
        """Copy a height grid (rows = y, cols = x, metres) into the hfield (for rendering)."""
        m = self.model
        size_z = float(m.hfield_size[0][2])
        base = ground_z - 5.0
        norm = np.clip((heights - base) / size_z, 0.0, 1.0)
        m.hfield_data[:] = norm.astype(np.float32).ravel()

    @staticmethod
    def quat_to_yaw(q: np.ndarray) -> float:
        return math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
