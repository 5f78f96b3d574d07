"""DBC-driven COM3 codecs (cantools) with strict range checks, neutral commands and the alive counter.

:func:`load_codec` returns an immutable :class:`Com3Codec` for a machine kind: the DBC its machine
description names (``can: {dbc: ...}`` of ``config/machines/<kind>.yaml``, e.g. the published COM3 excavator
frames ``dbc/excavator_com3.dbc``, our crawler-carrier extension ``dbc/crawler_carrier_com3.dbc`` or our dozer
extension ``dbc/dozer_com3.dbc``). Encoding refuses any value outside the signal's DBC range (or its raw
bit range where the DBC says ``[0|0]``, i.e. unspecified) instead of clipping or wrapping; decoding
refuses unknown ids, wrong DLCs and values outside the DBC range. The tables are built once from the
parsed DBC, so the per-frame cost is one cantools call plus one range loop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources
from types import MappingProxyType

import cantools
import cantools.database

from com3_can.errors import Com3DecodeError, Com3EncodeError
from tms_common.errors import ConfigError
from tms_model.machines import load_machine

__all__ = [
    "SignalSpec",
    "Com3Codec",
    "AliveCounter",
    "load_codec",
    "load_codec_from_string",
    "codec_for",
    "dbc_file",
    "dbc_files",
    "dbc_text",
]

#: Neutral (safe, "do nothing") physical values of command signals whose neutral is not 0 physical.
#: Everything else is neutral at physical 0 (0 rad/s, 0 m/s, 0 MPa pilot, mode "none").
#: Note: 0 physical is *not* all-zero bytes where the DBC has an offset (0 rad/s = raw 32000).
_NEUTRAL_OVERRIDES: Mapping[tuple[str, str], float] = MappingProxyType(
    {
        ("Machine_Setting_Cmd", "engine_rpm"): 900.0,  # idle rpm used by the reference tools
    }
)

#: Mask of the 29-bit identifier (DBC ids carry bit 31 as the "extended" flag).
EXT_ID_MASK = 0x1FFFFFFF


@dataclass(frozen=True)
class SignalSpec:
    """One signal of a frame: physical range accepted (DBC min/max, or the raw bit range when unspecified)."""

    name: str
    minimum: float
    maximum: float
    scale: float
    offset: float
    unit: str

    @property
    def lsb(self) -> float:
        """Physical value of one raw step."""
        return abs(self.scale)


def _signal_spec(sig: cantools.database.can.Signal) -> SignalSpec:
    scale = float(sig.scale)
    offset = float(sig.offset)
    raw_lo = -(2 ** (sig.length - 1)) if sig.is_signed else 0
    raw_hi = 2 ** (sig.length - 1) - 1 if sig.is_signed else 2**sig.length - 1
    lo = sig.minimum if sig.minimum is not None else raw_lo * scale + offset
    hi = sig.maximum if sig.maximum is not None else raw_hi * scale + offset
    return SignalSpec(sig.name, float(lo), float(hi), scale, offset, sig.unit or "")


@dataclass(frozen=True)
class _Frame:
    name: str
    frame_id: int
    dlc: int
    cycle_ms: int
    is_command: bool
    signals: tuple[SignalSpec, ...]
    message: cantools.database.can.Message
    # (name, lo - eps, hi + eps): eps absorbs float noise of raw*scale+offset at the range ends
    checks: tuple[tuple[str, float, float], ...]


class Com3Codec:
    """Encode/decode the COM3 frames of one machine; immutable after construction.

    Args:
        db: a parsed cantools database (strict mode).
        machine: name used in messages (the machine's or its kind's).
        command_sender: DBC node that sends commands (frames it sends are command frames).
    """

    def __init__(self, db: cantools.database.can.Database, machine: str, command_sender: str = "ExternalController"):
        self.machine = machine
        frames: dict[str, _Frame] = {}
        by_id: dict[int, _Frame] = {}
        for msg in db.messages:
            if msg.cycle_time is None:
                raise Com3EncodeError(f"{machine}: frame {msg.name} has no GenMsgCycleTime in the DBC")
            specs = tuple(_signal_spec(s) for s in msg.signals)
            checks = tuple((s.name, s.minimum - s.lsb * 1e-6, s.maximum + s.lsb * 1e-6) for s in specs)
            frame = _Frame(
                name=msg.name,
                frame_id=msg.frame_id & EXT_ID_MASK,
                dlc=msg.length,
                cycle_ms=int(msg.cycle_time),
                is_command=command_sender in msg.senders,
                signals=specs,
                message=msg,
                checks=checks,
            )
            frames[msg.name] = frame
            by_id[frame.frame_id] = frame
        self._frames: Mapping[str, _Frame] = MappingProxyType(frames)
        self._by_id: Mapping[int, _Frame] = MappingProxyType(by_id)
        self.command_frames: tuple[str, ...] = tuple(f.name for f in frames.values() if f.is_command)
        self.state_frames: tuple[str, ...] = tuple(f.name for f in frames.values() if not f.is_command)
        self._neutral = MappingProxyType({name: self._make_neutral(name) for name in self.command_frames})

    # -- lookup ----------------------------------------------------------------------------------
    def _frame(self, name: str) -> _Frame:
        try:
            return self._frames[name]
        except KeyError:
            raise Com3EncodeError(
                f"{self.machine}: unknown frame {name!r}; known frames: {', '.join(self._frames)}"
            ) from None

    @property
    def frame_names(self) -> tuple[str, ...]:
        """All frame names in DBC order."""
        return tuple(self._frames)

    def frame_id(self, name: str) -> int:
        """29-bit arbitration id of frame ``name``."""
        return self._frame(name).frame_id

    def frame_name(self, arbitration_id: int) -> str:
        """Name of the frame with this 29-bit id; Com3DecodeError(reason='unknown_id') if none."""
        frame = self._by_id.get(arbitration_id & EXT_ID_MASK)
        if frame is None:
            raise Com3DecodeError(f"{self.machine}: unknown COM3 id 0x{arbitration_id:08X}", reason="unknown_id")
        return frame.name

    def cycle_ms(self, name: str) -> int:
        """Cycle time of frame ``name`` in ms (DBC GenMsgCycleTime)."""
        return self._frame(name).cycle_ms

    def dlc(self, name: str) -> int:
        """Data length of frame ``name`` in bytes."""
        return self._frame(name).dlc

    def signals(self, name: str) -> tuple[SignalSpec, ...]:
        """Signal specs (physical range, scale, unit) of frame ``name``."""
        return self._frame(name).signals

    def is_command(self, name: str) -> bool:
        """True for frames the external controller (this side) sends."""
        return self._frame(name).is_command

    # -- encode / decode ----------------------------------------------------------------------------
    def encode(self, frame_name: str, signals: Mapping[str, float]) -> bytes:
        """Encode every signal of ``frame_name`` (all required, none extra) into its payload.

        Raises:
            Com3EncodeError: unknown frame or signal, missing signal, non-numeric/NaN value, or a value
                outside the signal's range (message names frame, signal, range and value).
        """
        frame = self._frame(frame_name)
        if len(signals) != len(frame.checks):
            self._explain_names(frame, signals)
        try:
            for name, lo, hi in frame.checks:
                value = signals[name]
                if not lo <= value <= hi:
                    self._raise_range(frame, name, value)
        except KeyError:
            self._explain_names(frame, signals)
        except TypeError:
            bad = next(n for n, _, _ in frame.checks if not isinstance(signals.get(n), int | float))
            raise Com3EncodeError(
                f"{self.machine}: {frame_name}.{bad}: expected a number, got {signals.get(bad)!r}"
            ) from None
        return frame.message.encode(signals, scaling=True, padding=False, strict=False)

    def _explain_names(self, frame: _Frame, signals: Mapping[str, float]) -> None:
        wanted = {s.name for s in frame.signals}
        missing = sorted(wanted - set(signals))
        extra = sorted(set(signals) - wanted)
        parts = []
        if missing:
            parts.append(f"missing signal(s) {missing}")
        if extra:
            parts.append(f"unknown signal(s) {extra}")
        raise Com3EncodeError(f"{self.machine}: {frame.name}: {'; '.join(parts)}")

    def _raise_range(self, frame: _Frame, name: str, value: float) -> None:
        spec = next(s for s in frame.signals if s.name == name)
        what = "NaN" if isinstance(value, float) and math.isnan(value) else repr(value)
        raise Com3EncodeError(
            f"{self.machine}: {frame.name}.{name}: value {what} {spec.unit} outside "
            f"[{spec.minimum:g}, {spec.maximum:g}] {spec.unit}".rstrip()
        )

    def decode(self, arbitration_id: int, data: bytes) -> tuple[str, dict[str, float]]:
        """Decode a received frame into ``(frame_name, {signal: physical value})``.

        Raises:
            Com3DecodeError: ``reason`` ``unknown_id``, ``bad_dlc`` or ``out_of_range`` (a raw value
                outside the DBC range, e.g. pilot pressure raw 255 = 5.1 MPa > 5 MPa).
        """
        frame = self._by_id.get(arbitration_id & EXT_ID_MASK)
        if frame is None:
            raise Com3DecodeError(f"{self.machine}: unknown COM3 id 0x{arbitration_id:08X}", reason="unknown_id")
        if len(data) != frame.dlc:
            raise Com3DecodeError(
                f"{self.machine}: {frame.name} (0x{frame.frame_id:08X}): DLC {len(data)}, expected {frame.dlc}",
                reason="bad_dlc",
            )
        values = frame.message.decode(bytes(data), decode_choices=False, scaling=True)
        for name, lo, hi in frame.checks:
            value = values[name]
            if not lo <= value <= hi:
                spec = next(s for s in frame.signals if s.name == name)
                raise Com3DecodeError(
                    f"{self.machine}: {frame.name}.{name}: received {value:g} {spec.unit} outside "
                    f"[{spec.minimum:g}, {spec.maximum:g}]",
                    reason="out_of_range",
                )
        return frame.name, values

    # -- neutral ----------------------------------------------------------------------------------
    def _make_neutral(self, name: str) -> dict[str, float]:
        out: dict[str, float] = {}
        for spec in self._frame(name).signals:
            value = _NEUTRAL_OVERRIDES.get((name, spec.name), 0.0)
            if not spec.minimum <= value <= spec.maximum:
                value = spec.minimum
            out[spec.name] = value
        return out

    def neutral(self, frame_name: str) -> dict[str, float]:
        """Physical values of the neutral ("do nothing") command for a command frame (a fresh dict)."""
        frame = self._frame(frame_name)
        if not frame.is_command:
            raise Com3EncodeError(f"{self.machine}: {frame_name} is a state frame; only command frames have a neutral")
        return dict(self._neutral[frame_name])


class AliveCounter:
    """The 8-bit alive counter the external controller increments on every send (wraps 255 -> 0)."""

    def __init__(self, start: int = 0, modulo: int = 256) -> None:
        if not 0 <= start < modulo:
            raise ValueError(f"alive counter start {start} outside [0, {modulo - 1}]")
        self._value = start
        self._modulo = modulo

    @property
    def value(self) -> int:
        """The value the next frame will carry."""
        return self._value

    def next(self) -> int:
        """Return the value for this frame and advance."""
        value = self._value
        self._value = (value + 1) % self._modulo
        return value

    @staticmethod
    def is_successor(previous: int, current: int, modulo: int = 256) -> bool:
        """True when ``current`` follows ``previous`` by one (with wrap)."""
        return current == (previous + 1) % modulo


def dbc_files() -> tuple[str, ...]:
    """The DBC files shipped in ``com3_can/dbc``."""
    return tuple(
        sorted(p.name for p in resources.files("com3_can").joinpath("dbc").iterdir() if p.name.endswith(".dbc"))
    )


def dbc_file(kind: str) -> str:
    """The DBC file (in ``com3_can/dbc``) of machine kind ``kind``: the one its description names (``can.dbc``).

    Raises:
        ConfigError: unknown kind (naming the known ones), or a DBC named that is not shipped (naming the file).
    """
    description = load_machine(kind)
    if description.dbc not in dbc_files():
        raise ConfigError(f"{description.source}: can.dbc: no DBC file {description.dbc!r} in com3_can/dbc "
                          f"(shipped: {', '.join(dbc_files())})")
    return description.dbc


def dbc_text(machine: str) -> str:
    """The DBC text of machine kind ``machine`` (see :func:`dbc_file`)."""
    return resources.files("com3_can").joinpath("dbc", dbc_file(machine)).read_text()


def load_codec_from_string(text: str, machine: str) -> Com3Codec:
    """Build a codec from DBC text (strict cantools parse)."""
    db = cantools.database.load_string(text, database_format="dbc", strict=True)
    return Com3Codec(db, machine)


@cache
def codec_for(dbc: str, machine: str) -> Com3Codec:
    """The (cached) codec of DBC file ``dbc`` (in ``com3_can/dbc``), named ``machine`` in its messages."""
    text = resources.files("com3_can").joinpath("dbc", dbc).read_text()
    return load_codec_from_string(text, machine)


@cache
def load_codec(machine: str) -> Com3Codec:
    """The (cached, immutable) codec of machine kind ``machine``, found through its machine description."""
    return codec_for(dbc_file(machine), machine)
