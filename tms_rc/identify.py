"""Command ``tms_rc_identify``: identify an excavator's front hydraulics over its COM3 CAN bus.

Like HEAP identifies its valves, it drives each front joint (swing, boom, arm, bucket) with velocity-command
steps (several amplitudes, both directions, small ones for the dead band) and a chirp, then boom, arm and bucket
at full command together (pump saturation), records the state frames (Front_Angle, Front_Angular_Velocity,
Hydraulic_Flow_Rate_1), runs :mod:`tms_rc.identification` and writes ``config/tms_rc/identified/<machine>.yaml``,
which the arm controller reads (dead times, lags, flow per joint speed, pump flow)::

    tms_rc_identify --plant-config config/sim/plant.yaml --machine zx200      # starts sim_plant itself
    tms_rc_identify --machine zx200 --can-interface udp_multicast --can-channel 239.74.163.20 --can-port 43120

Time base: the plant's own, the count of Front_Angular_Velocity frames times their DBC cycle (10 ms); the
command is sent on every such frame, so a plant slower than real time still yields its simulated-time delays.
The measured dead time therefore includes the CAN link both ways and the frame period.

Safety: the arm starts where it is (the plant's home pose), every step is planned inside the joint limits of the
machine's description less a margin, large steps begin at the far side of the range, and a guard zeroes a
joint's command as soon as its speed times the expected stopping time would carry it past the margin.
Only the description's geometry and limits are read (joints, velocity limits, home pose), never its hydraulics.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import math
import os
import random
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np

from tms_common.config import config_path, data_root, load_yaml
from tms_common.errors import ConfigError
from tms_common.schema import Reader
from tms_model.excavator.kinematics import JOINTS
from tms_model.fleet import load_bus_config, load_named
from tms_model.machines import EXCAVATOR, Machine, load_machine
from tms_model.site import Site
from tms_rc.identification import (
    JointEstimate,
    StepRecord,
    chirp_bandwidth,
    chirp_phase,
    estimate_joint,
    flow_per_speed,
    saturated_pump_flow,
)

__all__ = ["main", "identified_path", "IDENTIFIED_DIR"]

IDENTIFIED_DIR = ("tms_rc", "identified")
SHORT = {"swing_joint": "swing", "boom_joint": "boom", "arm_joint": "arm", "bucket_joint": "bucket"}
PUMP_JOINTS = ("boom_joint", "arm_joint", "bucket_joint")
#: [rad] kept inside the description's joint limits
MARGIN = 0.05
#: [rad] half range the continuous swing is allowed around where it starts
SWING_HALF_RANGE = 2.0
#: step amplitudes, fractions of the joint's velocity limit (1.2: beyond it, to see the saturation)
AMPLITUDES = (0.02, 0.05, 0.1, 0.25, 0.5, 0.8, 1.2)
#: [rad/s] a joint at rest below this
REST_SPEED = 0.002


def identified_path(name: str) -> Path:
    """``config/tms_rc/identified/<name>.yaml``."""
    return config_path(*IDENTIFIED_DIR, f"{name}.yaml")


# ------------------------------------------------------------------------------------------------- the CAN link
@dataclass
class Sample:
    tick: int
    q: np.ndarray
    v: np.ndarray
    flow: np.ndarray  # [L/min] flow into each drive in JOINTS order (Link.flow)
    u: np.ndarray  # the command sent on this tick


class Codec:
    """The machine's COM3 DBC through cantools. com3_can, on the same architecture level as tms_rc, is not imported
    (docs/architecture.md); its DBC files are read from its package directory, as the plant's and bridge's are."""

    def __init__(self, dbc: str) -> None:
        self.db = cantools.database.load_file(str(resources.files("com3_can").joinpath("dbc", dbc)), strict=True)

    def frame_id(self, name: str) -> int:
        return self.db.get_message_by_name(name).frame_id

    def cycle_ms(self, name: str) -> int:
        return int(self.db.get_message_by_name(name).cycle_time or 10)

    def neutral(self, name: str) -> dict[str, float]:
        """Every signal of frame ``name`` at physical 0 (clamped into its range)."""
        out = {}
        for sig in self.db.get_message_by_name(name).signals:
            lo = sig.minimum if sig.minimum is not None else -math.inf
            hi = sig.maximum if sig.maximum is not None and sig.maximum > lo else math.inf
            out[sig.name] = min(max(0.0, lo), hi)
        return out

    def encode(self, name: str, values: Mapping[str, float]) -> bytes:
        return bytes(self.db.get_message_by_name(name).encode(dict(values), scaling=True, strict=False))

    def decode(self, arbitration_id: int, data: bytes) -> tuple[str, dict[str, float]]:
        msg = self.db.get_message_by_frame_id(arbitration_id)
        return msg.name, {k: float(v) for k, v in msg.decode(data, decode_choices=False).items()}


def bus_config(name: str, overrides: Mapping[str, Any] | None = None, site: Site | None = None) -> dict[str, Any]:
    """The link to the real bus of the machine called ``name``: the top level of its kind's
    ``config/can/<kind>.yaml`` with the site's ``can`` changes for it (:func:`tms_model.fleet.load_bus_config`,
    as the converter reads it), then ``overrides`` (the ``--can-*`` options) that are not None; without the
    converter's sections (``bridge``, ``in_process``). ConfigError (``file:line: key: problem``) for a bad file."""
    cfg = load_bus_config(name, site=site)
    out = {k: v for k, v in cfg.items() if k not in ("bridge", "in_process")}
    out.update({k: v for k, v in (overrides or {}).items() if v is not None})
    if out.get("interface") != "udp_multicast":
        out.pop("port", None)
    return out


