"""The report's hydraulics figure: one load pass's cylinder pressures, from ``excavate`` leaf start to the next, kept
in bounded memory, and a note instead of the figure when no hydraulics came (an older plant, no digging excavator)."""

from __future__ import annotations

import json
import math

import matplotlib.image as mpimg

from tms_ur.experiment_core import ExperimentRecorder

LABELS = ("boom_bottom", "boom_rod", "arm_bottom", "arm_rod", "bucket_bottom", "bucket_rod", "swing_a", "swing_b",
          "pump", "relief")
EXCAVATE = "LeafNodeZx200 'excavate'"
CARRY = "LeafNodeZx200 'carry_over_vessel'"


def _pressures(t: float, pass_no: int) -> dict[str, float]:
    """Synthetic pressures [MPa]: the boom bottom peaks at 20 + pass_no in the middle of each 20 s pass."""
    phase = (t % 20.0) / 20.0
    boom = 6.0 + (14.0 + pass_no) * math.sin(math.pi * phase)
    return dict(zip(LABELS, (boom, 0.3, 8.0, 2.0, 5.0, 1.0, 0.3, 0.3, boom + 2.0, 34.3), strict=True))


def _run(rec: ExperimentRecorder, passes: int) -> None:
    """Task 2 (zx200) excavates every 20 s from t = 10 s, carries in between; hydraulics at 20 Hz throughout."""
    rec.task_machines[2] = "zx200"
    t = 0.0
    while t < 10.0 + 20.0 * passes + 5.0:
        k = int((t - 10.0) // 20.0) if t >= 10.0 else -1
        in_pass = (t - 10.0) % 20.0 if t >= 10.0 else -1.0
        if k < passes:
            rec.on_running_leaves(t, 2, [] if k < 0 else [EXCAVATE] if in_pass < 8.0 else [CARRY])
        rec.on_hydraulics(t, "zx200", _pressures(t, max(k, 0)))
        t = round(t + 0.05, 6)


def test_the_report_plots_the_last_complete_pass_and_links_it(tmp_path):
    rec = ExperimentRecorder()
    _run(rec, passes=4)
    machine, start, end, samples, complete = rec.hydraulics_pass()
    # four excavate starts (10, 30, 50, 70 s): the last complete pass is the third, 50-70 s
    assert (machine, start, end, complete) == ("zx200", 50.0, 70.0, True)
    assert samples[0][0] == 50.0 and samples[-1][0] < 70.0 and len(samples) == 400
    assert max(v["boom_bottom"] for _, v in samples) == 6.0 + 14.0 + 2  # the third pass (pass_no 2)
    index = rec.report(tmp_path)
    png = tmp_path / "hydraulics.png"
    assert png.stat().st_size > 5000
    height, width = mpimg.imread(png).shape[:2]
    assert (width, height) == (720, 360)  # 8 x 4 in at 90 dpi
    html = index.read_text()
    assert '<img src="hydraulics.png"' in html and "No hydraulics samples" not in html
    metrics = json.loads((tmp_path / "metrics.json").read_text())["hydraulics_pass"]
    assert metrics["start_s"] == 50.0 and metrics["end_s"] == 70.0 and metrics["samples"] == 400
    assert metrics["max_mpa"]["relief"] == 34.3


def test_a_pass_with_a_dump_in_it_does_not_replace_a_clean_one():
    # the last complete pass had the carrier's haul (a dump) in it: the pass before stays the one plotted
    rec2 = ExperimentRecorder()
    rec2.dump_events.append(-1.0)  # a dump long before does not count
    rec2.task_machines[2] = "zx200"
    for t10 in range(0, 1000):  # 0-100 s at 10 Hz: excavates at 10 and 30 s, a dump at 40 s, excavate at 50 s...
        t = round(t10 * 0.1, 6)
        if t >= 10.0 and abs((t - 10.0) % 20.0) < 1e-6:
            rec2.on_running_leaves(t, 2, [EXCAVATE])
        elif t >= 10.0 and abs((t - 10.0) % 20.0 - 8.0) < 1e-6:
            rec2.on_running_leaves(t, 2, [CARRY])
        if abs(t - 40.0) < 1e-6:
            rec2.dump_events.append(t)
        rec2.on_hydraulics(t, "zx200", _pressures(t, 0))
    # passes: 10-30 (clean), 30-50 (dump at 40), 50-70 (clean), 70-90 (clean), 90- (going on)
    assert rec2.hydraulics_pass()[1:3] == (70.0, 90.0)
    rec3 = ExperimentRecorder()
    rec3.task_machines[2] = "zx200"
    for t10 in range(0, 600):
        t = round(t10 * 0.1, 6)
        if t in (10.0, 30.0, 50.0):
            rec3.on_running_leaves(t, 2, [EXCAVATE])
        elif t in (18.0, 38.0):
            rec3.on_running_leaves(t, 2, [CARRY])
        if t == 40.0:
            rec3.dump_events.append(t)
        rec3.on_hydraulics(t, "zx200", _pressures(t, 0))
    assert rec3.hydraulics_pass()[1:3] == (10.0, 30.0)  # 30-50 had the dump: 10-30 is kept


def test_memory_stays_bounded_over_a_long_pass():
    rec = ExperimentRecorder()
    rec.task_machines[2] = "zx200"
    rec.on_running_leaves(0.0, 2, [EXCAVATE])
    for i in range(50_000):  # 2500 s of one pass at 20 Hz (a long wait for the carrier)
        rec.on_hydraulics(i * 0.05, "zx200", _pressures(i * 0.05, 0))
    trace = rec.hydraulics["zx200"]
    assert len(trace.current) <= trace.max_samples
    assert trace.current[0][0] == 0.0 and trace.current[-1][0] > 2400.0  # the whole span, at a lower rate
    machine, start, _end, _samples, complete = rec.hydraulics_pass()
    assert (machine, start, complete) == ("zx200", 0.0, False)


def test_without_hydraulics_the_report_has_a_note_and_no_figure(tmp_path):
    rec = ExperimentRecorder()
    rec.on_running_leaves(10.0, 2, [EXCAVATE])
    rec.on_running_leaves(18.0, 2, [CARRY])
    rec.on_running_leaves(30.0, 2, [EXCAVATE])
    (tmp_path / "hydraulics.png").write_bytes(b"an earlier report's")
    index = rec.report(tmp_path)
    html = index.read_text()
    assert not (tmp_path / "hydraulics.png").exists()
    assert "hydraulics.png" not in html
    assert "No hydraulics samples arrived" in html
    assert json.loads((tmp_path / "metrics.json").read_text())["hydraulics_pass"] is None


def test_samples_but_no_pass_say_so(tmp_path):
    rec = ExperimentRecorder()
    for i in range(100):
        rec.on_hydraulics(i * 0.05, "zx200", _pressures(i * 0.05, 0))
    html = rec.report(tmp_path).read_text()
    assert "100 hydraulics sample(s) arrived but no load pass" in html
    assert not (tmp_path / "hydraulics.png").exists()
