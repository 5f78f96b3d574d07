"""Pure core of the web control panel: configuration, access control, commands and the site snapshot.

Nothing here imports rclpy or a web framework, so it is unit-tested directly; ``tms_ur.nodes.tms_ur_panel``
wires it to ROS topics and a websocket server.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tms_common.errors import ConfigError, TmsError
from tms_model.excavator.kinematics import ExcavatorKinematics

__all__ = [
    "PanelConfig",
    "CommandError",
    "Command",
    "parse_command",
    "authorize",
    "SiteState",
    "arm_side_view",
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


def authorize(config: PanelConfig, remote_host: str, token: str | None) -> tuple[bool, str]:
    """Decide whether a request from ``remote_host`` carrying ``token`` may use the panel."""
    if is_loopback(remote_host):
        return True, "local"
    if not config.token:
        return False, "non-local requests are refused: the panel has no token configured"
    if token and hmac.compare_digest(token, config.token):
        return True, "token"
    return False, "non-local request without a valid token"


@dataclass(frozen=True)
class Command:
    op: str
    task_ids: tuple[int, ...] = ()


_OPS = {"start", "cancel", "emergency", "confirm"}


def parse_command(text: str) -> Command:
    """Parse one browser command: ``{"op": "start", "task_ids": [1, 2]}``, ``{"op": "cancel", "task_id": 1}``,
    ``{"op": "emergency"}`` or ``{"op": "confirm"}``."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CommandError(f"command is not JSON: {exc.msg}") from None
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
    return Command(op)


def _task_id(value: Any, field_name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise CommandError(f"{field_name}: task id must be an integer, got {value!r}")
    try:
        task_id = int(value)
    except ValueError:
        raise CommandError(f"{field_name}: task id must be an integer, got {value!r}") from None
    if task_id <= 0:
        raise CommandError(f"{field_name}: task id must be positive, got {task_id}")
    return task_id


def arm_side_view(joints: dict[str, float], kin: ExcavatorKinematics) -> list[list[float]]:
    """Side-view polyline (radial distance, height) [m] of the excavator front: boom foot, arm pin, bucket pin, tip.

    ``joints`` maps joint names to angles (missing = 0); the geometry is the machine model's.
    """
    q = np.array([float(joints.get(name, 0.0)) for name in kin.joints])
    return [[round(float(x), 3), round(float(z), 3)] for x, z in kin.side_view(q)]


@dataclass
class SiteState:
    """Latest values for the live view; every setter is cheap, ``snapshot()`` builds the JSON message."""

    tasks: list[dict[str, Any]] = field(default_factory=list)
    task_catalogue: list[dict[str, Any]] = field(default_factory=list)
    flags: dict[str, dict[str, Any]] = field(default_factory=dict)
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    trails: dict[str, list[list[float]]] = field(default_factory=dict)
    plan: list[list[float]] = field(default_factory=list)
    arm: list[list[float]] = field(default_factory=list)
    swing: float = 0.0
    soil: dict[str, float] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    max_trail: int = 2000

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
            "poses": self.poses,
            "trails": self.trails,
            "plan": self.plan,
            "arm": self.arm,
            "swing": self.swing,
            "soil": self.soil,
            "events": self.events[-20:],
        }
