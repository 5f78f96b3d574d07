"""Pure core of the web control panel: configuration, access control, commands and the site snapshot.

Nothing here imports rclpy or a web framework, so it is unit-tested directly; ``tms_ur.nodes.tms_ur_panel``
wires it to ROS topics and a websocket server.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import math
import re
import time
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from tms_common.errors import ConfigError, TmsError
from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_model.machines import CRAWLER_DUMP, DOZER, EXCAVATOR, LIFT_JOINT, ROTATE_JOINT, VESSEL_JOINT, Machine
from tms_model.transform import Transform
from tms_model.urdf import MachineTree
from tms_sp.terrain import TerrainError

__all__ = [
    "PanelConfig",
    "CommandError",
    "Command",
    "parse_command",
    "authorize",
    "check_origin",
    "check_token",
    "websocket_access",
    "Access",
    "INT32_MIN",
    "INT32_MAX",
    "TASK_ID_RANGE",
    "check_int_range",
    "SiteState",
    "arm_side_view",
    "machine_info",
    "TfError",
    "SiteTfView",
    "terrain_layer",
    "ReplayClock",
]


class CommandError(TmsError, ValueError):
    """A command from the browser is malformed; the message says which field."""


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and 'localhost'."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class PanelConfig:
    """Panel settings (ROS parameters of ``tms_ur_panel``; defaults in config/ur/panel.yaml).

    A bind address other than loopback requires a token: every request from a non-local address must
    then carry it (``?token=...``), and the panel refuses to start without one.
    """

    host: str = "127.0.0.1"
    port: int = 8088
    token: str = ""
    rate_hz: float = 5.0
    flag_records: tuple[str, ...] = ()
    db_uri: str = ""
    db_path: str = ""

    def __post_init__(self) -> None:
        if not is_loopback(self.host) and not self.token:
            raise ConfigError(f"tms_ur_panel: bind address {self.host!r} is not loopback; set a 'token' in the config")
        if not 0 < self.port < 65536:
            raise ConfigError(f"tms_ur_panel: port {self.port} out of range 1..65535")
        if not self.rate_hz >= 5.0:
            raise ConfigError(f"tms_ur_panel: rate_hz must be >= 5 (live view), got {self.rate_hz}")


def _token_matches(token: str | None, expected: str) -> bool:
    # compare_digest refuses str with non-ASCII characters (TypeError): compare the UTF-8 bytes instead,
    # so a hostile ``?token=%C3%A9`` is a wrong token, not an exception in the handshake.
    if not token:
        return False
    return hmac.compare_digest(token.encode("utf-8", "surrogatepass"), expected.encode("utf-8", "surrogatepass"))


def authorize(config: PanelConfig, remote_host: str, token: str | None) -> tuple[bool, str]:
    """Decide whether a request from ``remote_host`` carrying ``token`` may reach the panel at all (HTTP level)."""
    if is_loopback(remote_host):
        return True, "local"
    if not config.token:
        return False, "non-local requests are refused: the panel has no token configured"
    if _token_matches(token, config.token):
        return True, "token"
    return False, "non-local request without a valid token"


def _short(value: Any, limit: int = 60) -> str:
    """``repr`` cut to ``limit`` characters: refusal messages stay one short line whatever a client sends."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _host_port(authority: str) -> tuple[str, int] | None:
    """``host[:port]`` -> (lower-case host without IPv6 brackets, port; 80 when absent), None when malformed."""
    try:
        parts = urlsplit("http://" + authority)
        host, port = parts.hostname, parts.port
    except ValueError:
        return None
    if not host or parts.path or parts.query or parts.fragment or parts.username is not None:
        return None
    return host, 80 if port is None else port