def _plant_machines(plant_config: Path) -> Reader:
    """The ``machines:`` mapping (name -> description file) of a plant YAML, read through tms_common.schema."""
    data, where = load_yaml(plant_config)
    return Reader(data, where).sub("machines")


class Link:
    """The COM3 peer: a command frame on every Front_Angular_Velocity frame, the latest state kept per tick.

    ``front_mode`` / ``travel_mode``: the ``Machine_Setting_Cmd`` sources (front 1 pilot pressure, 2 velocity; travel
    1 pilot, 3 centre velocity + yaw rate); a pilot-pressure peer (:mod:`tms_rc.identify_pistons`) sends its own
    frames through :meth:`transmit` and :meth:`send_setting`."""

    def __init__(self, codec: Codec, bus_cfg: Mapping[str, Any], front_mode: int = 2, travel_mode: int = 3) -> None:
        self._can = can
        self.codec = codec
        self.bus = can.Bus(ignore_config=True, **bus_cfg)
        self.dt = codec.cycle_ms("Front_Angular_Velocity") * 1e-3
        self.tick = 0
        self.q: np.ndarray | None = None
        self.v = np.zeros(len(JOINTS))
        self.flow = np.zeros(len(JOINTS))
        self._setting = codec.neutral("Machine_Setting_Cmd")
        self._setting.update(front_signal_switch_command=front_mode, travel_signal_switch_command=travel_mode,
                             engine_rpm=2000,
                             power_eco_mode=1, working_mode_notice=1, yellow_led_mode=2)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.send({j: 0.0 for j in JOINTS})
        self.bus.shutdown()

    def send(self, u: Mapping[str, float]) -> None:
        values = self.codec.neutral("Velocity_Cmd_1")
        values.update({f"{SHORT[j]}_target_anguler_velocity": float(u.get(j, 0.0)) for j in JOINTS})
        self.transmit("Velocity_Cmd_1", values)
        self.send_setting()

    def send_setting(self, now: bool = False) -> None:
        """``Machine_Setting_Cmd`` on every 5th tick (its 50 ms DBC cycle), or ``now``."""
        if now or self.tick % 5 == 0:
            self.transmit("Machine_Setting_Cmd", self._setting)

    def transmit(self, frame: str, values: Mapping[str, float]) -> None:
        self.bus.send(self._can.Message(arbitration_id=self.codec.frame_id(frame),
                                        data=self.codec.encode(frame, values), is_extended_id=True))

    def wait_tick(self, timeout: float = 5.0) -> None:
        """Block until the next Front_Angular_Velocity frame (one plant step), keeping the other frames' values."""
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no Front_Angular_Velocity frame within {timeout} s: is the plant running on "
                                   f"this bus ({self.bus.channel_info})?")
            msg = self.bus.recv(min(remaining, 0.1))
            if msg is None:
                continue
            try:
                name, values = self.codec.decode(msg.arbitration_id, bytes(msg.data))
            except Exception:  # noqa: BLE001 - another machine's ids on a shared bus, an echo
                continue
            if name == "Front_Angle":
                self.q = np.array([values[f"{SHORT[j]}_relative_angle"] for j in JOINTS])
            elif name == "Hydraulic_Flow_Rate_1":
                # the flow into each drive (what its pump supplies): + into the cap / port A side, - out of it
                ports = [("swing_motor_a_flow_rate", "swing_motor_b_flow_rate")] + [
                    (f"{SHORT[j]}_cylinder_bottom_flow_rate", f"{SHORT[j]}_cylinder_rod_flow_rate") for j in JOINTS[1:]]
                self.flow = np.array([max(values[a], 0.0) + max(values[b], 0.0) for a, b in ports])
            elif name == "Front_Angular_Velocity":
                self.v = np.array([values[f"{SHORT[j]}_relative_angular_velocity"] for j in JOINTS])
                if self.q is not None:
                    self.tick += 1
                    return


