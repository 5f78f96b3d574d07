"""Pure core of the experiment supervisor: records a run and writes its report.

The recorder is fed time-stamped samples (simulated time ``t`` [s]) by ``tms_ur.nodes.tms_ur_experiment``:
soil volumes, truth and estimated poses, bucket-tip truth and estimate, global-blackboard flags,
task states and the leaves each task is running. From them it derives the events of the earthwork cycle:

* a **load pass** is one episode of vessel-load increase totalling more than ``pass_threshold`` m^3;
* a **haul cycle** ends with one episode of soil reaching the dump site (``dumped`` grows by more than
  ``pass_threshold``).

An episode is a run of increases with no gap longer than ``episode_gap_s``: a bucketful falls into the
vessel over a second or two and a vessel empties over several, sampled many times on the way; each
counts once, at the sample where its total first passes the threshold.

Several carriers (the fleet experiment, ``carriers``): each carrier's soil is fed by name
(:meth:`ExperimentRecorder.on_carrier_soil`: what landed in its vessel and what it dumped), and the **smallest
distance between two carriers near the loading point** is kept: the distance between two carriers' base
positions (truth) whenever at least one of them is within ``near_radius`` of ``loading_point``.

The **leaf times** are how long each task's leaves (its subtask calls, waits and flag reads, named as in
the tree) ran, from the ``running_leaves`` of ``/tms_ts/status``: where a load pass's time goes.

Any list of machines: every machine's truth pose (by name) gives its path; every estimate that comes is compared
with its own machine's truth (the travelling machines' localisation); every excavator's bucket tip (by name) with
its truth. The site map draws each machine by its type (:mod:`tms_ur.site_map`).

The **hydraulics of one load pass** (:meth:`ExperimentRecorder.on_hydraulics`, ``/sim/truth/<excavator>/hydraulics``
in MPa): a pass runs from the start of an ``excavate`` leaf to the start of the next; only the samples of the pass
going on and of the last complete pass without a dump in it are kept (one without a dump if there is one: the last
pass of a cycle also waits for the carrier's haul), so memory stays bounded over any run.

``report(directory)`` writes ``metrics.json``, ``site_map.png``, ``soil.png``, ``flags.png``, ``hydraulics.png``
(when hydraulics samples came) and ``index.html`` (one page linking them).

:func:`tree_actions`: the action servers a task's tree calls (its leaves' subtasks and their planning actions),
what the supervisor waits for before it starts the tasks.
"""

from __future__ import annotations

import json
import math
import statistics
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tms_model.fleet import load_named
from tms_model.machines import Machine
from tms_model.site import Site, load_site
from tms_ts.subtask_specs import SUBTASKS
from tms_ur.site_map import render_site_map

__all__ = ["AlignedError", "ExperimentRecorder", "Sample", "tasks_to_cancel_after_failure", "tree_actions",
           "TASK_DONE"]

#: task states (tms_msg/TaskState names) after which a task runs no more
TASK_DONE = frozenset({"SUCCESS", "FAILURE", "CANCELED"})


def tasks_to_cancel_after_failure(task_ids: list[int], states: dict[int, str]) -> list[int]:
    """The supervisor's policy when a task FAILED: every started task that has not ended yet, in order.

    Its partner would otherwise wait for a flag that never comes (a carrier's task waits for MOVING_FLG from
    an excavator's task that failed). ``states`` maps task id -> state name; returns [] when no task FAILED.
    """
    if not any(state == "FAILURE" for state in states.values()):
        return []
    return [tid for tid in task_ids if states.get(tid) not in TASK_DONE]


_TIP = "tip:"  # key prefix of an excavator's bucket-tip error series


def tree_actions(tree: str, blackboard: dict[str, Any] | None = None) -> list[str]:
    """The action servers task ``tree`` (its XML) calls, in order of first use: every leaf's
    ``/<model_name>/<subtask_name>``
    and, for a subtask of :data:`tms_ts.subtask_specs.SUBTASKS` whose downstream is an action, its planning action
    ``/<model_name>/<planning_action>``. A ``{key}`` port is read from the task's ``blackboard``; one it does not
    give (set by the tree itself) is left out."""
    blackboard = blackboard or {}

    def port(value: str) -> str | None:
        if value.startswith("{") and value.endswith("}"):
            got = blackboard.get(value[1:-1])
            return str(got) if isinstance(got, str) and got else None
        return value.strip("/")

    actions: list[str] = []
    for el in ET.fromstring(tree).iter():
        model, subtask = el.get("model_name"), el.get("subtask_name")
        if model is None or subtask is None:
            continue
        model, subtask = port(model), port(subtask)
        if not model or not subtask:
            continue
        names = [f"/{model}/{subtask}"]
        spec = SUBTASKS.get(subtask)
        if spec is not None and spec.downstream != "service":
            names.append(f"/{model}/{spec.planning_action}")
        actions += [n for n in names if n not in actions]
    return actions


