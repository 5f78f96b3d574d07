"""The experiment report's replay page: ``<run dir>/replay.html`` plays the run's recording (``<run dir>/bag``).

At report time the bag is read with :func:`tms_ur.recording.read_bag` into a small timeline (each machine's true
pose, the excavators' bucket tips, the soil totals and each carrier's vessel load, at most ``rate_hz`` samples per
second and series, on the recording's log time: simulated seconds) that is embedded as JSON in one static page: a
canvas with the site's points and mound, the machines drawn where they were, and a time slider. No script from a
CDN, nothing fetched. The page exposes what it drew as ``window.replayDrawn`` (a machine's map and canvas position at
the slider's time), so a browser test reads it.

The recorder closes the bag only when the launch stops, after the supervisor wrote its report, so ``scripts/demo.sh``
writes the page once the launch has ended: ``python -m tms_ur.replay_page <run dir>``.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tms_common.errors import TmsError
from tms_model.site import Site, load_site
from tms_ur.recording import RecordingError, bag_summary, read_bag

__all__ = ["ReplayError", "main", "replay_html", "replay_timeline", "write_replay"]

_POSE = "geometry_msgs/msg/PoseStamped"
_TIP = "geometry_msgs/msg/PointStamped"
_ARRAY = "std_msgs/msg/Float64MultiArray"


class ReplayError(TmsError):
    """The replay page cannot be made; the message names the run directory or the bag."""


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _labelled(msg: Any) -> dict[str, float]:
    labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
    return dict(zip(labels, msg.data, strict=False))


def replay_timeline(bag: str | Path, rate_hz: float = 5.0) -> dict[str, Any]:
    """The replay's data from the recording ``bag``: times in s of log time, positions in m (map frame).

    ``machines``: name -> [[t, x, y, yaw], ...] from ``/sim/truth/<name>/pose``; ``tips``: name -> [[t, x, y, z]]
    from ``/sim/truth/<name>/bucket_tip``; ``soil``: [[t, {label: m^3}]] from ``/sim/truth/soil``; ``carrier_soil``:
    name -> [[t, vessel m^3]] from ``/sim/truth/<name>/soil``. A series keeps the first sample of each ``1 /
    rate_hz`` interval from the recording's start (integer nanoseconds: no rounding drift).
    """
    summary = bag_summary(bag)
    wanted = [t for t, (ty, _) in summary.items() if t.startswith("/sim/truth/") and (
        (t.endswith("/pose") and ty == _POSE) or (t.endswith("/bucket_tip") and ty == _TIP)
        or (t.endswith("/soil") and ty == _ARRAY))]
    if not any(t.endswith("/pose") for t in wanted):
        raise ReplayError(f"replay of {bag}: the recording holds no /sim/truth/<machine>/pose topic "
                          f"(topics: {sorted(summary)})")
    last: dict[str, int] = {}  # topic -> interval of its last kept sample
    out: dict[str, Any] = {"machines": {}, "tips": {}, "soil": [], "carrier_soil": {}}
    t0_ns: int | None = None
    t_end = 0.0
    for m in read_bag(bag, topics=wanted):
        t = m.log_time_ns * 1e-9
        t0_ns = m.log_time_ns if t0_ns is None else t0_ns
        t_end = t
        interval = int((m.log_time_ns - t0_ns) * rate_hz) // 1_000_000_000
        if last.get(m.topic) == interval:
            continue
        last[m.topic] = interval
        parts = m.topic.split("/")  # "", "sim", "truth", <name or soil>, <kind>
        if m.topic == "/sim/truth/soil":
            out["soil"].append([round(t, 3), {k: round(v, 4) for k, v in _labelled(m.msg).items()}])
        elif parts[-1] == "pose":
            p = m.msg.pose.position
            out["machines"].setdefault(parts[3], []).append(
                [round(t, 3), round(p.x, 3), round(p.y, 3), round(_yaw(m.msg.pose.orientation), 4)])
        elif parts[-1] == "bucket_tip":
            p = m.msg.point
            out["tips"].setdefault(parts[3], []).append([round(t, 3), round(p.x, 3), round(p.y, 3), round(p.z, 3)])
        elif parts[-1] == "soil":
            vessel = _labelled(m.msg).get("vessel")
            if vessel is not None:
                out["carrier_soil"].setdefault(parts[3], []).append([round(t, 3), round(vessel, 4)])
    out["t0"] = round((t0_ns or 0) * 1e-9, 3)
    out["t1"] = round(t_end, 3)
    return out


def replay_html(timeline: dict[str, Any], site: Site, title: str = "Replay of the recording") -> str:
    """The static replay page for ``timeline`` (:func:`replay_timeline`) over ``site``'s points and mound."""
    data = dict(timeline)
    data["points"] = {name: [p.x, p.y] for name, p in site.points.items()}
    data["mound"] = [site.mound.cx, site.mound.cy, site.mound.base_radius]
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")  # no "</script>" inside the script
    return _PAGE.replace("@TITLE@", title).replace("@DATA@", payload)


def write_replay(run_dir: str | Path, site: Site | None = None) -> Path:
    """Write ``<run_dir>/replay.html`` from ``<run_dir>/bag``; returns its path."""
    run_dir = Path(run_dir)
    bag = run_dir / "bag"
    if not bag.is_dir():
        raise ReplayError(f"replay of {run_dir}: no recording {bag} (record with tms-launch --record {bag})")
    try:
        timeline = replay_timeline(bag)
    except RecordingError as exc:
        raise ReplayError(f"replay of {run_dir}: {exc}") from exc
    page = run_dir / "replay.html"
    page.write_text(replay_html(timeline, site or load_site()), encoding="utf-8")
    return page


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        print("usage: python -m tms_ur.replay_page RUN_DIR  (writes RUN_DIR/replay.html from RUN_DIR/bag)",
              file=sys.stderr)
        return 2
    try:
        page = write_replay(args[0])
    except TmsError as exc:
        print(f"replay_page: {exc}", file=sys.stderr)
        return 2
    print(f"replay page {page}")
    return 0


_PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>@TITLE@</title>
<style>body{font-family:sans-serif;max-width:1100px;margin:1em auto}canvas{border:1px solid #ccc}
#bar{display:flex;gap:8px;align-items:center}#slider{flex:1}#soil{font-size:90%;color:#333}</style></head><body>
<h1>@TITLE@</h1><p><a href="index.html">report</a> &middot; the recording: <a href="bag/">bag/</a>
(rosbag2, MCAP: ros2 bag play, Foxglove)</p>
<div id="bar"><button id="play">play</button><input id="slider" type="range" step="0.1">
<span id="time"></span></div><canvas id="map" width="1000" height="640"></canvas><div id="soil"></div>
<script id="data" type="application/json">@DATA@</script>
<script>
"use strict";
const D = JSON.parse(document.getElementById("data").textContent);
const cv = document.getElementById("map"), ctx = cv.getContext("2d");
const slider = document.getElementById("slider");
slider.min = D.t0; slider.max = D.t1; slider.value = D.t0;
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"];
// world bounds: every sample and site point, plus a margin; one scale for x and y
let xs = [], ys = [];
for (const s of Object.values(D.machines)) for (const p of s) { xs.push(p[1]); ys.push(p[2]); }
for (const p of Object.values(D.points)) { xs.push(p[0]); ys.push(p[1]); }
xs.push(D.mound[0] - D.mound[2], D.mound[0] + D.mound[2]);
ys.push(D.mound[1] - D.mound[2], D.mound[1] + D.mound[2]);
const x0 = Math.min(...xs) - 5, x1 = Math.max(...xs) + 5, y0 = Math.min(...ys) - 5, y1 = Math.max(...ys) + 5;
const scale = Math.min(cv.width / (x1 - x0), cv.height / (y1 - y0));
const px = (x, y) => [(x - x0) * scale, cv.height - (y - y0) * scale];
function at(series, t) {  // the last sample at or before t (binary search), else the first
  if (!series || !series.length) return null;
  let lo = 0, hi = series.length - 1;
  if (series[0][0] > t) return series[0];
  while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (series[mid][0] <= t) lo = mid; else hi = mid - 1; }
  return series[lo];
}
function draw(t) {
  ctx.clearRect(0, 0, cv.width, cv.height);
  const [mx, my] = px(D.mound[0], D.mound[1]);
  ctx.fillStyle = "#e8d8b0"; ctx.beginPath(); ctx.arc(mx, my, D.mound[2] * scale, 0, 2 * Math.PI); ctx.fill();
  ctx.fillStyle = "#555"; ctx.font = "11px sans-serif";
  for (const [name, p] of Object.entries(D.points)) {
    const [a, b] = px(p[0], p[1]); ctx.fillRect(a - 2, b - 2, 4, 4); ctx.fillText(name, a + 4, b - 4);
  }
  const drawn = {t: t, machines: {}, tips: {}};
  Object.keys(D.machines).sort().forEach((name, i) => {
    const s = at(D.machines[name], t); if (!s) return;
    const [a, b] = px(s[1], s[2]);
    ctx.save(); ctx.translate(a, b); ctx.rotate(-s[3]);
    ctx.fillStyle = COLORS[i % COLORS.length]; ctx.fillRect(-3 * scale, -1.5 * scale, 6 * scale, 3 * scale);
    ctx.fillStyle = "#000"; ctx.fillRect(2 * scale, -0.5 * scale, 1.5 * scale, 1 * scale);  // heading mark
    ctx.restore();
    ctx.fillStyle = "#000"; ctx.fillText(name, a + 3 * scale + 3, b);
    drawn.machines[name] = {stamp: s[0], x: s[1], y: s[2], yaw: s[3], px: a, py: b};
  });
  for (const [name, series] of Object.entries(D.tips)) {
    const s = at(series, t); if (!s) continue;
    const [a, b] = px(s[1], s[2]);
    ctx.strokeStyle = "#000"; ctx.beginPath(); ctx.arc(a, b, 4, 0, 2 * Math.PI); ctx.stroke();
    drawn.tips[name] = {stamp: s[0], x: s[1], y: s[2], z: s[3], px: a, py: b};
  }
  const soil = at(D.soil, t);
  const loads = Object.entries(D.carrier_soil).map(([n, s]) => {
    const v = at(s, t); return v ? `${n} ${v[1].toFixed(2)}` : "";
  });
  document.getElementById("soil").textContent = (soil ? "soil [m3]: " + Object.entries(soil[1]).map(
    ([k, v]) => `${k} ${v.toFixed(2)}`).join(", ") : "") + (loads.length ? " | vessels: " + loads.join(", ") : "");
  document.getElementById("time").textContent = `t = ${(t - D.t0).toFixed(1)} s (log time ${t.toFixed(1)} s)`;
  window.replayDrawn = drawn;
}
slider.addEventListener("input", () => draw(Number(slider.value)));
let timer = null;
document.getElementById("play").addEventListener("click", () => {
  if (timer) { clearInterval(timer); timer = null; return; }
  timer = setInterval(() => {  // 10x simulated time
    const t = Math.min(Number(slider.value) + 1.0, D.t1); slider.value = t; draw(t);
    if (t >= D.t1) { clearInterval(timer); timer = null; }
  }, 100);
});
draw(D.t0);
</script></body></html>
"""

if __name__ == "__main__":
    sys.exit(main())
