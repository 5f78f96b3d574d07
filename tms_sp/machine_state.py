"""Machine states as the original's ``tms_sp_machine`` writers send them to the DB, without ROS.

The original (``tms_sp/tms_sp_machine/scripts``) runs one node per machine and input: ``tms_sp_machine_joints``
(JointState), ``tms_sp_machine_odom`` (Odometry) and ``tms_sp_machine_posest`` (PoseStamped); each publishes on
``tms_db_data`` a ``tms_msg_db/Tmsdb`` with ``time`` the wall clock (``datetime.now().isoformat()``), ``type``
``machine_joints`` (joints) or ``machine_pose`` (odometry and pose), ``id`` 3012, ``name`` the machine's name and
``msg`` the JSON of the whole input message, field by field (``tms_db_util.msg_to_document``). Here one core serves
every machine and input; it keeps the newest message of each and hands out what a publishing tick writes, so a
rate bounds what reaches the DB (the original writes every message: rate 0).
"""

from __future__ import annotations

import array
import datetime as _dt
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tms_sp.errors import SensingError

__all__ = ["DATA_ID", "JOINTS_TYPE", "POSE_TYPE", "SOURCE_TYPES", "message_to_document", "stamp_text",
           "tmsdb_fields", "MachineStateSampler"]

#: ``id`` of every machine-state document (the original's DATA_ID)
DATA_ID = 3012
JOINTS_TYPE = "machine_joints"
POSE_TYPE = "machine_pose"
#: input -> the collection (``type``) its documents go to, as the original's three writers
SOURCE_TYPES = {"joints": JOINTS_TYPE, "odom": POSE_TYPE, "pose": POSE_TYPE}


def message_to_document(msg: Any) -> Any:
    """A ROS message as nested dicts, field by field in its definition's order (the original's ``msg_to_document``
    without rosidl's internal ``check_fields`` slot); arrays as lists. A non-finite float becomes ``None``: JSON has
    no NaN and the store refuses it (the original's MongoDB kept NaN)."""
    fields = getattr(msg, "get_fields_and_field_types", None)
    if callable(fields):
        return {name: message_to_document(getattr(msg, name)) for name in fields()}
    if isinstance(msg, bytes | bytearray):
        return list(msg)
    if isinstance(msg, np.ndarray | array.array):
        msg = msg.tolist()
    if isinstance(msg, list | tuple):
        return [message_to_document(v) for v in msg]
    if isinstance(msg, np.generic):
        msg = msg.item()
    if isinstance(msg, float) and not math.isfinite(msg):
        return None
    return msg


def stamp_text(now: _dt.datetime) -> str:
    """``time`` of a document: ISO 8601 with microseconds always (``isoformat()`` drops them at .000000, which the
    original's own reader then fails to parse)."""
    return now.isoformat(timespec="microseconds")


def tmsdb_fields(machine: str, source: str, msg: Any, time: str) -> dict:
    """The ``Tmsdb`` fields for ``msg`` of ``machine`` from input ``source`` (``joints``, ``odom``, ``pose``)."""
    try:
        kind = SOURCE_TYPES[source]
    except KeyError:
        raise SensingError(f"machine {machine!r}: input {source!r} is not one of {sorted(SOURCE_TYPES)}") from None
    return {"time": time, "type": kind, "id": DATA_ID, "name": machine,
            "msg": json.dumps(message_to_document(msg), allow_nan=False)}


@dataclass
class _Pending:
    msg: Any
    time: str


class MachineStateSampler:
    """The newest message of each (machine, input) until a tick takes it.

    ``rate_hz`` 0: :meth:`offer` returns the document at once (the original, every message); otherwise :meth:`offer`
    keeps the message and :meth:`take` (called every ``1 / rate_hz`` s) returns one document per (machine, input)
    that received something since the last tick, in machine order.
    """

    def __init__(self, machines: Iterable[str], rate_hz: float, clock: Callable[[], _dt.datetime] | None = None):
        self.machines = list(dict.fromkeys(machines))
        if not self.machines or not all(isinstance(m, str) and m for m in self.machines):
            raise SensingError(f"machines: a non-empty list of machine names is needed, got {self.machines!r}")
        if isinstance(rate_hz, bool) or not isinstance(rate_hz, int | float) or not math.isfinite(rate_hz) \
                or rate_hz < 0:
            raise SensingError(f"rate_hz: must be a number >= 0 (0: every message), got {rate_hz!r}")
        self.rate_hz = float(rate_hz)
        self._clock = clock or _dt.datetime.now
        self._pending: dict[tuple[str, str], _Pending] = {}

    def offer(self, machine: str, source: str, msg: Any) -> dict | None:
        """A message arrived; the document to publish now (rate 0) or None (kept for the next tick)."""
        if machine not in self.machines:
            raise SensingError(f"machine {machine!r} is not one of {self.machines}")
        time = stamp_text(self._clock())
        if self.rate_hz == 0:
            return tmsdb_fields(machine, source, msg, time)
        self._pending[(machine, source)] = _Pending(msg, time)
        return None

    def take(self) -> list[dict]:
        """The documents of this tick (each message converted once, here, not at 50 Hz in :meth:`offer`)."""
        order = {m: i for i, m in enumerate(self.machines)}
        keys = sorted(self._pending, key=lambda k: (order[k[0]], k[1]))
        out = [tmsdb_fields(m, s, self._pending[(m, s)].msg, self._pending[(m, s)].time) for m, s in keys]
        self._pending.clear()
        return out