@dataclass
class Sample:
    t: float
    values: dict[str, float]


def _stats(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    ordered = sorted(values)
    return {
        "n": len(values),
        "mean": round(statistics.fmean(values), 4),
        "median": round(statistics.median(values), 4),
        "p95": round(ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))], 4),
        "max": round(ordered[-1], 4),
    }


def _rms(values: list[float]) -> float | None:
    return round(math.sqrt(sum(v * v for v in values) / len(values)), 4) if values else None


@dataclass
class _Episodes:
    """Counts episodes of increase of one volume (see the module docstring)."""

    threshold: float
    gap_s: float
    _last: float | None = None
    _start_value: float = 0.0
    _last_rise: float | None = None
    _counted: bool = False

    def update(self, t: float, value: float) -> bool:
        """Feed a sample; True when it completes a new episode (total rise > threshold)."""
        if self._last is None:
            self._last = value
            return False
        rising = value > self._last + 1e-9
        if self._last_rise is not None and t - self._last_rise > self.gap_s:
            self._last_rise = None  # episode over
        if rising and self._last_rise is None:
            self._start_value, self._counted = self._last, False
        if rising:
            self._last_rise = t
        self._last = value
        if self._last_rise is not None and not self._counted and value - self._start_value > self.threshold:
            self._counted = True
            return True
        return False


class AlignedError:
    """Distance between estimates and the truth *at each estimate's own stamp* (truth interpolated).

    Pairing an estimate with whatever truth sample came last adds the speed times the difference in
    delivery delay to the error: in a fast swing (about 6 m/s at the bucket tip) 0.1 s of difference read as
    0.6 m. Here truth samples ``(t, x, y)`` are kept for ``horizon_s``; an estimate stamped inside the
    kept span is compared with the truth interpolated linearly at its stamp; one stamped after the
    newest truth waits (at most ``horizon_s``) for the truth of its time; one older than the kept truth, or
    between two truth samples more than ``max_gap_s`` apart, is counted in ``unmatched``. Errors are appended
    to ``errors``.
    """

    def __init__(self, errors: list[float], *, horizon_s: float = 2.0, max_gap_s: float = 0.25) -> None:
        from collections import deque

        self.errors = errors
        self.unmatched = 0
        self.horizon_s = horizon_s
        self.max_gap_s = max_gap_s
        self._truth: deque[tuple[float, float, float]] = deque()
        self._waiting: deque[tuple[float, float, float]] = deque()

    def truth(self, t: float, x: float, y: float) -> None:
        if self._truth and t <= self._truth[-1][0]:
            if t < self._truth[-1][0] - self.horizon_s:  # time went back (a new run): start over
                self._truth.clear()
            else:
                return  # out of order or repeated: the kept series stays monotonic
        self._truth.append((t, x, y))
        while self._waiting and self._waiting[0][0] <= t:
            self._compare(*self._waiting.popleft())
        while len(self._truth) > 2 and self._truth[1][0] < t - self.horizon_s:
            self._truth.popleft()

    def estimate(self, t: float, x: float, y: float) -> None:
        if self._truth and t <= self._truth[-1][0]:
            self._compare(t, x, y)
            return
        self._waiting.append((t, x, y))
        while self._waiting and self._waiting[0][0] < t - self.horizon_s:  # its truth never came
            self._waiting.popleft()
            self.unmatched += 1

    def _compare(self, t: float, x: float, y: float) -> None:
        import bisect

        series = self._truth
        i = bisect.bisect_left(series, (t, -math.inf, -math.inf))
        if i < len(series) and series[i][0] == t:
            tx, ty = series[i][1], series[i][2]
        elif 0 < i < len(series) and series[i][0] - series[i - 1][0] <= self.max_gap_s:
            (t0, x0, y0), (t1, x1, y1) = series[i - 1], series[i]
            w = (t - t0) / (t1 - t0)
            tx, ty = x0 + w * (x1 - x0), y0 + w * (y1 - y0)
        else:
            self.unmatched += 1
            return
        self.errors.append(math.hypot(x - tx, y - ty))