# ---------------------------------------------------------------------------------------------- the experiment
@dataclass
class JointPlan:
    """What is known of one joint while it is identified: range, and the delays so far (for stop distances)."""

    index: int
    vmax: float
    lo: float
    hi: float
    dead: float = 1.0  # [s] guesses until the first steps are fitted
    lag: float = 0.5
    gain: float = 1.0

    @property
    def stop_s(self) -> float:
        """[s] the joint moves on this long after its command goes to zero."""
        # after the command goes to zero a joint at speed v moves v (dead + lag): the command still in the dead
        # time, then the lag's decay
        return self.dead + self.lag


@dataclass
class Recording:
    samples: list[Sample] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {"tick": np.array([s.tick for s in self.samples]), "q": np.array([s.q for s in self.samples]),
                "v": np.array([s.v for s in self.samples]), "flow": np.array([s.flow for s in self.samples]),
                "u": np.array([s.u for s in self.samples])}


class Experiment:
    def __init__(self, link: Link, machine: Machine, log: Callable[[str], None], wait_s: float = 30.0) -> None:
        self.link = link
        self.log = log
        self.link.wait_tick(wait_s)
        assert link.q is not None
        self.start_q = link.q.copy()
        self.plans: dict[str, JointPlan] = {}
        for i, j in enumerate(JOINTS):
            joint = machine.joint(j)
            if joint.lower is None or joint.upper is None:
                lo, hi = self.start_q[i] - SWING_HALF_RANGE, self.start_q[i] + SWING_HALF_RANGE
            else:
                lo, hi = joint.lower + MARGIN, joint.upper - MARGIN
            self.plans[j] = JointPlan(i, joint.velocity, lo, hi)

    # -- primitives
    def run(self, command: Callable[[int], Mapping[str, float]], ticks: int, rec: Recording | None = None,
            guard: bool = True) -> Recording:
        """Send ``command(k)`` on each of the next ``ticks`` plant steps (zeroed by the guard near a limit)."""
        rec = rec if rec is not None else Recording()
        cut: set[str] = set()
        for k in range(ticks):
            q, v = self.link.q, self.link.v
            u = dict(command(k))
            if guard:
                for j, p in self.plans.items():
                    c = u.get(j, 0.0)
                    if j in cut or c == 0.0:
                        continue
                    # the measured speed (median of the last frames: a dynamic plant rings); the commanded one would
                    # stop a step early while the dead time and lag estimates are still those of the small steps
                    recent = [smp.v[p.index] for smp in rec.samples[-5:]] or [v[p.index]]
                    speed = abs(float(np.median(recent)))
                    ahead = q[p.index] + math.copysign(speed * p.stop_s, c)
                    if not p.lo <= ahead <= p.hi:
                        cut.add(j)
                        self.log(f"  guard: {j} command {c:+.3f} rad/s stopped at {q[p.index]:.3f} rad "
                                 f"(range {p.lo:.3f}..{p.hi:.3f})")
                for j in cut:
                    u[j] = 0.0
            self.link.send(u)
            rec.samples.append(Sample(self.link.tick, q.copy(), v.copy(), self.link.flow.copy(),
                                      np.array([u.get(j, 0.0) for j in JOINTS])))
            self.link.wait_tick()
        return rec

    def rest(self, rec: Recording | None = None, max_s: float = 15.0) -> Recording:
        """Zero command until every joint rests (after the longest stop time at least)."""
        rec = rec if rec is not None else Recording()
        min_ticks = int(max(p.stop_s for p in self.plans.values()) / self.link.dt)
        still = 0
        for k in range(int(max_s / self.link.dt)):
            self.run(lambda _k: {}, 1, rec, guard=False)
            still = still + 1 if np.all(np.abs(self.link.v) < REST_SPEED) else 0
            if k >= min_ticks and still >= 20:
                break
        return rec

    def move_to(self, targets: Mapping[str, float], tol: float = 0.03) -> None:
        """Open-loop moves at half the velocity limit (command area = displacement), corrected once or twice."""
        for _ in range(3):
            q = self.link.q
            moves = {j: t - q[self.plans[j].index] for j, t in targets.items()}
            moves = {j: d for j, d in moves.items() if abs(d) > tol}
            if not moves:
                return
            speed = {j: math.copysign(0.5 * self.plans[j].vmax, d) for j, d in moves.items()}
            ticks = {j: int(round(abs(d) / (abs(speed[j]) * self.plans[j].gain) / self.link.dt))
                     for j, d in moves.items()}

            def command(k: int, speed: dict[str, float] = speed, ticks: dict[str, int] = ticks) -> dict[str, float]:
                return {j: v for j, v in speed.items() if k < ticks[j]}

            self.run(command, max(ticks.values()), guard=False)
            self.rest()

    def step(self, joint: str, command: float, hold_s: float) -> StepRecord:
        p = self.plans[joint]
        n_hold = int(round(hold_s / self.link.dt))
        rec = self.run(lambda k: {joint: command} if k < n_hold else {}, n_hold)
        self.rest(rec)
        a = rec.arrays()
        u = a["u"][:, p.index]
        cut = np.flatnonzero(u != command)
        held = int(cut[0]) if cut.size else n_hold
        t = (a["tick"] - a["tick"][0]) * self.link.dt
        return StepRecord(joint, command, t, a["v"][:, p.index], held * self.link.dt, a["flow"][:, p.index])

    # -- procedures
    def identify_joint(self, joint: str, amplitudes: Sequence[float],
                       chirp_s: float) -> tuple[JointEstimate, list[StepRecord], dict[str, Any]]:
        p = self.plans[joint]
        centre = float(np.clip(self.start_q[p.index], p.lo, p.hi))
        span = p.hi - p.lo
        records: list[StepRecord] = []
        hold = 3.0
        self.rest()  # the dynamic plant settles under gravity after it starts
        for frac in amplitudes:
            for sign in (1.0, -1.0):
                cmd = sign * frac * p.vmax
                # the joint travels its speed (at most the velocity limit) times the hold
                travel = min(abs(cmd) * p.gain, p.vmax) * hold
                if travel > 0.9 * span:
                    cmd = math.copysign(0.9 * span / hold / p.gain, cmd)
                    travel = 0.9 * span
                q = self.link.q[p.index]
                if any(abs(cmd - r.command) < 1e-9 for r in records):
                    continue  # an amplitude capped to one already stepped
                if not (p.lo + 0.05 * span <= q + math.copysign(1.1 * travel, cmd) <= p.hi - 0.05 * span):
                    # from the far side of the range (a long step) or around the centre (a short one)
                    start = centre - math.copysign(travel / 2.0, cmd)
                    start = float(np.clip(start, p.lo + 0.02 * span, p.hi - 0.02 * span - travel) if cmd > 0
                                  else np.clip(start, p.lo + 0.02 * span + travel, p.hi - 0.02 * span))
                    self.move_to({joint: start})
                rec = self.step(joint, cmd, hold)
                records.append(rec)
                self.log(f"  {joint} step {cmd:+.4f} rad/s for {rec.hold_s:.2f} s")
            moving = [r for r in records if abs(np.median(r.speed[r.t >= 0.8 * r.hold_s])) > 0.003]
            if moving and len(moving) >= 2:
                with contextlib.suppress(ValueError):
                    est = estimate_joint(records)
                    p.dead, p.lag, p.gain = est.dead_time_s, est.lag_s, max(est.gain, 0.1)
                    hold = max(1.0, p.dead + 4.5 * p.lag)
        est = estimate_joint(records)
        p.dead, p.lag, p.gain = est.dead_time_s, est.lag_s, max(est.gain, 0.1)
        chirp: dict[str, Any] = {}
        if chirp_s > 0:
            amp = 0.25 * p.vmax
            f1 = 3.0
            # the joint swings over 2 amp / (2 pi f) at frequency f: start where that fits the range
            f0 = max(0.1, 2.0 * amp * p.gain / (2.0 * math.pi * 0.7 * span))
            self.move_to({joint: float(np.clip(centre - amp * p.gain / (2 * math.pi * f0), p.lo, p.hi))})
            n = int(round(chirp_s / self.link.dt))
            rec = self.run(lambda k: {joint: amp * math.sin(float(chirp_phase(k * self.link.dt, f0, f1, chirp_s)))},
                           n)
            self.rest(rec)
            a = rec.arrays()
            t = (a["tick"] - a["tick"][0]) * self.link.dt
            bw, table = chirp_bandwidth(t, a["u"][:, p.index], a["v"][:, p.index], f0=f0, f1=f1, gain=est.gain)
            chirp = {"bandwidth_hz": bw, "f0": f0, "f1": f1, "amplitude": amp, "duration": chirp_s, "table": table}
            self.log(f"  {joint} chirp {f0:.2f}..{f1:.1f} Hz at {amp:.3f} rad/s: -3 dB at {bw:.3f} Hz")
        self.move_to({joint: centre})
        return est, records, chirp

    def pump(self) -> dict[str, Any]:
        """Boom up, arm crowd and bucket curl at their velocity limits at once, from the far ends of their ranges."""
        dirs = {"boom_joint": -1.0, "arm_joint": 1.0, "bucket_joint": 1.0}
        starts = {j: (self.plans[j].hi if d < 0 else self.plans[j].lo) for j, d in dirs.items()}
        self.move_to(starts)
        hold = max(self.plans[j].dead + 5.0 * self.plans[j].lag for j in dirs)
        n = int(round(hold / self.link.dt))
        cmd = {j: d * self.plans[j].vmax for j, d in dirs.items()}
        rec = self.run(lambda k: cmd if k < n else {}, n)
        self.rest(rec)
        a = rec.arrays()
        idx = [self.plans[j].index for j in dirs]
        t = (a["tick"] - a["tick"][0]) * self.link.dt
        total = np.sum(np.abs(a["flow"][:, idx]), axis=1)
        return {"t": t, "total": total, "command": cmd, "speeds": a["v"][:, idx]}


