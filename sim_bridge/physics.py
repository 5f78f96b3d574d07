"""Rigid-body dynamics of the machines: MuJoCo's ``mj_step`` with hydraulic drives computed between its substeps.

Every driven joint of every machine is a MuJoCo degree of freedom with mass, stepped under gravity; nothing on a
machine is set directly (the bases stay kinematic mocap bodies moved by the track model, see ``tracks.py``).
An excavator's boom, arm and bucket are pushed by cylinders: MuJoCo spatial tendons between the pin sites (the
bucket's through its four-bar linkage, closed by an equality constraint), each with a unit-gain ``motor``; the
swing by a ``motor`` on the swing joint (the hydraulic motor and its reduction). Other joints (a carrier's vessel and
upper body, a dozer's blade) get a ``motor`` on the joint.

Each drive is an oil column between a valve and a piston, linearised (``FluidDrive``): the valve meters the flow
that sets the reference speed ``v_ref`` (``hydraulics.py``); the trapped oil is a spring of stiffness
``k = beta_e (A_cap^2 / V_cap + A_rod^2 / V_rod)`` on the difference between the oil's volume (``x_ref``, the
integral of ``v_ref``) and the piston's position, with damping on the speed difference; the force is clipped at the
relief setting, the clipped oil goes over the relief (``x_ref`` follows the piston: no wind-up). Modelled: oil
compressibility (linearised about mid-stroke), relief valves, cylinder viscous friction, the four-bar, inertia and
gravity of every link, soil weight and cutting forces on the bucket (applied by the plant; a pressed bucket's bearing
through ``substep_hook``, each substep). Not modelled: leakage,
cavitation, pressure dynamics of the pump and hoses beyond the linear spring, Coulomb friction of the seals.

The force law runs in numpy over all drives of the site between MuJoCo substeps (``mj_step1`` / ``mj_step2``), so a
site of ten machines is one vector operation per substep.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from tms_common.schema import setting

__all__ = ["PhysicsSpec", "Drive", "FluidDrives"]

G = 9.81


@dataclass(frozen=True)
class PhysicsSpec:
    """A machine YAML's ``physics:`` section (the plant's model only: no controller reads it)."""

    source: str
    damping_ratio: float = setting(0.7, lo=0.05, hi=3.0, doc="of each drive about its start pose")
    # excavators: the cylinder circuits
    oil_bulk_modulus_mpa: float | None = setting(None, lo=10.0, hi=3000.0)
    hose_volume_l: float | None = setting(None, lo=0.0)
    tank_pressure_mpa: float | None = setting(None, lo=0.0, hi=5.0)
    cylinder_viscous_ns_per_m: float | None = setting(None, lo=0.0)
    pilot_crack_mpa: float | None = setting(None, lo=0.0, hi=5.0)
    pilot_full_mpa: float | None = setting(None, lo=0.1, hi=5.0)
    spool_overlap: float | None = setting(None, lo=0.0, hi=0.9)
    pump_power_kw: float | None = setting(None, lo=1.0)
    ls_margin_mpa: float | None = setting(None, lo=0.0, hi=10.0)
    function_flow_lpm: dict[str, float] | None = setting(None, lo=0.0)
    swing_brake_delay_s: float | None = setting(None, lo=0.0)
    # other joints: a stiff hydraulic drive on the joint
    drive_frequency_hz: float | None = setting(None, lo=0.1, hi=50.0)
    drive_torque_limit_nm: dict[str, float] | None = setting(None, lo=0.0)
    # dozers: the blade's resistance and the tracks' slip under it (sim_bridge.tracks, Plant._doze)
    traction_coefficient: float | None = setting(None, lo=0.05, hi=1.5, doc="max drawbar pull / machine weight")
    shear_modulus_m: float | None = setting(None, lo=0.001, hi=0.2, doc="[m] the soil's shear deformation modulus K")
    track_contact_length_m: float | None = setting(None, lo=0.1, hi=10.0, doc="[m] each track's length on the ground")
    blade_rake_deg: float | None = setting(None, lo=10.0, hi=90.0, doc="[deg] the blade's cutting angle")

    def need(self, where: str, *names: str) -> None:
        """ValueError naming the missing keys a machine of this type needs."""
        missing = [n for n in names if getattr(self, n) is None]
        if missing:
            raise ValueError(f"{where}: physics: missing {', '.join(missing)}")


@dataclass
class Drive:
    """One hydraulic drive: the MuJoCo actuator it writes, its oil spring, damping, viscous friction and force limits
    (``f_min`` < 0 < ``f_max``: pulling / pushing relief force), stroke limits of its oil volume and the joint it
    moves (for the effective mass that sets its damping)."""

    actuator: int
    stiffness: float  # [N/m or N m/rad]; 0: set from ``frequency`` and the effective mass at the start pose
    viscous: float
    f_min: float
    f_max: float
    x_min: float
    x_max: float
    damping_ratio: float
    frequency: float = 0.0  # [Hz] natural frequency of a drive given no stiffness
    #: the joint (dof index) the drive moves and dl/dq at the start pose: its effective mass is the joint's inertia
    #: over ratio^2 (a tendon through a closed linkage has no useful moment of its own); -1 = the actuator's own
    dof: int = -1
    ratio: float = 1.0


class FluidDrives:
    """All hydraulic drives of the site, stepped together between MuJoCo substeps."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, drives: Sequence[Drive], substeps: int) -> None:
        """``drives`` at the start pose (``data``'s qpos): their stiffness and damping are set from it."""
        self.model, self.data = model, data
        self.substeps = substeps
        self.n = len(drives)
        self.ids = np.array([d.actuator for d in drives], dtype=int)
        #: the drives as one slice of MuJoCo's actuator arrays when they are its actuators in order (a view each
        #: substep instead of a gather)
        self._sel = slice(0, self.n) if np.array_equal(self.ids, np.arange(model.nu)) else self.ids
        mujoco.mj_forward(model, data)
        mass = [self._effective_mass(d.actuator) if d.dof < 0 else self._joint_inertia(d.dof) / d.ratio**2
                for d in drives]
        self.k = np.array([d.stiffness if d.stiffness > 0 else m * (2 * math.pi * d.frequency) ** 2
                           for d, m in zip(drives, mass, strict=True)])
        self.c = np.array([d.viscous for d in drives])
        self.f_min = np.array([d.f_min for d in drives])
        self.f_max = np.array([d.f_max for d in drives])
        self.x_min = np.array([d.x_min for d in drives])
        self.x_max = np.array([d.x_max for d in drives])
        self.kv = np.array(
            [2 * d.damping_ratio * math.sqrt(k * m) for d, k, m in zip(drives, self.k, mass, strict=True)]
        )
        self.mass = np.array(mass)
        self.x_ref = data.actuator_length[self.ids].copy()
        self.v_ref = np.zeros(self.n)
        self.force = np.zeros(self.n)
        self.saturated = np.zeros(self.n, dtype=bool)
        self.sub_dt = model.opt.timestep
        #: called after each substep's ``mj_step1`` (positions and sites current, forces not yet applied): the plant's
        #: stiff external forces (a pressed bucket's bearing, ``Plant._press``) follow the substeps there; None: none
        self.substep_hook: Callable[[], None] | None = None
        self.reset()

    def _effective_mass(self, actuator: int) -> float:
        """Mass (inertia) ``actuator`` sees along its own direction at the current pose: 1 / (J M^-1 J^T)."""
        m, d = self.model, self.data
        row = self._moment_row(actuator)
        x = np.zeros(m.nv)
        mujoco.mj_solveM(m, d, x.reshape(1, -1), row.reshape(1, -1))
        inv = float(row @ x)
        return 1.0 / inv if inv > 1e-12 else 1.0

    def _joint_inertia(self, dof: int) -> float:
        """Inertia about joint ``dof`` with the other joints free: 1 / (M^-1)[dof, dof]."""
        m, d = self.model, self.data
        e = np.zeros(m.nv)
        e[dof] = 1.0
        x = np.zeros(m.nv)
        mujoco.mj_solveM(m, d, x.reshape(1, -1), e.reshape(1, -1))
        return 1.0 / float(x[dof])

    def _moment_row(self, actuator: int) -> np.ndarray:
        m, d = self.model, self.data
        row = np.zeros(m.nv)
        adr, nnz = int(d.moment_rowadr[actuator]), int(d.moment_rownnz[actuator])
        row[d.moment_colind[adr: adr + nnz]] = d.actuator_moment[adr: adr + nnz]
        return row

    def reset(self, settle_s: float = 2.0) -> None:
        """Hold the present pose: oil volumes such that each drive carries its static load here (after a teleport or
        at start). The machines are let sag under gravity for ``settle_s``, the compression each drive needed is
        kept and the joints are put back, at rest: a machine does not drop when the plant starts."""
        m, d = self.model, self.data
        qpos = d.qpos.copy()
        mujoco.mj_forward(m, d)
        self.x_ref[:] = d.actuator_length[self.ids]
        self.v_ref[:] = 0.0
        for _ in range(round(settle_s / (self.sub_dt * self.substeps))):
            self.step()
        mujoco.mj_forward(m, d)
        preload = self.x_ref - d.actuator_length[self.ids]
        d.qpos[:] = qpos
        d.qvel[:] = 0.0
        d.qacc_warmstart[:] = 0.0
        mujoco.mj_forward(m, d)
        self.x_ref[:] = d.actuator_length[self.ids] + preload

    def step(self) -> None:
        """Advance ``substeps`` MuJoCo steps with the drives' forces recomputed before each."""
        m, d = self.model, self.data
        ids, h = self._sel, self.sub_dt
        k, kv, kc = self.k, self.kv, self.kv + self.c
        x_ref, f_min, f_max, x_min, x_max = self.x_ref, self.f_min, self.f_max, self.x_min, self.x_max
        push = kv * self.v_ref
        dx = self.v_ref * h
        hook = self.substep_hook
        for _ in range(self.substeps):
            mujoco.mj_step1(m, d)
            if hook is not None:
                hook()
            x_ref += dx
            np.clip(x_ref, x_min, x_max, out=x_ref)
            f = k * (x_ref - d.actuator_length[ids]) + push - kc * d.actuator_velocity[ids]
            fc = np.clip(f, f_min, f_max)
            # where the relief opens, the oil that cannot follow goes to tank: the spring holds the relief force
            x_ref += (fc - f) / k
            d.ctrl[ids] = fc
            mujoco.mj_step2(m, d)
        self.force = fc
        self.saturated = fc != f
        bad = d.warning[mujoco.mjtWarning.mjWARN_BADQACC]
        if bad.number:
            # MuJoCo has reset the state to the model's reference pose: carrying on would teleport every machine
            joint = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.dof_jntid[bad.lastinfo]))
            raise FloatingPointError(f"MuJoCo: the dynamics diverged at joint {joint} (time {d.time:.3f} s)")
        mujoco.mj_kinematics(m, d)  # sites and bodies at the new positions (mj_step2 leaves them one step old)