def check_origin(config: PanelConfig, origins: list[str], host_header: str | None) -> tuple[bool, str]:
    """May a websocket whose handshake carried these ``Origin`` headers command the machines?

    The panel's own page opens ``ws://<the address in its URL bar>/ws``, so its Origin is ``http://`` + the
    handshake's ``Host``. A page from anywhere else (another port, host or scheme, ``null`` from a sandbox or a
    file) differs. Host == Origin alone would let a DNS-rebinding page (evil.example resolving to 127.0.0.1)
    pass, so a loopback panel (no token) also requires the host to be a loopback name; off loopback the
    token (``check_token``) is what a rebinding page cannot have. No Origin at all is a non-browser client
    (browsers always send one on a websocket handshake, RFC 6455 4.1): a web page cannot omit it, and a local
    program could publish on the ROS topics directly, so it is allowed, under the same token rule.
    """
    if not origins:
        return True, "no Origin header: a non-browser client"
    if len(origins) > 1:
        return False, f"bad origin: {len(origins)} Origin headers"
    origin = origins[0]
    host_hp = _host_port(host_header) if host_header and host_header.isascii() else None
    own = f"http://{host_header}" if host_hp else f"http://{config.host}:{config.port}"
    parts = urlsplit(origin) if origin.isascii() else None
    if parts is None or parts.scheme != "http" or not parts.netloc:
        return False, f"bad origin {_short(origin)}: the panel's own page is {own}"
    origin_hp = _host_port(parts.netloc)
    if origin_hp is None or origin.rstrip("/") != f"{parts.scheme}://{parts.netloc}":
        return False, f"bad origin {_short(origin)}: not scheme://host:port"
    if host_hp is None:
        return False, f"bad origin {_short(origin)}: the handshake has no valid Host header to compare it with"
    if origin_hp != host_hp or origin_hp[1] != config.port:
        return False, f"bad origin {_short(origin)}: the panel's own page is {own}"
    if is_loopback(config.host) and not is_loopback(origin_hp[0]):
        return False, f"bad origin {_short(origin)}: a loopback panel is addressed by a loopback name only"
    return True, "own origin"


def check_token(config: PanelConfig, token: str | None) -> tuple[bool, str]:
    """Commands need the panel's token whenever one is configured (always the case off loopback)."""
    if not config.token:
        return True, "no token configured (loopback panel)"
    if not token:
        return False, "missing token: this panel takes commands only from a URL with ?token=..."
    if _token_matches(token, config.token):
        return True, "token"
    return False, "wrong token"


@dataclass(frozen=True)
class Access:
    """What one websocket connection may do, decided once at its handshake."""

    commands: bool  # start, cancel, emergency stop, confirm: everything the websocket takes writes or commands
    view: bool  # the live-view snapshots
    refusal: str = ""  # why commands are refused (sent back with every refused command, logged once)
    kind: str = ""  # "bad origin", "missing token" or "wrong token" when refused


def websocket_access(config: PanelConfig, origins: list[str], host_header: str | None,
                     token: str | None) -> Access:
    """Origin and token rules together. A page from another origin gets neither commands nor the live view
    (the site's state is not for other sites to read); the own page without the token gets the view only."""
    origin_ok, origin_reason = check_origin(config, origins, host_header)
    if not origin_ok:
        return Access(commands=False, view=False, refusal=origin_reason, kind="bad origin")
    token_ok, token_reason = check_token(config, token)
    if token_ok:
        return Access(commands=True, view=True)
    return Access(commands=False, view=True, refusal=token_reason, kind="wrong token" if token else "missing token")


#: Range of the ROS ``int32`` type: ``tms_msg/TaskIds.task_ids`` (int32[]), ``std_msgs/Int32`` (cancel) and the
#: tms_msg_ts ``task_id`` fields. tests/tms_ur/test_panel_core.py checks them against the generated messages.
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
#: Task ids the panel accepts: positive int32 (a larger one would wrap when serialised, 4294967297 -> 1).
TASK_ID_RANGE = (1, INT32_MAX)


def check_int_range(field_name: str, value: int, lo: int, hi: int, type_name: str) -> int:
    """``value`` if ``lo <= value <= hi``, else a CommandError naming the field, the value and the range."""
    if not lo <= value <= hi:
        raise CommandError(f"{field_name}: {_short(value, 40)} is out of range {lo}..{hi} ({type_name})")
    return value


@dataclass(frozen=True)
class Command:
    op: str
    task_ids: tuple[int, ...] = ()
    seek: float | None = None  # replay: go to this log time [s]
    play: bool | None = None  # replay: play (True) or pause (False)


_OPS = {"start", "cancel", "emergency", "confirm", "replay"}