# --------------------------------------------------------------------------------------------------- the plant
def _free_port(rng: random.Random) -> int:
    """A udp port below Fast DDS's (7400 + 250 * domain ...) and the tests' CAN ports (3000..6999) no socket holds."""
    for _ in range(200):
        port = rng.randrange(2000, 3000)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("", port))
            except OSError:
                continue
            return port
    raise RuntimeError("no free udp port in 2000..2999 for a private CAN bus")


@contextlib.contextmanager
def start_plant(plant_config: Path, speed: float, log: Callable[[str], None]) -> Iterator[dict[str, dict[str, Any]]]:
    """Run ``sim_plant`` on ``plant_config`` with every machine on a private udp_multicast bus; yields the buses.

    ROS discovery is off for it (ROS_AUTOMATIC_DISCOVERY_RANGE=OFF): its /clock and truth topics reach no one.
    """
    names = _plant_machines(plant_config).keys()
    rng = random.Random(os.getpid() * 7919 + time.monotonic_ns())
    buses = {m: {"interface": "udp_multicast", "channel": f"239.76.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
                 "port": _free_port(rng)} for m in names}
    # the console script beside this interpreter (the project's venv), else the one on PATH
    exe = Path(sys.executable).parent / "sim_plant"
    if not exe.is_file():
        found = shutil.which("sim_plant")
        if found is None:
            raise ConfigError("sim_plant: no such command beside this Python or on PATH (is the project installed?)")
        exe = Path(found)
    args = [str(exe), "--ros-args", "-p", f"config:={plant_config}", "-p", f"speed:={speed}"]
    for m, cfg in buses.items():
        args += ["-p", f"{m}_can_interface:={cfg['interface']}", "-p", f"{m}_can_channel:={cfg['channel']}",
                 "-p", f"{m}_can_port:={cfg['port']}"]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="OFF", PYTHONUNBUFFERED="1")
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    lines: list[str] = []
    ready = threading.Event()

    def pump_output() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip())
            if "sim_plant: running" in line:
                ready.set()

    threading.Thread(target=pump_output, daemon=True).start()
    try:
        if not ready.wait(90.0):
            raise RuntimeError("sim_plant did not start within 90 s:\n" + "\n".join(lines[-20:]))
        log(f"sim_plant running on {plant_config} (pid {proc.pid})")
        try:
            yield buses
        except BaseException:
            log("sim_plant's last output:\n" + "\n".join(lines[-15:]))
            raise
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 15)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                proc.wait()


