"""The pilot cut-off frame (hydraulic lock): converter -> machine, a TMS extension beside COM3.

COM3 carries no lock or emergency-stop command: on the real machines the hydraulic lock is a function
of the separate radio lock-release remote, and ``Machine_State`` only reports it
(``lock_cmd_state``, ``pilot_shutoff_valve_state``). A stop through the proportional command path
waits for the hydraulic dead time (0.31-0.93 s on the ZX200), so a fast stop needs the pilot cut-off:
the pilot shut-off solenoid vents the pilot line and the main spools spring to neutral in ~0.1 s.
``dbc/pilot_cutoff.dbc`` defines one frame, ``Pilot_Cutoff_Cmd`` (same id on both machines' buses),
for a relay wired in series with that solenoid. The converter sends it on every change and every
100 ms (its DBC cycle) once a cut-off was requested; the plant honours it after the solenoid delay
of its machine YAML (``pilot_cutoff:``).
"""

from __future__ import annotations

from functools import cache
from importlib import resources

import cantools

from com3_can.codec import AliveCounter, Com3Codec

__all__ = ["FRAME", "cutoff_codec", "CutoffSender"]

FRAME = "Pilot_Cutoff_Cmd"


@cache
def cutoff_codec() -> Com3Codec:
    """Codec of ``dbc/pilot_cutoff.dbc`` (one command frame)."""
    text = resources.files("com3_can").joinpath("dbc", "pilot_cutoff.dbc").read_text()
    db = cantools.database.load_string(text, database_format="dbc", strict=True)
    return Com3Codec(db, "pilot_cutoff")


class CutoffSender:
    """Cut-off state of one converter and its frames (not thread-safe; the node serialises calls).

    ``requested`` is the OR of the sources (``lock`` topic, emg_stop latch). Nothing is sent until a
    cut-off was requested once, so a converter never asked to lock puts no extra frame on the bus.
    """

    def __init__(self) -> None:
        self.codec = cutoff_codec()
        self.frame_id = self.codec.frame_id(FRAME)
        self.period = self.codec.cycle_ms(FRAME) / 1000.0
        self.sources: dict[str, bool] = {}
        self._alive = AliveCounter()
        self._active = False  # a cut-off was requested at least once: keep sending cyclically
        self._next = 0.0

    @property
    def engaged(self) -> bool:
        return any(self.sources.values())

    def set(self, source: str, on: bool, now: float) -> bytes | None:
        """Set one source; returns the frame payload to send at once when the state changed."""
        before = self.engaged
        self.sources[source] = bool(on)
        if self.engaged and not self._active:
            self._active = True
        if self._active and self.engaged != before:
            return self._frame(now)
        return None

    def due(self, now: float) -> bytes | None:
        """The cyclic frame when due (only once a cut-off was ever requested)."""
        if self._active and now >= self._next:
            return self._frame(now)
        return None

    def _frame(self, now: float) -> bytes:
        self._next = now + self.period
        return self.codec.encode(FRAME, {"pilot_cutoff_cmd": 1.0 if self.engaged else 0.0,
                                         "alive_counter": float(self._alive.next())})
