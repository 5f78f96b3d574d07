"""The plant: the machines of the site and the soil, advanced in fixed steps of simulated time.

Pure core (no ROS, no CAN): :class:`Plant` holds one machine per entry of the plant YAML's ``machines``
(built by its type's profile, :mod:`sim_bridge.profiles`), takes actuator commands (front joint
velocities, track speeds, a vessel target angle or velocity), steps hydraulics, tracks, kinematics
(MuJoCo) and soil, and exposes the true state. The paper's soil is dug by the plant's first excavator and
carried by its first crawler carrier (``PlantSpec.excavator`` / ``carrier``); every carrier loads and dumps, every
dozer blade cuts. :mod:`sim_bridge.can_io` maps COM3 frames onto these commands and the
state onto frames; :mod:`sim_bridge.nodes.sim_plant` adds ``/clock`` and ``/sim/truth``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from sim_bridge.config import load_plant
from sim_bridge.machines import CrawlerCarrier, Dozer, Excavator
from sim_bridge.model import SiteModel
from sim_bridge.physics import FluidDrives, G
from sim_bridge.profiles import PLANT_PROFILES
from sim_bridge.soil import HeightField, SoilState
from sim_bridge.soil_force import bearing_terms, fee_force, rake_range
from sim_bridge.spec import PlantSpec

__all__ = ["Plant", "MachineTruth", "stamp_parts"]

log = logging.getLogger(__name__)


def stamp_parts(t: float) -> tuple[int, int]:
    """Simulated time [s] -> ``(sec, nanosec)`` of a ROS stamp, carrying a rounded-up second.

    A time a hair below a whole second (3.0 read as 2.9999999999999996) rounds to 1e9 ns; that carry
    must go into ``sec``. Splitting off ``int(t)`` first and wrapping the nanoseconds stamped it
    ``2.000`` instead, one second back: every truth pose, /clock and scan at such a second jumped
    back 0.95 s, and tms_sp's arrival detector took that as a sim reset (SENSING_ARRIVAL_FLG fell
    once per simulated second).
    """
    sec, nanosec = divmod(round(t * 1e9), 1_000_000_000)
    return int(sec), int(nanosec)


@dataclass(frozen=True)
class MachineTruth:
    """True base pose of a machine in map (yaw CCW from east)."""

    x: float
    y: float
    z: float
    yaw: float


class Plant:
    """The machines of the plant YAML, the site model and the soil; ``step()`` advances ``dt`` of simulated time."""

    def __init__(self, spec: PlantSpec | None = None) -> None:
        self.spec = spec or load_plant()
        self.dt = self.spec.dt
        self.time = 0.0  # = steps * dt (not accumulated: summing 0.01 drifts off the step grid)
        self.steps = 0
        self.machines: dict[str, Any] = {
            name: PLANT_PROFILES.get(m.type).make_machine(m, self.dt) for name, m in self.spec.machines.items()
        }
        #: the soil-digging excavator and the soil-carrying crawler carrier (the paper's ZX200 and IC120); None in a
        #: plant without them (``experiment: none``)
        self.excavator: Excavator = self.machines.get(self.spec.excavator)  # type: ignore[assignment]
        self.carrier: CrawlerCarrier = self.machines.get(self.spec.carrier)  # type: ignore[assignment]
        self.carriers = {n: m for n, m in self.machines.items() if isinstance(m, CrawlerCarrier)}
        self.dozers = {n: m for n, m in self.machines.items() if isinstance(m, Dozer)}
        self.model = SiteModel(self.spec)
        self._place_joints()
        drives = []
        self._drive_slices: dict[str, slice] = {}
        for name, m in self.spec.machines.items():
            own = PLANT_PROFILES.get(m.type).drives(m, self.model.model)
            self._drive_slices[name] = slice(len(drives), len(drives) + len(own))
            drives += own
        self.drives = FluidDrives(self.model.model, self.model.data, drives, self.spec.substeps)
        self._joint_names = {name: [f"{name}_{j}" for j in mach.bank.names] for name, mach in self.machines.items()}
        #: machine -> (qpos addresses, dof addresses) of its bank's joints: one gather per step, not a name lookup each
        self._joint_adr = {
            name: (np.array([self.model.qpos_adr(j) for j in joints], dtype=int),
                   np.array([self.model.dof(j) for j in joints], dtype=int))
            for name, joints in self._joint_names.items()
        }
        #: excavator -> its swing's dof (the parking brake is friction on it)
        self._swing_dofs = {
            name: self.model.dof(f"{name}_{mach.front.names[0]}")
            for name, mach in self.machines.items() if isinstance(mach, Excavator)
        }
        #: the digging excavator's front dofs (swing, boom, arm, bucket): the soil's resistance is friction on them
        self._front_dofs = np.array([self.model.dof(f"{self.spec.excavator}_{j}") for j in self.excavator.front.names]
                                    if self.excavator is not None else [], dtype=int)

        self.ground = HeightField(self.spec.soil)
        self.soil = SoilState(carrier=self.spec.carrier, vessels=dict.fromkeys(self.carriers, 0.0),
                              blades=dict.fromkeys(self.dozers, 0.0))
        self.initial_volume = self.ground.volume()
        self._place_bases()
        self.model.forward()
        self._tip = self.model.bucket_tip() if self.excavator is not None else None
        self.tip_speed = 0.0
        self._tip_velocity = np.zeros(3)
        self._cut_direction = (1.0, 0.0, 0.0)
        self.cut_force: tuple[np.ndarray, np.ndarray] | None = None  # the soil's last force on the bucket edge
        self._wedge_memo = None  # ((soil id, (depth, rake, surcharge)), (horizontal, vertical)) of the last wedge
        self._edges: dict[str, tuple[float, float, float]] = {}
        #: dozer -> the soil's last resistance to its blade [N] (its tracks slip under it: ``base.load_slip``)
        self.blade_force: dict[str, float] = dict.fromkeys(self.dozers, 0.0)
        #: the soil's bearing force on the pressed bucket edge [N, up] and the bearing capacity there [N] of the last
        #: substep (``soil.penetration``; 0 without it or out of contact)
        self.press_force = 0.0
        self.press_capacity = 0.0
        self.press_displaced = 0.0  # [m^3] soil the pressed bucket has pushed aside so far (bearing failure)
        self._press_on = bool(self.spec.soil.penetration and self.excavator is not None
                              and self.spec.soil.cutting is not None)
        if self._press_on:
            self._press_setup()


    # -- state -------------------------------------------------------------------------------------
    def truth(self, machine: str) -> MachineTruth:
        m = self.machines[machine]
        return MachineTruth(m.base.x, m.base.y, m.z, m.base.yaw)

    def bucket_tip(self) -> tuple[float, float, float]:
        if self._tip is None:
            return (math.nan, math.nan, math.nan)
        return (float(self._tip[0]), float(self._tip[1]), float(self._tip[2]))

    def total_volume(self) -> float:
        """Ground (above the datum) + bucket + vessels + blades: constant up to rounding."""
        return self.ground.volume() + self.soil.held()

    def roll_pitch(self, machine: str) -> tuple[float, float]:
        """Roll and pitch of a base resting on the height field under its footprint [rad]."""
        m = self.machines[machine]
        t = m.description.footprint
        c, s = math.cos(m.base.yaw), math.sin(m.base.yaw)
        x, y = m.base.x, m.base.y
        hl, hw = t.length / 2, t.width / 2
        front = self.ground.height(x + c * hl, y + s * hl)
        back = self.ground.height(x - c * hl, y - s * hl)
        left = self.ground.height(x - s * hw, y + c * hw)
        right = self.ground.height(x + s * hw, y - c * hw)
        pitch = math.atan2(back - front, 2 * hl)  # + = nose down (REP 103: pitch about y)
        roll = math.atan2(left - right, 2 * hw)  # + = left side up (REP 103: roll about x)
        return roll, pitch

    # -- stepping ----------------------------------------------------------------------------------
    def _place_bases(self) -> None:
        """The mocap bases where the track model has them, on the ground."""
        m = self.model
        for name, mach in self.machines.items():
            mach.z = self.ground.height(mach.base.x, mach.base.y)
            m.set_base(name, mach.base.x, mach.base.y, mach.z, mach.base.yaw)

    def _place_joints(self) -> None:
        """qpos from the machines' joint positions (start, teleport), at rest; closes the bucket linkages."""
        m = self.model
        for name, mach in self.machines.items():
            for joint, q in zip(mach.bank.names, mach.bank.q, strict=True):
                m.set_joint(f"{name}_{joint}", q)
                m.rest_joint(f"{name}_{joint}")
            here = dict(zip(mach.bank.names, mach.bank.q, strict=True))
            extra = PLANT_PROFILES.get(self.spec.machines[name].type).linkage_joints(self.spec.machines[name], here)
            for joint, q in extra.items():
                m.set_joint(joint, q)
                m.rest_joint(joint)
        m.forward()

    def _loads(self) -> None:
        """External forces of the soil: the weight of what buckets and vessels hold, and the cutting resistance on
        the digging bucket's edge while it is below the surface (Reece/McKyes, :mod:`sim_bridge.soil_force`).

        The horizontal resistance is Coulomb friction on the front's joints (MuJoCo's ``frictionloss``, solved
        implicitly: a bucket its cylinders cannot drag through the soil stalls instead of chattering), each joint
        getting |J_edge^T F|: what the cut costs it (a crowd, or a curl while the edge moves along the arm, deeper
        than the cylinders can drag stalls at relief). Lifting the edge straight up costs the joints little. The
        wedge's vertical part is an applied force at the edge."""
        m, data = self.model.model, self.model.data
        xfrc = data.xfrc_applied
        xfrc[:] = 0.0
        for name, load in self.soil.vessels.items():
            if load > 0.0:
                xfrc[self.model.body_ids[f"{name}_vessel_link"], 2] = -load * self.spec.soil.loose_density * G
        for name, dof in self._swing_dofs.items():
            front = self.machines[name].front
            m.dof_frictionloss[dof] = front.brake_torque if front.swing_brake else 0.0
        if self.excavator is None:
            return
        body = self.model.bucket_body
        if self.soil.bucket > 0.0:
            xfrc[body, 2] = -self.soil.bucket * self.spec.soil.loose_density * G
        dofs = self._front_dofs
        m.dof_frictionloss[dofs[1:]] = 0.0
        self.cut_force = self._cutting_force()
        if self.cut_force is None:
            return
        force, tip = self.cut_force
        jac = np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, data, jac, None, self.model.tip_site)
        horizontal = np.array([force[0], force[1], 0.0])
        m.dof_frictionloss[dofs] += np.abs(horizontal @ jac[:, dofs])
        xfrc[body, 2] += force[2]
        r = tip - data.xipos[body]
        xfrc[body, 3] += r[1] * force[2]  # the moment r x (0, 0, fz) about the bucket's centre of mass
        xfrc[body, 4] -= r[0] * force[2]

    # -- penetration: the bucket pressed into the ground (soil.penetration) ---------------------------
    def _press_setup(self) -> None:
        """Constants of the pressed edge: contact B x w, the Winkler spring k_s B w and the capacity's terms
        (:func:`sim_bridge.soil_force.bearing_terms` times the area: capacity = q0 + dq * D)."""
        soil = self.spec.soil.cutting
        assert soil is not None and soil.subgrade_modulus is not None  # load_plant refuses a soil without it
        b, w = self.spec.soil.penetration_breadth, self.excavator.bucket.width
        q0, dq = bearing_terms(soil, b, w)
        self._press_k = soil.subgrade_modulus * b * w
        self._press_q0, self._press_dq = float(q0) * b * w, float(dq) * b * w
        self._press_surface = math.inf  # the soil surface under the edge this step (lowered where it yields)
        self._press_around = -math.inf  # the surrounding surface (the overburden's top)
        self._press_base = np.zeros(6)  # the bucket's other external force this step (weight, cut)
        self.drives.substep_hook = self._press

    def _press_start(self) -> None:
        """Once per plant step, before the substeps: the soil surface under the edge (the lowest of its cell and the
        cells one cell ahead and behind along the arm's heading: an edge riding on its own cut floor compresses
        that floor, not the uncut face ahead of it) and around it (the highest within two cells, as the wedge's
        depth), and the bucket's applied force without the bearing."""
        tip = self._tip
        heading = self.excavator.base.yaw + self.excavator.front.q[0]
        ux, uy = math.cos(heading), math.sin(heading)
        g, res = self.ground, self.spec.soil.resolution
        here = g.height(tip[0], tip[1])
        near = [g.height(tip[0] + k * ux * res, tip[1] + k * uy * res) for k in (-2, -1, 1, 2)]
        self._press_surface = min(here, near[1], near[2])
        self._press_around = max(here, near[0], near[3])
        self._press_base[:] = self.model.data.xfrc_applied[self.model.bucket_body]

    def _press(self) -> None:
        """Each substep (after ``mj_step1``): the soil's bearing force on the edge, :func:`penetration_force`'s law
        in scalar form: ``min(k_s delta, q_ult(D)) B w`` up at the edge, delta = the surface under the edge - the
        edge, D = max(delta, the surrounding surface - the edge). Where the spring would carry more than the
        capacity the soil yields: its surface under the edge follows the edge down to where the spring carries the
        capacity (the plant removes that soil after the step, :meth:`_press_yield`)."""
        d = self.model.data
        body = self.model.bucket_body
        xfrc = d.xfrc_applied[body]
        xfrc[:] = self._press_base
        tip = d.site_xpos[self.model.tip_site]
        z = float(tip[2])
        delta = self._press_surface - z
        if delta <= 0.0:
            self.press_force = 0.0
            return
        capacity = self._press_q0 + self._press_dq * max(delta, self._press_around - z)
        f = self._press_k * delta
        if f > capacity:
            self._press_surface = z + capacity / self._press_k
            f = capacity
        r = tip - d.xipos[body]
        xfrc[2] += f
        xfrc[3] += r[1] * f  # the moment r x (0, 0, f) about the bucket's centre of mass
        xfrc[4] -= r[0] * f
        self.press_force, self.press_capacity = f, capacity

    def _press_yield(self, tip) -> None:
        """After the substeps: where the soil under the edge has yielded, its cells (the edge's width, one cell
        along) are lowered to the yielded surface and the soil displaced is heaved up beside the bucket, half on
        each side beyond its width (the bearing failure's side heave; volume conserved as a cut and a deposit)."""
        if self._press_surface >= self.ground.height(tip[0], tip[1]):
            return
        heading = self.excavator.base.yaw + self.excavator.front.q[0]
        lx, ly = -math.sin(heading), math.cos(heading)
        w = self.excavator.bucket.width
        moved = self.ground.cut((tip[0], tip[1]), (tip[0], tip[1]), self._press_surface, width=w,
                                lateral=(lx, ly), max_volume=math.inf)
        if moved <= 0.0:
            return
        radius = self.spec.soil.deposit_radius
        side = 0.5 * w + radius + self.spec.soil.resolution
        for sign in (-1.0, 1.0):
            self.ground.deposit(tip[0] + sign * side * lx, tip[1] + sign * side * ly, 0.5 * moved, radius)
        self.press_displaced += moved

    def _cutting_force(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(force of the soil on the bucket edge [N], the edge) while the edge is below the surface, else None.

        Depth = the uncut surface two cells ahead of the edge (or at it) - the edge's height; rake = the pin->edge
        line's angle below horizontal (the bucket's back plate), kept inside the wedge's range and 30-80 degrees;
        surcharge = the soil above the bucket's height and the soil already in the bucket over its width and a 1 m
        long floor (Luengo, Singh and Cannon 1998 carry it as a surcharge). The
        direction is the edge's horizontal motion (a still edge: the last one it moved in)."""
        soil = self.spec.soil.cutting
        tip = self._tip
        if soil is None or tip is None:
            return None
        # the edge cuts the cells it passes down to its own height: the depth of cut is the uncut surface two cells
        # ahead of it (either way along the arm's heading: the side already cut is the lower one)
        heading = self.excavator.base.yaw + self.excavator.front.q[0]
        ux, uy = math.cos(heading), math.sin(heading)
        ahead = 2 * self.spec.soil.resolution
        depth = max(self.ground.height(tip[0], tip[1]), self.ground.height(tip[0] + ux * ahead, tip[1] + uy * ahead),
                    self.ground.height(tip[0] - ux * ahead, tip[1] - uy * ahead)) - tip[2]
        if depth <= 0.0:
            return None
        lo, hi = rake_range(soil)
        # a bucket's cutting plate meets the soil at 30-80 degrees; near the wedge's limit rake the factors diverge
        rake = min(max(abs(self.excavator.tip_angle()), lo + 0.05, math.radians(30)), hi - 0.05, math.radians(80))
        bucket = self.excavator.bucket
        # the wedge in front of the bucket is at most the bucket's own height deep; soil standing above it and the
        # soil already in the bucket (over a 1 m long floor) press on it as a surcharge (Luengo, Singh and Cannon)
        tool = min(depth, abs(bucket.tip_xyz[2]))
        surcharge = (soil.unit_weight * (depth - tool)
                     + self.soil.bucket * self.spec.soil.loose_density * G / bucket.width)
        self._cut_direction = (ux, uy, 0.0)  # the wedge lies in the arm's vertical plane (a bucket cuts fore or aft)
        # the wedge's inertia term (McKyes) is left out: it grows with the square of a speed the same force sets, and
        # at the bucket's speeds it is a few percent of the weight term
        h, v = self._wedge(soil, rake, tool, bucket.width, surcharge)
        ux, uy, _ = self._cut_direction
        # the wedge's vertical force (on the tool, + up: the soil draws a raked edge down) exists while it cuts:
        # ramped in over the first 2 cm/s of the edge's motion along the arm, none on a still edge
        along = abs(float(self._tip_velocity[0] * ux + self._tip_velocity[1] * uy))
        return np.array([-h * ux, -h * uy, v * min(1.0, along / 0.02)]), tip

    def _wedge(self, soil, rake: float, depth: float, width: float, surcharge: float) -> tuple[float, float]:
        """(horizontal, vertical) wedge force [N]; the last one again while the cut has not changed by more than
        2 mm of depth, 0.2 degrees of rake or 1 % of surcharge (a still or slow edge: the beta search is most of the
        soil's cost per step)."""
        key = np.array([depth, rake, surcharge])
        last = self._wedge_memo
        if last is not None and last[0][0] == id(soil) and np.all(np.abs(key - last[0][1]) <= (
                0.002, 0.0035, 0.01 * abs(last[0][1][2]) + 1.0)):
            return last[1]
        f = fee_force(soil, rake, depth, width, surcharge=surcharge)
        out = float(np.ravel(f.horizontal)[0]), float(np.ravel(f.vertical)[0])
        self._wedge_memo = ((id(soil), key), out)
        return out

    def step(self) -> None:
        """Advance one ``dt``: valves, bases, dynamics (MuJoCo), soil."""
        for mach in self.machines.values():
            mach.step()
        self._place_bases()
        v_ref = self.drives.v_ref
        for name, mach in self.machines.items():
            v_ref[self._drive_slices[name]] = mach.bank.v_ref
        self._loads()
        if self._press_on:
            self._press_start()
        self.drives.step()
        force, speed = self.drives.force, self.model.data.actuator_velocity[self.drives.ids]
        qpos, qvel = self.model.data.qpos, self.model.data.qvel
        for name, mach in self.machines.items():
            bank = mach.bank
            qadr, dadr = self._joint_adr[name]
            bank.q[:] = qpos[qadr].tolist()
            bank.v[:] = qvel[dadr].tolist()
            sl = self._drive_slices[name]
            bank.set_forces(force[sl], speed[sl])
        if self.excavator is not None:
            tip = self.model.bucket_tip()
            prev = self._tip
            self._tip_velocity = (tip - prev) / self.dt
            self.tip_speed = math.dist(tip, prev) / self.dt
            self._soil(prev, tip)
            if self._press_on:
                self._press_yield(tip)
            self._tip = tip
        self._dump()
        for name, dz in self.dozers.items():
            self._doze(name, dz)
        self.advance_clock()

    def advance_clock(self) -> None:
        """Count one step: ``time = steps * dt`` (no accumulated rounding; replay uses it too)."""
        self.steps += 1
        self.time = self.steps * self.dt

    def _soil(self, prev, tip) -> None:  # numpy vectors
        zx = self.excavator.bucket
        soil = self.soil
        ground = self.ground
        surface = ground.height(tip[0], tip[1])
        cutting = self.tip_speed >= zx.cut_min_speed
        if self._press_on:
            # with the bearing modelled, an edge moving more down than along presses (Plant._press) instead of
            # cutting: only its horizontal motion cuts
            v = self._tip_velocity
            along = math.hypot(v[0], v[1])
            cutting = along >= zx.cut_min_speed and along >= -v[2]
        if tip[2] < surface and cutting:
            heading = self.excavator.base.yaw + self.excavator.front.q[0]
            lateral = (-math.sin(heading), math.cos(heading))
            # a pressed edge (soil.penetration) cuts down to the soil it compresses, not to its own height: the soil
            # under it stays carrying it (the Winkler spring's compression, Plant._press)
            floor = tip[2] + self.press_force / self._press_k if self._press_on else tip[2]
            got = ground.cut(
                (prev[0], prev[1]),
                (tip[0], tip[1]),
                floor,
                width=zx.width,
                lateral=lateral,
                max_volume=zx.capacity - soil.bucket,
            )
            soil.bucket += got
            soil.dug += got
        alpha = self.excavator.tip_angle()
        if soil.bucket > 0.0 and alpha < zx.release_tip_angle and tip[2] >= surface:
            rate = zx.capacity / zx.spill_time * min(1.0, (zx.release_tip_angle - alpha) / 0.5)
            out = min(soil.bucket, rate * self.dt)
            soil.bucket -= out
            self._land(tip[0], tip[1], out)

    @staticmethod
    def _vessel_frame(ic: CrawlerCarrier) -> tuple[float, float, float, float, float]:
        """(ox, oy, cos, sin, yaw) of the vessel: base_link coordinates at swing 0 map to the map frame by turning
        about the slew centre (ox, oy) by the swing, then by the base pose."""
        sw = ic.swing_joint
        ox, oy = (sw.origin_xyz[0], sw.origin_xyz[1]) if sw is not None else (0.0, 0.0)
        th = ic.swing_angle
        return ox, oy, math.cos(th), math.sin(th), ic.base.yaw + th

    def _vessel_to_map(self, ic: CrawlerCarrier, bx: float, by: float) -> tuple[float, float]:
        """Map position of the point (bx, by) of base_link at swing 0 on the swung upper body."""
        ox, oy, c, sn, _ = self._vessel_frame(ic)
        x, y = ox + c * (bx - ox) - sn * (by - oy), oy + sn * (bx - ox) + c * (by - oy)
        cy, sy = math.cos(ic.base.yaw), math.sin(ic.base.yaw)
        return ic.base.x + cy * x - sy * y, ic.base.y + sy * x + cy * y

    def _land(self, x: float, y: float, volume: float) -> None:
        """Soil falling at (x, y): into a carrier's vessel when over it and lowered, else on the ground."""
        for name, ic in self.carriers.items():
            s = ic.vessel
            ox, oy, _, _, yaw = self._vessel_frame(ic)
            # (x, y) in the upper body's frame at the slew centre, then in base_link at swing 0
            cx, cy = self._vessel_to_map(ic, ox, oy)
            c, sn = math.cos(yaw), math.sin(yaw)
            dx, dy = x - cx, y - cy
            bx, by = ox + c * dx + sn * dy, oy - sn * dx + c * dy
            hinge_x = s.hinge_xyz[0]
            over = hinge_x <= bx <= hinge_x + s.inner_length and abs(by - s.hinge_xyz[1]) <= s.inner_width / 2
            if over and ic.vessel_angle <= s.load_max_angle:
                into = min(volume, max(0.0, s.capacity - self.soil.vessels[name]))
                self.soil.vessels[name] += into
                self.soil.loaded += into
                self.soil.loaded_by[name] = self.soil.loaded_by.get(name, 0.0) + into
                volume -= into
                break
        self.ground.deposit(x, y, volume, self.spec.soil.deposit_radius)

    def _dump(self) -> None:
        """Every raised vessel empties onto a pile ``dump_distance`` behind its hinge, where the swung vessel points."""
        for name, ic in self.carriers.items():
            s = ic.vessel
            angle = ic.vessel_angle
            load = self.soil.vessels[name]
            if load <= 0.0 or angle <= s.dump_start_angle:
                continue
            span = max(1e-6, (ic.vessel_joint.upper or angle) - s.dump_start_angle)
            rate = s.capacity / s.dump_time * min(1.0, (angle - s.dump_start_angle) / span)
            out = min(load, rate * self.dt)
            self.soil.vessels[name] = load - out
            self.soil.dumped += out
            self.soil.dumped_by[name] = self.soil.dumped_by.get(name, 0.0) + out
            px, py = self._vessel_to_map(ic, s.hinge_xyz[0] - s.dump_distance, s.hinge_xyz[1])
            self.ground.deposit(px, py, out, self.spec.soil.dump_radius)

    def dump_point(self, machine: str) -> tuple[float, float]:
        """Map position where carrier ``machine`` would put its dumped pile now."""
        ic = self.carriers[machine]
        return self._vessel_to_map(ic, ic.vessel.hinge_xyz[0] - ic.vessel.dump_distance, ic.vessel.hinge_xyz[1])

    def blade_edge(self, machine: str) -> tuple[float, float, float]:
        """Map position of dozer ``machine``'s blade edge (centre of the cutting edge)."""
        dz = self.dozers[machine]
        ex, ey, ez = dz.edge_in_base()
        c, sn = math.cos(dz.base.yaw), math.sin(dz.base.yaw)
        return dz.base.x + c * ex - sn * ey, dz.base.y + sn * ex + c * ey, dz.z + ez

    def _doze(self, name: str, dz: Dozer) -> None:
        """The blade cuts while moving below the surface and leaves its load ahead when lifted above it.

        While the tracks drive forward, the soil resists the blade (``blade_force``, handed to the tracks as their
        drawbar load): the Reece/McKyes wedge in front of the edge (depth = the uncut surface at or one cell ahead
        of the edge - the edge; rake ``physics.blade_rake_deg``; the blade's width) plus the friction of the pile
        it pushes, load x loose density x g x tan(phi) (the usual dozer resistance split into cutting, pushing
        the prism ahead of the blade and the machine's own motion: Caterpillar Performance Handbook; Wong, Theory
        of Ground Vehicles). Backing up pushes nothing. ``Plant.step`` moves the bases before this: the tracks see
        the resistance one step (10 ms) late."""
        b = dz.blade
        x, y, z = self.blade_edge(name)
        prev = self._edges.get(name)
        self._edges[name] = (x, y, z)
        if prev is None:
            return
        surface = self.ground.height(x, y)
        load = self.soil.blades[name]
        speed = math.hypot(x - prev[0], y - prev[1]) / self.dt
        yaw = dz.base.yaw
        if z < surface and speed >= b.cut_min_speed:
            got = self.ground.cut((prev[0], prev[1]), (x, y), z, width=b.width,
                                  lateral=(-math.sin(yaw), math.cos(yaw)), max_volume=b.capacity - load)
            load += got
            self.soil.pushed += got
        elif load > 0.0 and z > surface + 0.05:
            self.ground.deposit(x + math.cos(yaw) * b.spill_distance, y + math.sin(yaw) * b.spill_distance, load,
                                self.spec.soil.dump_radius)
            load = 0.0
        self.soil.blades[name] = load
        soil, base = self.spec.soil.cutting, dz.base
        track = 0.5 * (base.vl + base.vr)
        force = 0.0
        if soil is not None and track > 0.0:
            ahead = self.spec.soil.resolution
            depth = max(surface, self.ground.height(x + math.cos(yaw) * ahead, y + math.sin(yaw) * ahead)) - z
            if depth > 0.0:
                rake_deg = self.spec.machines[name].physics.blade_rake_deg
                assert rake_deg is not None  # the dozer profile requires it
                lo, hi = rake_range(soil)
                rake = min(max(math.radians(rake_deg), lo + 0.05), hi - 0.05)
                force = float(fee_force(soil, rake, depth, b.width).horizontal[0])
            force += load * self.spec.soil.loose_density * G * math.tan(soil.phi)
            # ramped in over the first 2 cm/s of track speed (as tool_force's): tracks at rest push nothing
            force *= min(1.0, track / 0.02)
        self.blade_force[name] = base.drawbar = force

    # -- replay ------------------------------------------------------------------------------------
    def set_truth(self, machine: str, x: float, y: float, yaw: float, joints: dict[str, float]) -> None:
        """Teleport a machine (replay mode): base pose and joint angles, actuators emptied."""
        m = self.machines[machine]
        m.base.x, m.base.y, m.base.yaw = x, y, yaw
        bank = m.bank
        bank.set_positions(joints)
        bank.reset()
        self._place_joints()
        self._place_bases()
        self.drives.reset(settle_s=0.0)  # replay: the recorded poses, not a load to carry
        self.model.forward()
        if self.excavator is not None:
            self._tip = self.model.bucket_tip()