# ------------------------------------------------------------------------------------------------------ output
def _rel(path: Path) -> str:
    root = data_root().resolve()
    with contextlib.suppress(ValueError):
        return str(path.resolve().relative_to(root))
    return str(path)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def _num(x: float, nd: int = 4) -> str:
    return "null" if x is None or not math.isfinite(x) else f"{round(float(x), nd):g}"


def render(name: str, command_line: str, plant_lines: Sequence[str], estimates: Mapping[str, JointEstimate],
           flows: Mapping[str, tuple[float, float]], chirps: Mapping[str, Mapping[str, Any]],
           pump: Mapping[str, Any] | None, dt: float) -> str:
    out = [
        f"# Front hydraulics of {name} identified over its COM3 CAN bus by tms_rc_identify (tms_rc/identify.py),",
        "# read by the arm controller (config/tms_rc/excavator_arm_controller.yaml `identified`). Made with:",
        f"#   {command_line}",
        *plant_lines,
        "# Figures (tms_rc.identification): dead_time_s = first response after a velocity step and lag_s = the",
        "# first-order lag, a dead-time + lag fit of the unsaturated steps (median); measured in the plant's time",
        f"# (Front_Angular_Velocity frames x {dt * 1e3:g} ms, the command sent on each), so the dead time already",
        "# includes the CAN link both ways and the frame period. gain = steady speed / command; saturated_speed_rad_s",
        "# dead_band_rad_s and flow_lpm_per_rad_s = [negative, positive direction]; flow_lpm_per_rad_s = the flow",
        "# into the drive (Hydraulic_Flow_Rate_1: cylinder bottom side extending, rod side retracting; swing motor",
        "# inlet port) per unit joint speed; bandwidth_hz = -3 dB of a chirp.",
        f"machine: {name}",
    ]
    if pump is not None:
        out += [
            "# pump_flow_lpm: total flow into boom+arm+bucket at full command together (saturated: the demand",
            "# of the three commands at their flow coefficients exceeds it; false = a lower bound only).",
            f"pump_flow_lpm: {_num(pump['flow'], 1)}",
            f"pump_saturated: {'true' if pump['saturated'] else 'false'}",
        ]
    out.append("joints:")
    for j, e in estimates.items():
        c = chirps.get(j, {})
        out.append(
            f"  {j}: {{dead_time_s: {_num(e.dead_time_s, 3)}, lag_s: {_num(e.lag_s, 3)}, gain: {_num(e.gain, 3)}, "
            f"saturated_speed_rad_s: [{_num(e.saturated_speed[0], 3)}, {_num(e.saturated_speed[1], 3)}], "
            f"dead_band_rad_s: [{_num(e.dead_band[0], 4)}, {_num(e.dead_band[1], 4)}], "
            f"flow_lpm_per_rad_s: [{_num(flows[j][0], 1)}, {_num(flows[j][1], 1)}], "
            f"bandwidth_hz: {_num(c.get('bandwidth_hz', math.nan), 3)}}}"
        )
    out.append("# The steps: command [rad/s] -> steady speed [rad/s], dead time [s], lag [s], fit rms [rad/s]")
    for j, e in estimates.items():
        for f in e.fits:
            out.append(f"#   {j} {f.command:+.4f} -> {f.steady:+.4f}"
                       + (f", {f.dead_time_s:.3f}, {f.lag_s:.3f}, {f.rms:.4f}" if f.moved else ", still"))
    for j, c in chirps.items():
        out.append(f"# Chirp {j}: {c['f0']:.3f}..{c['f1']:g} Hz log over {c['duration']:g} s at {c['amplitude']:.3f} "
                   "rad/s; |G|/gain at " + ", ".join(f"{f:.2f} Hz {m:.2f}" for f, m in c["table"][::3]))
    return "\n".join(out) + "\n"


