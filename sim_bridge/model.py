"""MuJoCo model of the site, generated from the machine YAMLs, and its kinematics.

``build_mjcf(spec)`` writes an MJCF document: the terrain height field and every machine of the plant,
each written by its type's profile (:mod:`sim_bridge.profiles`) with names prefixed by the machine's
name: an excavator is mocap base -> swing -> boom -> arm -> bucket with the URDF joint origins, the links' masses,
its cylinders (spatial tendons between pin sites, the bucket's through its four-bar) and a ``<name>_bucket_tip``
site, a crawler carrier is mocap base -> (rotating upper body ->) vessel on its rear hinge, a dozer mocap base ->
blade lift arm. The bases are mocap bodies moved by the track model; every joint is a degree of freedom under
gravity, driven by the motors :mod:`sim_bridge.physics` writes (``mj_step``, ``step_s / substeps`` per MuJoCo step).
No geometry collides: soil forces come from :mod:`sim_bridge.soil_force`, not from contacts. URDF ``rpy`` is
fixed-axis XYZ, hence ``eulerseq="XYZ"``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim_bridge.profiles import PLANT_PROFILES
from sim_bridge.spec import PlantSpec
from tms_model.geometry import quaternion_from_yaw, yaw_from_wxyz

__all__ = ["build_mjcf", "SiteModel"]


def build_mjcf(spec: PlantSpec) -> str:
    """The MJCF XML of every machine on the site (pure function of the configuration)."""
    sections: dict[str, list[str]] = {"tendon": [], "equality": [], "actuator": []}
    for machine in spec.machines.values():
        for key, extra in PLANT_PROFILES.get(machine.type).mjcf_sections(machine).items():
            sections[key] += extra
    soil = spec.soil
    nrow = int(round(soil.size_y / soil.resolution))
    ncol = int(round(soil.size_x / soil.resolution))
    cx = soil.x_min + soil.size_x / 2
    cy = soil.y_min + soil.size_y / 2
    lines = [
        '<mujoco model="tms_site">',
        '  <compiler angle="radian" eulerseq="XYZ"/>',
        f'  <option timestep="{spec.dt / spec.substeps}" gravity="0 0 -9.81"/>',
        # joint friction (brakes, the soil's cutting resistance) as hard Coulomb friction: MuJoCo's default soft
        # friction row is a damper of b/R that a joint driven through the four-bar's soft equality drags past its
        # frictionloss (a buried bucket curled at 0.5 rad/s against 500 kN m of "friction" at 14 MPa)
        f'  <default><joint solreffriction="{2 * spec.dt / spec.substeps} 1" solimpfriction="0.99 0.9999 0.001"/>'
        '</default>',
        '  <visual><global offwidth="1920" offheight="1080"/><headlight ambient="0.45 0.45 0.45" diffuse="0.6 0.6 '
        '0.6"/></visual>',
        "  <asset>",
        f'    <hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="{soil.size_x / 2} {soil.size_y / 2} 10 0.5"/>',
        '    <material name="soil" rgba="0.55 0.42 0.28 1"/>',
        '    <material name="zx" rgba="0.9 0.55 0.1 1"/>',
        '    <material name="ic" rgba="0.85 0.75 0.2 1"/>',
        '    <material name="dz" rgba="0.95 0.8 0.1 1"/>',
        "  </asset>",
        "  <worldbody>",
        '    <light pos="0 0 40" dir="0 0 -1" directional="true"/>',
        f'    <geom name="terrain" type="hfield" hfield="terrain" pos="{cx} {cy} {soil.ground_z - 5.0}" '
        'material="soil" contype="0" conaffinity="0"/>',
    ]
    for machine in spec.machines.values():
        lines += PLANT_PROFILES.get(machine.type).mjcf(machine)
    lines.append("  </worldbody>")
    for key, extra in sections.items():
        if extra:
            lines += [f"  <{key}>", *extra, f"  </{key}>"]
    lines.append("</mujoco>")
    return "\n".join(lines)


def yaw_quat(yaw: float) -> np.ndarray:
    """MuJoCo's scalar-first quaternion (w, x, y, z) of a rotation ``yaw`` about z."""
    x, y, z, w = quaternion_from_yaw(yaw)
    return np.array([w, x, y, z])


class SiteModel:
    """MuJoCo model + data of the site: set base poses and joint angles, read frames and sites."""

    def __init__(self, spec: PlantSpec) -> None:
        self.xml = build_mjcf(spec)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._mocap = {
            name: int(m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{name}_base")])
            for name in spec.machines
        }
        self._qadr = {}
        self._jid = {}
        for j in range(m.njnt):
            self._qadr[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)] = int(m.jnt_qposadr[j])
            self._jid[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)] = j
        self._tip_sites = {  # excavator name -> its bucket tip site
            name: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{name}_bucket_tip") for name in spec.machines
            if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"{name}_bucket_tip") >= 0
        }
        self.tip_site = self._tip_sites.get(spec.excavator, -1)  # -1: no digging excavator (experiment: none)
        self.bucket_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"{spec.excavator}_bucket_link")
        self.body_ids = {
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b): b for b in range(m.nbody)
        }
        self.spec = spec

    def set_base(self, machine: str, x: float, y: float, z: float, yaw: float) -> None:
        i = self._mocap[machine]
        self.data.mocap_pos[i] = (x, y, z)
        self.data.mocap_quat[i] = yaw_quat(yaw)

    def set_joint(self, name: str, value: float) -> None:
        """Set joint ``name``: ``<machine>_<joint>`` (e.g. the boom of the machine named ``m``: ``m_boom_joint``)."""
        self.data.qpos[self._qadr[name]] = value

    def forward(self) -> None:
        """Recompute the kinematics after setting poses and joints."""
        mujoco.mj_kinematics(self.model, self.data)

    def qpos_adr(self, name: str) -> int:
        """The qpos index of joint ``name``."""
        return self._qadr[name]

    def dof(self, name: str) -> int:
        """The dof index of joint ``name``."""
        return int(self.model.jnt_dofadr[self._jid[name]])

    def rest_joint(self, name: str) -> None:
        """Zero the speed of joint ``name`` (a teleport)."""
        self.data.qvel[self.model.jnt_dofadr[self._jid[name]]] = 0.0

    def bucket_tip(self, machine: str | None = None) -> np.ndarray:
        """Bucket tip in map of excavator ``machine`` (default: the one digging the soil)."""
        site = self.tip_site if machine is None else self._tip_sites[machine]
        return self.data.site_xpos[site].copy()

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
        """Yaw of a MuJoCo (w, x, y, z) quaternion."""
        return yaw_from_wxyz(q)