def parse_command(text: str) -> Command:
    """Parse one browser command: ``{"op": "start", "task_ids": [1, 2]}``, ``{"op": "cancel", "task_id": 1}``,
    ``{"op": "emergency"}`` or ``{"op": "confirm"}``."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CommandError(f"command is not JSON: {exc.msg}") from None
    except RecursionError:
        # json recurses per nesting level: '[' * 100000 fits in one frame
        raise CommandError("command is not JSON the panel reads: nested too deep") from None
    except ValueError as exc:
        # an integer literal of more than 4300 digits (int conversion limit)
        raise CommandError(f"command is not JSON the panel reads: {str(exc)[:80]}") from None
    if not isinstance(data, dict):
        raise CommandError("command must be a JSON object")
    op = data.get("op")
    if op not in _OPS:
        raise CommandError(f"unknown op {op!r}; expected one of {', '.join(sorted(_OPS))}")
    if op == "start":
        ids = data.get("task_ids")
        if not isinstance(ids, list) or not ids:
            raise CommandError("start needs a non-empty 'task_ids' list")
        return Command(op, tuple(_task_id(i, "task_ids") for i in ids))
    if op == "cancel":
        return Command(op, (_task_id(data.get("task_id"), "task_id"),))
    if op == "replay":
        seek, play = data.get("seek"), data.get("play")
        if seek is not None and (isinstance(seek, bool) or not isinstance(seek, (int, float))
                                 or not math.isfinite(seek)):
            raise CommandError(f"replay: 'seek' must be a time in seconds, got {_short(seek)}")
        if play is not None and not isinstance(play, bool):
            raise CommandError(f"replay: 'play' must be true or false, got {_short(play)}")
        if seek is None and play is None:
            raise CommandError("replay needs 'seek' (a log time in seconds) or 'play' (true/false)")
        return Command(op, seek=None if seek is None else float(seek), play=play)
    return Command(op)


_DECIMAL = re.compile(r"\s*[+-]?[0-9]{1,40}\s*", re.ASCII)


def _task_id(value: Any, field_name: str) -> int:
    """A task id from JSON (an integer, or a string of ASCII digits), checked against ``TASK_ID_RANGE``
    before any message is built: int32 fields do not check on assignment, they wrap when serialised."""
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise CommandError(f"{field_name}: task id must be an integer, got {_short(value)}")
    if isinstance(value, str):
        # int() would also take '1_0', full-width and other Unicode digits, and 4000-digit strings
        if not _DECIMAL.fullmatch(value):
            raise CommandError(f"{field_name}: task id must be an integer, got {_short(value)}")
        value = int(value)
    lo, hi = TASK_ID_RANGE
    return check_int_range(field_name, value, lo, hi, "task ids are positive int32")


def arm_side_view(joints: dict[str, float], kin: ExcavatorKinematics) -> list[list[float]]:
    """Side-view polyline (radial distance, height) [m] of the excavator front: boom foot, arm pin, bucket pin, tip.

    ``joints`` maps joint names to angles (missing = 0); the geometry is the machine model's.
    """
    q = np.array([float(joints.get(name, 0.0)) for name in kin.joints])
    return [[round(float(x), 3), round(float(z), 3)] for x, z in kin.side_view(q)]


def machine_info(machine: Machine) -> dict[str, Any]:
    """What the page needs of a machine's description to draw it: name, kind, type and footprint [m]."""
    return {"name": machine.model_name, "kind": machine.kind, "type": machine.type,
            "length": machine.footprint.length, "width": machine.footprint.width}


def _angle(joints: dict[str, float], name: str) -> float | None:
    return round(float(joints[name]), 4) if name in joints else None