def _plant_lines(plant_config: Path | None, machine_file: Path | None, bus: Mapping[str, Any]) -> list[str]:
    if plant_config is None:
        return [f"# Plant: a running plant on {dict(bus)}; its configuration is not known to this command."]
    lines = [f"# Plant: sim_plant on {_rel(plant_config)} (sha256 {_sha(plant_config)}), this machine described by "
             f"{_rel(machine_file)} (sha256 {_sha(machine_file)})." if machine_file else
             f"# Plant: sim_plant on {_rel(plant_config)} (sha256 {_sha(plant_config)}).",
             f"# {_rel(plant_config)} as it was:"]
    lines += [f"#   | {line}" for line in plant_config.read_text().splitlines()]
    return lines


def _command_line(prog: str, argv: Sequence[str] | None) -> str:
    """The command as run (``prog`` and its words; existing files relative to the repo), for a file's header."""
    words = [prog, *(sys.argv[1:] if argv is None else argv)]
    return shlex.join(_rel(Path(w)) if Path(w).exists() else w for w in words)


# -------------------------------------------------------------------------------------------------------- main
def _common_args(ap: argparse.ArgumentParser) -> None:
    """The options every identification over the bus has: the machine, the plant it may start, the bus."""
    ap.add_argument("--machine", required=True, help="the excavator's name on the site (its namespace)")
    ap.add_argument("--plant-config", type=Path, help="start sim_plant on this plant YAML (private CAN buses)")
    ap.add_argument("--speed", type=float, default=1.0, help="sim_plant speed (x real time) with --plant-config")
    ap.add_argument("--machine-config", type=Path, help="the machine description (default: the plant config's "
                    "entry, else config/machines/<kind>.yaml)")
    ap.add_argument("--can-interface"), ap.add_argument("--can-channel"), ap.add_argument("--can-port", type=int)


