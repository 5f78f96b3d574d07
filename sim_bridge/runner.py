"""The plant loop: pacing (real time, N x real time, or as fast as possible), CAN I/O, truth log, replay.

One loop iteration = poll command frames, watchdog, one plant step (``dt`` of simulated time), state
frames due, then the ``on_step`` hook (the node publishes ``/clock`` and truth from it). With
``speed > 0`` the loop sleeps to an absolute deadline ``start + sim_time / speed`` (no drift), so in real time
the 10 ms frames leave every 10 ms of wall time. A late loop makes up at most ``catch_up_s`` of wall time by
running its steps without sleeping (default 0: none, a late step shifts the schedule); a longer stall shifts the
schedule by the rest. ``speed == 0`` runs as fast as the CPU allows.

Truth log (JSON lines, one record per ``period`` of simulated time): the time, every machine of the plant by
its name (base pose and the angles of the joints it reports) and the soil::

    {"t": 1.25, "<machine>": {"x":..,"y":..,"z":..,"yaw":.., "joints": {...}}, "<machine>": {...},
     "soil": {"mound": .., "ground": .., "bucket": .., "vessel": .., "dumped": ..}}

Replay drives the models from such a log (latest record at or before the current time) instead of
from the commands, as OperaSimVR's replay mode does: state frames, ``/clock`` and truth follow the log. The log
must hold the machines of the plant it is replayed on.
"""

from __future__ import annotations

import json
import threading
import time
from bisect import bisect_right
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from sim_bridge.can_io import PlantCanIO
from sim_bridge.errors import ReplayError
from sim_bridge.plant import Plant

__all__ = ["PlantRunner", "TruthRecorder", "TruthLog", "truth_record"]


#: keys of a truth record that are not machines
TIME, SOIL = "t", "soil"


def truth_record(plant: Plant) -> dict[str, Any]:
    """The plant's true state as one JSON-able record."""
    record: dict[str, Any] = {TIME: round(plant.time, 6)}
    for name, m in plant.machines.items():
        record[name] = {"x": m.base.x, "y": m.base.y, "z": m.z, "yaw": m.base.yaw,
                        "joints": dict(zip(m.bank.names, m.bank.q, strict=True))}
    record[SOIL] = {"mound": plant.ground.mound_volume(), "ground": plant.ground.ground_soil_volume(),
                    "bucket": plant.soil.bucket, "vessel": plant.soil.vessel, "dumped": plant.soil.dumped}
    return record


def _machines(record: dict[str, Any]) -> list[str]:
    return [key for key in record if key not in (TIME, SOIL)]


class TruthRecorder:
    """Appends truth records to a JSON-lines file every ``period`` simulated seconds."""

    def __init__(self, path: str | Path, period: float) -> None:
        self.path = Path(path)
        self.period = period
        self._next = 0.0
        self._file: IO[str] = self.path.open("w")

    def __call__(self, plant: Plant) -> None:
        if plant.time + 1e-9 >= self._next:
            self._file.write(json.dumps(truth_record(plant)) + "\n")
            self._next += self.period

    def close(self) -> None:
        self._file.close()


class TruthLog:
    """A recorded truth log loaded for replay."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            lines = self.path.read_text().splitlines()
        except OSError as exc:
            raise ReplayError(f"{self.path}: cannot read the truth log: {exc.strerror}") from None
        self.records: list[dict[str, Any]] = []
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                float(rec[TIME])
                rec[SOIL]  # presence check
                if not _machines(rec):
                    raise KeyError("no machine")
                for m in _machines(rec):
                    rec[m]["x"], rec[m]["y"], rec[m]["yaw"], rec[m]["joints"]  # presence check
            except (ValueError, KeyError, TypeError) as exc:
                raise ReplayError(f"{self.path}:{number}: not a truth record ({type(exc).__name__}: {exc})") from None
            self.records.append(rec)
        if not self.records:
            raise ReplayError(f"{self.path}: the truth log holds no records")
        self.times = [float(r[TIME]) for r in self.records]
        #: the machines of the log (those of its first record; every record must hold them)
        self.machines = tuple(_machines(self.records[0]))
        for number, rec in enumerate(self.records, 1):
            if tuple(_machines(rec)) != self.machines:
                raise ReplayError(f"{self.path}: record {number} holds the machines {_machines(rec)}, the first "
                                  f"{list(self.machines)}")

    @property
    def duration(self) -> float:
        return self.times[-1]

    def at(self, t: float) -> dict[str, Any]:
        """The latest record at or before ``t`` (the first one before the log starts)."""
        return self.records[max(0, bisect_right(self.times, t + 1e-9) - 1)]

    def check(self, plant: Plant) -> None:
        """ReplayError unless the log holds exactly the machines of ``plant``."""
        if set(self.machines) != set(plant.machines):
            raise ReplayError(f"{self.path}: the log holds the machines {sorted(self.machines)}, the plant "
                              f"{sorted(plant.machines)} (replay on the plant YAML it was recorded with)")

    def apply(self, plant: Plant) -> dict[str, Any]:
        rec = self.at(plant.time)
        for m in self.machines:
            r = rec[m]
            plant.set_truth(m, r["x"], r["y"], r["yaw"], r["joints"])
        return rec


class PlantRunner:
    """Runs the plant loop until ``stop()`` (or ``duration`` simulated seconds)."""

    def __init__(
        self,
        plant: Plant,
        io: PlantCanIO | None,
        *,
        speed: float = 1.0,
        on_step: Callable[[Plant], None] | None = None,
        replay: TruthLog | None = None,
        catch_up_s: float = 0.0,
    ) -> None:
        if speed < 0:
            raise ValueError(f"speed must be >= 0 (0 = as fast as possible), got {speed}")
        if catch_up_s < 0:
            raise ValueError(f"catch_up_s must be >= 0 (0 = no catching up), got {catch_up_s}")
        self.plant = plant
        self.io = io
        self.speed = speed
        self.catch_up_s = catch_up_s
        self.on_step = on_step
        self.replay = replay
        if replay is not None:
            replay.check(plant)
            if io is not None:
                io.replay = True
        self._stop = threading.Event()
        self._now, self._sleep = time.perf_counter, time.sleep  # the wall clock (a test's own, to step it)
        self.wall_elapsed = 0.0
        self.late_steps = 0  # steps that started more than one dt (wall, scaled) behind schedule

    def stop(self) -> None:
        self._stop.set()

    def run(self, duration: float | None = None) -> None:
        plant, io = self.plant, self.io
        t_sim0 = plant.time
        wall0 = start = self._now()
        dt = plant.dt
        while not self._stop.is_set():
            if duration is not None and plant.time - t_sim0 >= duration - 1e-9:
                break
            if self.speed > 0:
                deadline = wall0 + (plant.time - t_sim0) / self.speed
                delay = deadline - self._now()
                if delay > 0:
                    self._sleep(delay)
                elif delay < -dt / self.speed:
                    self.late_steps += 1
                    if -delay > self.catch_up_s:  # keep catch_up_s of the lag to make up, shift by the rest
                        wall0 += -delay - self.catch_up_s
            if io is not None:
                io.poll()
                io.watchdog()
            if self.replay is not None:
                plant.advance_clock()
                self.replay.apply(plant)
            else:
                plant.step()
            if io is not None:
                io.emit()
            if self.on_step is not None:
                self.on_step(plant)
        self.wall_elapsed = self._now() - start