#: the leaf whose start begins a load pass (``LeafNodeZx200 'excavate'``: a name with this word)
_PASS_LEAF = "excavate"
#: the chambers :meth:`ExperimentRecorder.report` plots, per cylinder: (bottom, rod)
_CYLINDERS = (("boom_bottom", "boom_rod"), ("arm_bottom", "arm_rod"), ("bucket_bottom", "bucket_rod"))


@dataclass
class _PassTrace:
    """One excavator's hydraulics samples: the pass going on and the one complete pass kept (module docstring).

    A pass longer than ``max_samples`` samples is halved in rate (every other sample dropped) each time it fills."""

    max_samples: int = 4000
    labels: tuple[str, ...] = ()
    start: float | None = None
    current: list[tuple[float, tuple[float, ...]]] = field(default_factory=list)
    #: (start, end, samples, without a dump) of the pass kept
    kept: tuple[float, float, list[tuple[float, tuple[float, ...]]], bool] | None = None
    received: int = 0

    def sample(self, t: float, labels: tuple[str, ...], values: tuple[float, ...]) -> None:
        self.received += 1
        if labels != self.labels:  # another layout (a restarted plant): the samples so far do not compare
            self.labels, self.current, self.kept = labels, [], None
        if self.start is None or t < self.start:
            return  # before the first pass
        self.current.append((t, values))
        if len(self.current) > self.max_samples:
            self.current = self.current[::2]

    def boundary(self, t: float, clean: bool) -> None:
        """A pass starts at ``t``; the one before it ends there (``clean``: no dump during it)."""
        if self.start is not None and self.current and (self.kept is None or clean or not self.kept[3]):
            self.kept = (self.start, t, self.current, clean)
        self.start, self.current = t, []