def _args(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="tms_rc_identify", description=__doc__.split("\n\n")[0])
    _common_args(ap)
    ap.add_argument("--joints", default=",".join(JOINTS), help="comma-separated front joints to identify")
    ap.add_argument("--amplitudes", default=",".join(map(str, AMPLITUDES)),
                    help="step amplitudes, fractions of each joint's velocity limit")
    ap.add_argument("--chirp-s", type=float, default=25.0, help="chirp duration [s] per joint (0: no chirp)")
    ap.add_argument("--no-pump", action="store_true", help="skip the boom+arm+bucket pump saturation run")
    ap.add_argument("--wait-s", type=float, default=30.0,
                    help="[s] longest wait for the plant's first state frame (a plant still starting)")
    ap.add_argument("--output", type=Path, help="default config/tms_rc/identified/<machine>.yaml")
    return ap.parse_args(argv)


def _description(name: str, machine_file: Path | None, plant_config: Path | None) -> tuple[Machine, Path | None]:
    if machine_file is None and plant_config is not None:
        machines = _plant_machines(plant_config)
        if not machines.has(name):
            raise machines.error(machines.path, f"no machine {name!r} (has {sorted(machines.keys())})")
        entry = machines.string(name)
        machine_file = Path(entry) if Path(entry).is_absolute() else config_path(entry)
    if machine_file is not None:
        return load_machine(machine_file.stem, machine_file).named(name), machine_file
    m = load_named(name)
    return m, Path(m.source) if m.source else None