@dataclass
class SiteState:
    """Latest values for the live view; every setter is cheap, ``snapshot()`` builds the JSON message.

    Per machine by name, after its description's type (:meth:`set_joints`): an excavator's arm side view and swing
    (``arms``), a carrier's vessel (``vessels``: tip angle, slew angle of a rotating upper body, load), a dozer's blade
    (``blades``: lift angle). ``machines`` are the machines shown (:func:`machine_info`), in the order the page
    colours them.
    """

    tasks: list[dict[str, Any]] = field(default_factory=list)
    task_catalogue: list[dict[str, Any]] = field(default_factory=list)
    flags: dict[str, dict[str, Any]] = field(default_factory=dict)
    machines: list[dict[str, Any]] = field(default_factory=list)
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    trails: dict[str, list[list[float]]] = field(default_factory=dict)
    plans: dict[str, list[list[float]]] = field(default_factory=dict)
    arms: dict[str, dict[str, Any]] = field(default_factory=dict)
    vessels: dict[str, dict[str, float | None]] = field(default_factory=dict)
    blades: dict[str, dict[str, float | None]] = field(default_factory=dict)
    soil: dict[str, float] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    max_trail: int = 2000

    def set_joints(self, machine: Machine, joints: dict[str, float], kin: ExcavatorKinematics | None = None) -> None:
        """Machine ``machine``'s measured joints (name -> position) into the view its type has; an excavator needs
        its ``kin`` (the side view is its forward kinematics)."""
        name = machine.model_name
        if machine.type == EXCAVATOR and kin is not None:
            self.arms[name] = {"side": arm_side_view(joints, kin), "swing": _angle(joints, kin.joints[0]) or 0.0}
        elif machine.type == CRAWLER_DUMP:
            vessel = self.vessels.setdefault(name, {})
            vessel["angle"] = _angle(joints, VESSEL_JOINT)
            if machine.swing is not None:
                vessel["swing"] = _angle(joints, ROTATE_JOINT)
        elif machine.type == DOZER:
            self.blades[name] = {"lift": _angle(joints, LIFT_JOINT)}

    def set_load(self, machine: str, volume: float) -> None:
        """Soil in carrier ``machine``'s vessel [m^3]."""
        self.vessels.setdefault(machine, {})["load"] = round(float(volume), 3)

    def set_plan(self, machine: str, points: list[list[float]]) -> None:
        """Machine ``machine``'s planned path, thinned to at most about 400 points."""
        self.plans[machine] = points[:: max(1, len(points) // 400)]

    def set_pose(self, machine: str, x: float, y: float, yaw: float) -> None:
        self.poses[machine] = {"x": round(x, 3), "y": round(y, 3), "yaw": round(yaw, 4)}
        trail = self.trails.setdefault(machine, [])
        if not trail or math.hypot(trail[-1][0] - x, trail[-1][1] - y) > 0.2:
            trail.append([round(x, 2), round(y, 2)])
            del trail[: max(0, len(trail) - self.max_trail)]

    def event(self, level: str, text: str) -> None:
        """Record a message shown in the panel's event log (errors from the scheduler, refusals)."""
        self.events.append({"t": round(time.time(), 3), "level": level, "text": text})
        del self.events[: max(0, len(self.events) - 50)]

    def snapshot(self) -> dict[str, Any]:
        return {
            "type": "state",
            "t": round(time.time(), 3),
            "tasks": self.tasks,
            "catalogue": self.task_catalogue,
            "flags": self.flags,
            "machines": self.machines,
            "poses": self.poses,
            "trails": self.trails,
            "plans": self.plans,
            "arms": self.arms,
            "vessels": self.vessels,
            "blades": self.blades,
            "soil": self.soil,
            "events": self.events[-20:],
        }


# ---- the 3-D view: link poses in map from /tf, terrain layers -------------------------------------------------------
class TfError(TmsError, ValueError):
    """A /tf transform the 3-D view cannot use; the message names the frames and the field."""


MAP_FRAME = "map"


class SiteTfView:
    """Latest /tf and /tf_static edges, composed into each machine's link poses in ``map`` for the 3-D view.

    ``trees`` are the machines shown (their URDF trees, frames with the machine's tf prefix). Each machine's poses
    carry the stamp of its ``odom -> base_link`` edge (the pose the page draws) and the stamp of every edge from its
    base up to ``map`` (``chain``, by child frame), so a client can compare the view with exactly those /tf edges.
    Edges of frames no shown machine has (another site's) are ignored.
    """

    def __init__(self, trees: list[MachineTree]) -> None:
        self.trees = {t.machine.model_name: t for t in trees}
        self._edges: dict[str, tuple[str, Transform, float]] = {}  # child -> (parent, parent_T_child, stamp)
        self._known = {MAP_FRAME}
        for t in trees:
            self._known |= {t.frame(link) for link in (*t.links, "odom")}
        self.version = 0  # bumped on every accepted edge: the snapshot is rebuilt only when it changed

    def set(self, parent: str, child: str, translation: tuple[float, float, float],
            rotation: tuple[float, float, float, float], stamp: float) -> None:
        """One transform ``parent_T_child`` at ``stamp`` [s]; TfError naming the frames for a non-finite value or a
        rotation that is not a unit quaternion (nothing is kept then)."""
        if child not in self._known:
            return
        values = (*translation, *rotation)
        if not all(math.isfinite(v) for v in values):
            raise TfError(f"/tf {parent} -> {child}: non-finite value in {values}")
        norm = math.sqrt(sum(c * c for c in rotation))
        if abs(norm - 1.0) > 0.01:
            raise TfError(f"/tf {parent} -> {child}: rotation quaternion has norm {norm:.4f}, expected 1")
        rot = tuple(float(c) / norm for c in rotation)
        self._edges[child] = (parent, Transform(tuple(float(v) for v in translation), rot), float(stamp))  # type: ignore[arg-type]
        self.version += 1

    def in_map(self, frame: str) -> Transform | None:
        """``map_T_frame`` from the latest edges; None while an edge of the chain is missing."""
        out = Transform()
        seen = 0
        while frame != MAP_FRAME:
            edge = self._edges.get(frame)
            if edge is None or seen > 64:
                return None
            out = edge[1] * out
            frame = edge[0]
            seen += 1
        return out

    def machine_links(self, name: str) -> dict[str, Any] | None:
        """``{"stamp": s, "links": {frame: [x, y, z, qx, qy, qz, qw]}}`` in ``map`` for machine ``name``; None until
        its base_link reaches ``map``."""
        tree = self.trees[name]
        base = tree.frame("base_link")
        edge = self._edges.get(base)
        if edge is None or self.in_map(base) is None:
            return None
        links = {}
        for link in tree.links:
            pose = self.in_map(tree.frame(link))
            if pose is not None:
                links[tree.frame(link)] = [round(v, 5) for v in (*pose.translation, *pose.rotation)]
        chain, frame = {}, base
        while frame != MAP_FRAME and frame in self._edges and len(chain) < 64:
            chain[frame] = round(self._edges[frame][2], 9)
            frame = self._edges[frame][0]
        return {"stamp": round(edge[2], 9), "chain": chain, "links": links}

    def snapshot(self) -> dict[str, Any]:
        return {name: pose for name in self.trees if (pose := self.machine_links(name)) is not None}


def terrain_layer(kind: str, file_id: str, z: np.ndarray, x_min: float, y_min: float, x_max: float,
                  y_max: float) -> dict[str, Any]:
    """A heightmap (``z[row, col]`` in image order: row 0 the north edge) as the 3-D view draws it, heights in
    mm-rounded metres, row-major; ``tms_sp.terrain.TerrainError`` naming the layer for non-finite heights or an empty
    extent."""
    z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.size == 0 or not np.all(np.isfinite(z)):
        raise TerrainError(f"terrain {kind} {file_id}: heights must be a finite 2-D grid, got shape {z.shape}")
    if not (x_max > x_min and y_max > y_min):
        raise TerrainError(f"terrain {kind} {file_id}: empty extent x {x_min}..{x_max} y {y_min}..{y_max}")
    return {"kind": kind, "id": str(file_id), "rows": int(z.shape[0]), "cols": int(z.shape[1]),
            "x_min": float(x_min), "y_min": float(y_min), "x_max": float(x_max), "y_max": float(y_max),
            "z": [round(float(v), 3) for v in z.ravel()]}


class ReplayClock:
    """Which recorded messages the view has applied: log times ``times`` [ns] sorted ascending, a cursor and a
    replay time [s] that advances with wall time while playing.

    The view's state at time ``t`` is every message with log time <= ``t`` applied in order, so a seek back
    restarts from the first message (:meth:`seek` says so by returning True) and a seek forward only applies
    the messages in between.
    """

    def __init__(self, times_ns: list[int]) -> None:
        if not times_ns:
            raise CommandError("replay: the recording holds no message of the panel's topics")
        if any(b < a for a, b in zip(times_ns, times_ns[1:], strict=False)):
            raise CommandError("replay: the recording's messages are not in log-time order")
        self.times = times_ns
        self.start = times_ns[0] * 1e-9
        self.end = times_ns[-1] * 1e-9
        self.t = self.start
        self.cursor = 0  # messages [0, cursor) are applied
        self.playing = False

    def seek(self, t: float) -> bool:
        """Go to ``t`` (clamped to the recording); True when the view must be cleared and refilled from the start."""
        t = min(max(float(t), self.start), self.end)
        restart = t < self.t
        if restart:
            self.cursor = 0
        self.t = t
        return restart

    def advance(self, wall_dt: float) -> None:
        """While playing, move the replay time on by ``wall_dt`` (real-time replay); pause at the end."""
        if self.playing:
            self.t = min(self.t + max(0.0, wall_dt), self.end)
            if self.t >= self.end:
                self.playing = False

    def due(self) -> range:
        """Indices of the messages to apply now (log time <= t), and the cursor moves past them."""
        limit = int(round(self.t * 1e9))
        first = self.cursor
        while self.cursor < len(self.times) and self.times[self.cursor] <= limit:
            self.cursor += 1
        return range(first, self.cursor)

    def state(self) -> dict[str, Any]:
        return {"start": self.start, "end": self.end, "t": round(self.t, 9), "playing": self.playing}