@dataclass
class ExperimentRecorder:
    """Accumulates one run. All times are simulated seconds; volumes m^3; distances m."""

    pass_threshold: float = 0.05
    episode_gap_s: float = 3.0
    soil: list[Sample] = field(default_factory=list)
    paths: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    loc_errors: list[float] = field(default_factory=list)
    tip_errors: list[float] = field(default_factory=list)
    flags: dict[str, list[tuple[float, Any]]] = field(default_factory=dict)
    task_states: dict[int, list[tuple[float, str]]] = field(default_factory=dict)
    leaf_times: dict[int, dict[str, list[float]]] = field(default_factory=dict)
    pass_times: list[float] = field(default_factory=list)
    cycle_times: list[float] = field(default_factory=list)
    pass_events: list[float] = field(default_factory=list)
    dump_events: list[float] = field(default_factory=list)
    wall_start: float | None = None
    wall_end: float | None = None
    sim_start: float | None = None
    sim_end: float | None = None
    initial_mound: float | None = None
    #: how the run ended: "done" (the tasks ended), "timeout", or "stopped" (SIGINT/SIGTERM before the end)
    ended: str = "done"
    _passes: _Episodes | None = None
    _dumps: _Episodes | None = None
    _aligned: dict[str, AlignedError] = field(default_factory=dict)
    _leaf_starts: dict[int, dict[str, float]] = field(default_factory=dict)
    #: the carriers whose soil comes by name (:meth:`on_carrier_soil`, the fleet); empty when the one vessel of
    #: ``on_soil`` is the load (the paper's single carrier)
    carriers: list[str] = field(default_factory=list)
    #: (x, y) of the loading point and the radius around it in which carrier distances count
    loading_point: tuple[float, float] | None = None
    near_radius: float = 12.0
    carrier_soil: dict[str, list[tuple[float, float, float, float]]] = field(default_factory=dict)
    min_carrier_distance: float = math.inf
    min_carrier_distance_at: tuple[float, str, str] | None = None
    #: task id -> machine name (for the report)
    task_machines: dict[int, str] = field(default_factory=dict)
    _last_pose: dict[str, tuple[float, float]] = field(default_factory=dict)
    #: machine name -> its first truth pose (t, x, y, yaw): where the site map draws a machine with no site pose
    first_pose: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)
    #: excavator name -> its hydraulics samples of one load pass (:meth:`on_hydraulics`)
    hydraulics: dict[str, _PassTrace] = field(default_factory=dict)

    # -- inputs -------------------------------------------------------------------------------
    def on_soil(self, t: float, mound: float, bucket: float, vessel: float, dumped: float) -> None:
        """``/sim/truth/soil``: ``vessel`` is the paper's one vessel (with carriers by name, passes come from their
        own totals: :meth:`on_carrier_soil`)."""
        self._clock(t)
        if self.initial_mound is None:
            self.initial_mound = mound
        if self._dumps is None:
            self._dumps = _Episodes(self.pass_threshold, self.episode_gap_s)
        self.soil.append(Sample(t, {"mound": mound, "bucket": bucket, "vessel": vessel, "dumped": dumped}))
        if not self.carriers:
            self._on_load(t, vessel)
        if self._dumps.update(t, dumped):
            if self.dump_events:
                self.cycle_times.append(t - self.dump_events[-1])
            self.dump_events.append(t)

    def _on_load(self, t: float, load: float) -> None:
        """A sample of the soil landed so far; an episode of rise is a load pass."""
        if self._passes is None:
            self._passes = _Episodes(self.pass_threshold, self.episode_gap_s)
        if self._passes.update(t, load):
            if self.pass_events and (not self.dump_events or self.pass_events[-1] > self.dump_events[-1]):
                self.pass_times.append(t - self.pass_events[-1])
            self.pass_events.append(t)

    def _error_series(self, key: str) -> AlignedError:
        """The aligned series of ``key``: a machine's name (its localisation) or ``tip:<name>`` (an excavator's tip)."""
        if key not in self._aligned:
            self._aligned[key] = AlignedError(self.tip_errors if key.startswith(_TIP) else self.loc_errors)
        return self._aligned[key]

    def on_truth_pose(self, t: float, machine: str, x: float, y: float, yaw: float) -> None:
        """Truth pose stamped ``t`` (the plant's simulated time)."""
        self._clock(t)
        # every machine's truth: whichever sends estimates (a travelling machine's localisation) is compared with it
        self._error_series(machine).truth(t, x, y)
        self.first_pose.setdefault(machine, (t, x, y, yaw))
        path = self.paths.setdefault(machine, [])
        if not path or math.hypot(path[-1][1] - x, path[-1][2] - y) > 0.1:
            path.append((t, x, y))
        if machine in self.carriers and self.loading_point is not None:
            self._last_pose[machine] = (x, y)
            lx, ly = self.loading_point
            near = math.hypot(x - lx, y - ly) <= self.near_radius
            for other, (ox, oy) in self._last_pose.items():
                if other == machine or not (near or math.hypot(ox - lx, oy - ly) <= self.near_radius):
                    continue
                d = math.hypot(x - ox, y - oy)
                if d < self.min_carrier_distance:
                    self.min_carrier_distance, self.min_carrier_distance_at = d, (t, *sorted((machine, other)))

    def on_carrier_soil(self, t: float, machine: str, vessel: float, loaded: float, dumped: float) -> None:
        """Carrier ``machine``'s load now and its totals landed in the vessel and dumped [m^3]."""
        series = self.carrier_soil.setdefault(machine, [])
        if not series or series[-1][1:] != (vessel, loaded, dumped):
            series.append((t, vessel, loaded, dumped))
        # every carrier's landed total together: one excavator loads one carrier at a time
        self._on_load(t, sum(s[-1][2] for s in self.carrier_soil.values()))

    def on_estimated_pose(self, t: float, machine: str, x: float, y: float) -> None:
        """Localisation estimate stamped ``t``; compared with the truth at ``t`` (:class:`AlignedError`)."""
        self._error_series(machine).estimate(t, x, y)

    def on_truth_tip(self, t: float, x: float, y: float, machine: str = "") -> None:
        """Excavator ``machine``'s bucket tip, true position (map frame, horizontal) stamped ``t``."""
        self._error_series(_TIP + machine).truth(t, x, y)

    def on_estimated_tip(self, t: float, x: float, y: float, machine: str = "") -> None:
        """Excavator ``machine``'s bucket tip from its measured joint angles stamped ``t``; compared with its
        truth at ``t``. Every excavator's errors go into one ``end_effector_error_m``."""
        self._error_series(_TIP + machine).estimate(t, x, y)

    def on_hydraulics(self, t: float, machine: str, values: dict[str, float]) -> None:
        """Excavator ``machine``'s chamber, pump and relief pressures [MPa] at ``t`` (labels as the plant names them:
        ``boom_bottom``, ``boom_rod``, ..., ``pump``, ``relief``)."""
        self.hydraulics.setdefault(machine, _PassTrace()).sample(t, tuple(values), tuple(values.values()))

    def _pass_boundary(self, t: float, task_id: int) -> None:
        """An ``excavate`` leaf of task ``task_id`` started: a load pass of its machine (every excavator traced when
        the task's machine is not known) begins."""
        machine = self.task_machines.get(task_id)
        if machine in self.hydraulics:
            traces = [self.hydraulics[machine]]
        else:  # a task named otherwise than the plant's machine: every trace; the task's own may not have come yet
            traces = list(self.hydraulics.values()) + ([self.hydraulics.setdefault(machine, _PassTrace())]
                                                       if machine else [])
        for trace in traces:
            clean = trace.start is None or not any(trace.start <= d <= t for d in self.dump_events)
            trace.boundary(t, clean)

    def on_flags(self, t: float, flags: dict[str, Any]) -> None:
        for key, value in flags.items():
            series = self.flags.setdefault(key, [])
            if not series or series[-1][1] != value:
                series.append((t, value))

    def on_task_state(self, t: float, task_id: int, state: str) -> None:
        series = self.task_states.setdefault(task_id, [])
        if not series or series[-1][1] != state:
            series.append((t, state))

    def on_running_leaves(self, t: float, task_id: int, leaves: list[str]) -> None:
        """The leaves task ``task_id`` is running at ``t``; a leaf's time runs from its first to its last report."""
        leaves = [leaf.split(" (task ")[0] for leaf in leaves]  # drop the XML position tms_ts appends
        starts = self._leaf_starts.setdefault(task_id, {})
        for name in [n for n in starts if n not in leaves]:
            self.leaf_times.setdefault(task_id, {}).setdefault(name, []).append(t - starts.pop(name))
        for name in leaves:
            if name not in starts and _PASS_LEAF in name:
                self._pass_boundary(t, task_id)
            starts.setdefault(name, t)

    def _clock(self, t: float) -> None:
        if self.sim_start is None:
            self.sim_start = t
        self.sim_end = t

    # -- derived ------------------------------------------------------------------------------
    @property
    def cycles(self) -> int:
        return len(self.dump_events)

    def soil_moved(self) -> float:
        if not self.soil:
            return 0.0
        return round(self.soil[-1].values["dumped"] - self.soil[0].values["dumped"], 4)

    def metrics(self) -> dict[str, Any]:
        sim = (self.sim_end or 0.0) - (self.sim_start or 0.0)
        wall = (self.wall_end or 0.0) - (self.wall_start or 0.0)
        last = self.soil[-1].values if self.soil else {}
        return {
            "ended": self.ended,
            "cycles": self.cycles,
            "soil_moved_m3": self.soil_moved(),
            "mound_initial_m3": self.initial_mound,
            "mound_final_m3": last.get("mound"),
            "load_passes": len(self.pass_events),
            "load_pass_time_s": _stats(self.pass_times),
            "haul_cycle_time_s": _stats(self.cycle_times),
            "sim_time_s": round(sim, 2),
            "wall_time_s": round(wall, 2),
            "real_time_factor": round(sim / wall, 2) if wall > 0 else None,
            "localisation_error_m": {"rms": _rms(self.loc_errors), **(_stats(self.loc_errors) or {}),
                                     "unmatched": sum(self._unmatched(k) for k in self._aligned
                                                      if not k.startswith(_TIP))},
            "end_effector_error_m": {"rms": _rms(self.tip_errors), **(_stats(self.tip_errors) or {}),
                                     "unmatched": sum(self._unmatched(k) for k in self._aligned if k.startswith(_TIP))},
            "flags_timeline": {k: [[round(t, 2), v] for t, v in series] for k, series in self.flags.items()},
            "task_states": {str(k): [[round(t, 2), s] for t, s in v] for k, v in self.task_states.items()},
            "leaf_time_s": {
                str(k): {name: _stats(times) for name, times in sorted(v.items())} for k, v in self.leaf_times.items()
            },
            "pass_events_s": [round(t, 2) for t in self.pass_events],
            "dump_events_s": [round(t, 2) for t in self.dump_events],
            "task_end_states": {str(k): v[-1][1] for k, v in self.task_states.items() if v},
            "hydraulics_pass": self._hydraulics_metrics(),
            **self._fleet_metrics(),
        }

    def _fleet_metrics(self) -> dict[str, Any]:
        if not self.carriers:
            return {}
        per: dict[str, Any] = {}
        for name in self.carriers:
            series = self.carrier_soil.get(name, [])
            first, last = (series[0], series[-1]) if series else ((0.0, 0.0, 0.0, 0.0),) * 2
            per[name] = {"soil_moved_m3": round(last[3] - first[3], 4), "loaded_m3": round(last[2] - first[2], 4),
                         "in_vessel_m3": round(last[1], 4)}
        at = self.min_carrier_distance_at
        return {
            "carriers": per,
            "tasks": {str(k): {"machine": m, "state": (self.task_states.get(k) or [(0.0, None)])[-1][1]}
                      for k, m in sorted(self.task_machines.items())},
            "min_carrier_distance_near_loading_point_m": (
                round(self.min_carrier_distance, 3) if math.isfinite(self.min_carrier_distance) else None),
            "min_carrier_distance_at": {"t": round(at[0], 2), "carriers": list(at[1:])} if at else None,
            "near_radius_m": self.near_radius,
        }

    def hydraulics_pass(self) -> tuple[str, float, float, list[tuple[float, dict[str, float]]], bool] | None:
        """The load pass whose pressures the report plots: (machine, start, end, samples as label -> MPa, complete);
        the kept complete pass of the first excavator that has one, else the pass going on when the run ended; None
        when no hydraulics sample came in a pass."""
        for machine, trace in sorted(self.hydraulics.items()):
            if trace.kept is not None:
                start, end, samples, _clean = trace.kept
                return machine, start, end, [(t, dict(zip(trace.labels, v, strict=True))) for t, v in samples], True
        for machine, trace in sorted(self.hydraulics.items()):
            if trace.start is not None and trace.current:
                samples = [(t, dict(zip(trace.labels, v, strict=True))) for t, v in trace.current]
                return machine, trace.start, samples[-1][0], samples, False
        return None

    def _hydraulics_metrics(self) -> dict[str, Any] | None:
        chosen = self.hydraulics_pass()
        if chosen is None:
            return None
        machine, start, end, samples, complete = chosen
        labels = list(samples[0][1])
        return {"machine": machine, "start_s": round(start, 2), "end_s": round(end, 2), "complete": complete,
                "samples": len(samples),
                "max_mpa": {k: round(max(v[k] for _, v in samples), 2) for k in labels}}

    def _hydraulics_note(self) -> str:
        """Why the report has no hydraulics figure."""
        received = sum(trace.received for trace in self.hydraulics.values())
        if not received:
            return ("No hydraulics samples arrived (/sim/truth/&lt;excavator&gt;/hydraulics: a plant without it, or "
                    "no digging excavator): no pressure plot.")
        return f"{received} hydraulics sample(s) arrived but no load pass (an excavate leaf) started: no pressure plot."

    def _plot_hydraulics(self, path: Path, plt) -> bool:
        """The boom, arm and bucket bottom and rod pressures of one load pass against time; False when none came."""
        chosen = self.hydraulics_pass()
        if chosen is None:
            return False
        machine, start, end, samples, complete = chosen
        fig, ax = plt.subplots(figsize=(8, 4))
        ts = [t - start for t, _ in samples]
        for (bottom, rod), color in zip(_CYLINDERS, ("tab:blue", "tab:orange", "tab:green"), strict=True):
            if bottom in samples[0][1]:
                ax.plot(ts, [v[bottom] for _, v in samples], color=color, label=bottom)
            if rod in samples[0][1]:
                ax.plot(ts, [v[rod] for _, v in samples], color=color, ls="--", label=rod)
        if "relief" in samples[0][1]:
            ax.axhline(samples[-1][1]["relief"], color="red", lw=0.8, label="relief")
        ax.set_xlabel(f"time from the pass start (simulated {start:.1f} s) [s]")
        ax.set_ylabel("pressure [MPa]")
        ax.set_title(f"{machine}: cylinder pressures of one load pass, {start:.1f}-{end:.1f} s"
                     + ("" if complete else " (incomplete: the run ended in it)"))
        ax.legend(loc="best", fontsize=7, ncol=2)
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        return True

    def _unmatched(self, key: str) -> int:
        return self._aligned[key].unmatched if key in self._aligned else 0

    # -- report -------------------------------------------------------------------------------
    def report(
        self,
        directory: Path,
        *,
        site: Site | None = None,
        machines: list[Machine] | None = None,
        loading_point: str = "P1",
        title: str = "Earthwork run",
    ) -> Path:
        """Write metrics.json, the PNG plots and index.html into ``directory``; returns index.html.

        ``site`` defaults to config/site.yaml; ``machines`` (the descriptions the site map draws) to those of the
        machines recorded (a path), as named on the site.
        """
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        directory.mkdir(parents=True, exist_ok=True)
        metrics = self.metrics()
        (directory / "metrics.json").write_text(json.dumps(metrics, indent=2))

        site = site or load_site()
        if machines is None:
            machines = [load_named(name, site=site) for name in self.paths if name in site.machines]
        render_site_map(directory / "site_map.png", site, machines=machines, paths=self.paths,
                        loading_point=loading_point)

        fig, ax = plt.subplots(figsize=(8, 4))
        if self.soil:
            ts = [s.t for s in self.soil]
            for key in ("mound", "vessel", "dumped", "bucket"):
                ax.plot(ts, [s.values[key] for s in self.soil], label=key)
        for t in self.dump_events:
            ax.axvline(t, color="grey", lw=0.5)
        ax.set_xlabel("simulated time [s]")
        ax.set_ylabel("volume [m^3]")
        ax.set_title("Mound volume, vessel load and dumped soil")
        ax.legend(loc="best")
        fig.savefig(directory / "soil.png", dpi=90)
        plt.close(fig)

        fig, ax = plt.subplots(figsize=(8, max(2.5, 0.45 * len(self.flags) + 1)))
        end = self.sim_end or 0.0
        for row, (_key, series) in enumerate(sorted(self.flags.items())):
            for i, (t, value) in enumerate(series):
                t_next = series[i + 1][0] if i + 1 < len(series) else end
                if value is True:
                    ax.barh(row, t_next - t, left=t, color="tab:green")
                elif value is not False:
                    ax.text(t, row, str(value), fontsize=7, va="center")
        ax.set_yticks(range(len(self.flags)))
        ax.set_yticklabels(sorted(self.flags))
        ax.set_xlabel("simulated time [s]")
        ax.set_title("Global-blackboard flags (green = true)")
        fig.tight_layout()
        fig.savefig(directory / "flags.png", dpi=90)
        plt.close(fig)

        if self._plot_hydraulics(directory / "hydraulics.png", plt):
            hydraulics = '<img src="hydraulics.png" alt="cylinder pressures of one load pass">'
        else:
            (directory / "hydraulics.png").unlink(missing_ok=True)  # a report rewritten into the same directory
            hydraulics = f"<p>{self._hydraulics_note()}</p>"

        rows = "".join(
            f"<tr><th>{k}</th><td>{json.dumps(v)}</td></tr>"
            for k, v in metrics.items()
            if k not in ("flags_timeline", "task_states", "pass_events_s", "dump_events_s")
        )
        # a recording of the run (tms-launch --record <dir>/bag) is closed after this report; its replay page is
        # written then (tms_ur.replay_page, scripts/demo.sh)
        replay = ('<p><a href="replay.html">Replay</a> of the recording <a href="bag/">bag/</a> (rosbag2, MCAP)</p>\n'
                  if (directory / "bag").is_dir() else "")
        html = f"""<!doctype html><html><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:1em auto}} \
td,th{{text-align:left;padding:2px 8px;border-bottom:1px solid #ddd}}
img{{max-width:100%;border:1px solid #ccc;margin:4px 0}}</style></head><body>
<h1>{title}</h1><table>{rows}</table>
<p><a href="metrics.json">metrics.json</a> (full timelines)</p>
{replay}<h2>Site map</h2><img src="site_map.png" alt="site map">
<h2>Soil</h2><img src="soil.png" alt="soil volumes">
<h2>Flags</h2><img src="flags.png" alt="flag timeline">
<h2>Hydraulics of one load pass</h2>{hydraulics}
</body></html>"""
        index = directory / "index.html"
        index.write_text(html)
        return index