def _terminate(_signum: int, _frame: Any) -> None:
    raise SystemExit(143)  # the plant started here is stopped on the way out


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; a bad file or option stops it with one line (``file:line: key: problem``), exit code 2; a
    plant that sends nothing, a plant that does not start or a CAN bus that cannot be opened, one line, exit code 1."""
    signal.signal(signal.SIGTERM, _terminate)
    args = _args(argv)
    try:
        return _run(args, argv)
    except (ConfigError, ValueError) as exc:
        print(f"tms_rc_identify: {exc}", file=sys.stderr, flush=True)
        return 2
    except (TimeoutError, RuntimeError, can.CanError, OSError) as exc:
        print(f"tms_rc_identify: {exc}", file=sys.stderr, flush=True)
        return 1


def _run(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    if args.plant_config is not None:
        args.plant_config = args.plant_config.resolve()
    command_line = _command_line("tms_rc_identify", argv)

    def log(msg: str) -> None:
        print(msg, flush=True)

    machine, machine_file = _description(args.machine, args.machine_config, args.plant_config)
    machine.require(EXCAVATOR)
    joints = [j.strip() for j in args.joints.split(",") if j.strip()]
    unknown = [j for j in joints if j not in JOINTS]
    if unknown:
        raise ConfigError(f"--joints: {unknown} are not front joints {list(JOINTS)}")
    amplitudes = sorted(float(a) for a in args.amplitudes.split(","))
    codec = Codec(machine.dbc)
    # a real bus: the machine's kind's config/can/<kind>.yaml as the site changes it (read before anything starts)
    real_bus = None if args.plant_config is not None else bus_config(
        args.machine, {k: getattr(args, f"can_{k}") for k in ("interface", "channel", "port")})
    output = args.output or identified_path(args.machine)
    with contextlib.ExitStack() as stack:
        if args.plant_config is not None:
            buses = stack.enter_context(start_plant(args.plant_config, args.speed, log))
            bus = buses[args.machine]
        else:
            bus = real_bus
        link = Link(codec, bus)
        stack.callback(link.close)
        exp = Experiment(link, machine, log, args.wait_s)
        log(f"{args.machine}: start pose {np.round(exp.start_q, 3).tolist()} ({list(JOINTS)})")
        estimates: dict[str, JointEstimate] = {}
        flows: dict[str, tuple[float, float]] = {}
        chirps: dict[str, dict[str, Any]] = {}
        for j in joints:
            log(f"{j}:")
            est, records, chirp = exp.identify_joint(j, amplitudes, args.chirp_s)
            estimates[j] = est
            flows[j] = tuple(flow_per_speed([r for r in records if r.command * s > 0]) for s in (-1.0, 1.0))
            if chirp:
                chirps[j] = chirp
            log(f"  -> dead time {est.dead_time_s:.3f} s, lag {est.lag_s:.3f} s, gain {est.gain:.3f}, saturated "
                f"{est.saturated_speed[0]:.3f}/{est.saturated_speed[1]:.3f} rad/s, dead band "
                f"{est.dead_band[0]:.4f}/{est.dead_band[1]:.4f} rad/s, flow {flows[j][0]:.1f}/{flows[j][1]:.1f} L/min "
                "per rad/s")
        pump = None
        if not args.no_pump and all(j in estimates for j in PUMP_JOINTS):
            log("pump: boom + arm + bucket at full command")
            p = exp.pump()
            flow = saturated_pump_flow(p["t"], p["total"])
            demand = sum(flows[j][c > 0] * abs(c) * estimates[j].gain for j, c in p["command"].items())
            pump = {"flow": flow, "saturated": demand > 1.05 * flow, "demand": demand}
            log(f"  -> pump flow {flow:.1f} L/min (demand of the commands {demand:.1f} L/min)")
        exp.move_to({j: float(exp.start_q[exp.plans[j].index]) for j in JOINTS})
    text = render(args.machine, command_line, _plant_lines(args.plant_config, machine_file, bus), estimates, flows,
                  chirps, pump, link.dt)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text)
    log(f"wrote {_rel(output)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
