// Live view and controls of the TMS web panel. No framework: one websocket, two canvases.
"use strict";
const token = new URLSearchParams(location.search).get("token");
document.getElementById("link-3d").href = "/3d" + (token ? `?token=${encodeURIComponent(token)}` : "");
let ws = null;
let last = null;
const picked = new Set();

function connect() {
  const url = `ws://${location.host}/ws` + (token ? `?token=${encodeURIComponent(token)}` : "");
  ws = new WebSocket(url);
  ws.onopen = () => { setConn(true); };
  ws.onclose = () => { setConn(false); setTimeout(connect, 1000); };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "state") { last = msg; render(msg); }
    // acks are also logged by the server and arrive with the next snapshot; a refusal (bad origin, missing
    // token) is logged there once per connection, so each one is also shown here
    else if (msg.type === "ack" && !msg.ok) { console.warn(msg.text); if (msg.refused) addEvent("error", msg.text); }
  };
}
function setConn(ok) { const c = document.getElementById("conn"); c.textContent = ok ? "live" : "disconnected"; c.className = ok ? "ok" : "bad"; }
function send(cmd) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(cmd)); else addEvent("error", "not connected"); }
const localEvents = [];
function addEvent(level, text) { localEvents.push({ level, text }); if (last) render(last); }

function emergency() { send({ op: "emergency" }); }
document.getElementById("estop").onclick = emergency;
document.addEventListener("keydown", (e) => { if (e.key === "Escape") { e.preventDefault(); emergency(); } });
document.getElementById("start").onclick = () => {
  const ids = document.getElementById("task-ids").value.split(/[\s,]+/).filter(Boolean).map(Number);
  send({ op: "start", task_ids: ids });
};
document.getElementById("confirm").onclick = () => send({ op: "confirm" });

function el(tag, attrs = {}, text = "") { const e = document.createElement(tag); Object.assign(e, attrs); if (text !== "") e.textContent = text; return e; }

function render(s) {
  const cat = document.querySelector("#catalogue tbody"); cat.replaceChildren();
  for (const t of s.catalogue) {
    // The table is rebuilt on every snapshot: the selection lives in `picked`, not in the DOM.
    const tr = el("tr"); const cb = el("input", { type: "checkbox", value: t.task_id, className: "pick", checked: picked.has(t.task_id) });
    cb.onchange = () => {
      if (cb.checked) picked.add(t.task_id); else picked.delete(t.task_id);
      document.getElementById("task-ids").value = [...picked].sort((a, b) => a - b).join(" ");
    };
    const td0 = el("td"); td0.append(cb);
    tr.append(td0, el("td", {}, String(t.task_id)), el("td", {}, t.model_name), el("td", {}, t.description)); cat.append(tr);
  }
  const tb = document.querySelector("#tasks tbody"); tb.replaceChildren();
  for (const t of s.tasks) {
    const tr = el("tr", { id: `task-${t.task_id}` });
    const cancel = el("button", {}, "Cancel"); cancel.onclick = () => send({ op: "cancel", task_id: t.task_id });
    const td = el("td"); td.append(cancel);
    tr.append(el("td", {}, String(t.task_id)), el("td", { className: `state state-${t.state}` }, t.state),
      el("td", {}, t.running.join(", ") + (t.message ? ` — ${t.message}` : "")), td);
    tb.append(tr);
  }
  const flags = document.getElementById("flags"); flags.replaceChildren();
  for (const [rec, fields] of Object.entries(s.flags)) {
    const div = el("div"); div.append(el("b", {}, rec + ": "));
    for (const [k, v] of Object.entries(fields)) div.append(el("span", { className: `flag ${v}` }, `${k}=${v}`));
    flags.append(div);
  }
  const ev = document.getElementById("events"); ev.replaceChildren();
  for (const e of [...s.events, ...localEvents].slice(-25).reverse()) ev.append(el("li", { className: e.level }, e.text));
  const poses = document.querySelector("#poses tbody"); poses.replaceChildren();
  for (const [m, p] of Object.entries(s.poses)) {
    const tr = el("tr", { id: `pose-${m}` });
    tr.append(el("td", {}, m), el("td", { className: "x" }, p.x.toFixed(2)), el("td", { className: "y" }, p.y.toFixed(2)), el("td", {}, p.yaw.toFixed(2)));
    poses.append(tr);
  }
  // each machine's state after its type (the server says which machines there are and of what type)
  const state = document.getElementById("arm-state"); state.replaceChildren();
  const deg = (a) => (a === null || a === undefined ? "-" : `${a.toFixed(2)} rad`);
  for (const m of s.machines) {
    let text = "";
    const arm = s.arms[m.name], vessel = s.vessels[m.name], blade = s.blades[m.name];
    if (arm && arm.side.length) {
      const tip = arm.side[arm.side.length - 1];
      text = `${m.name} swing ${arm.swing.toFixed(2)} rad, bucket tip ${tip[0].toFixed(1)} m out, ${tip[1].toFixed(1)} m high`;
    } else if (vessel) {
      text = `${m.name} vessel ${deg(vessel.angle)}` + ("swing" in vessel ? `, upper body ${deg(vessel.swing)}` : "")
        + (vessel.load !== undefined ? `, load ${vessel.load.toFixed(2)} m3` : "");
    } else if (blade) {
      text = `${m.name} blade lift ${deg(blade.lift)}`;
    }
    if (text) state.append(el("div", { id: `state-${m.name}`, className: "machine-state" }, text));
  }
  const soil = document.getElementById("soil"); soil.replaceChildren();
  for (const [k, v] of Object.entries(s.soil)) soil.append(el("div", { className: "soil" }, `${k}: ${v.toFixed(2)}`));
  drawMap(s); drawArm(s);
}

function drawMap(s) {
  const c = document.getElementById("map"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const pts = [];
  for (const tr of Object.values(s.trails)) pts.push(...tr);
  for (const p of Object.values(s.poses)) pts.push([p.x, p.y]);
  for (const plan of Object.values(s.plans)) pts.push(...plan);
  if (!pts.length) { g.fillText("waiting for machine poses", 20, 20); return; }
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of pts) { x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y); }
  const pad = 10, span = Math.max(x1 - x0, y1 - y0, 20) + 2 * pad;
  const k = Math.min(c.width, c.height) / span;
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  const X = (x) => c.width / 2 + (x - cx) * k, Y = (y) => c.height / 2 - (y - cy) * k;
  g.strokeStyle = "#eee"; g.lineWidth = 1;
  for (let gx = Math.floor((cx - span) / 10) * 10; gx < cx + span; gx += 10) { g.beginPath(); g.moveTo(X(gx), 0); g.lineTo(X(gx), c.height); g.stroke(); }
  for (let gy = Math.floor((cy - span) / 10) * 10; gy < cy + span; gy += 10) { g.beginPath(); g.moveTo(0, Y(gy)); g.lineTo(c.width, Y(gy)); g.stroke(); }
  const line = (p, color, w) => { if (p.length < 2) return; g.strokeStyle = color; g.lineWidth = w; g.beginPath(); g.moveTo(X(p[0][0]), Y(p[0][1])); for (const q of p) g.lineTo(X(q[0]), Y(q[1])); g.stroke(); };
  const colors = machineColors(s);
  for (const [m, tr] of Object.entries(s.trails)) line(tr, colors[m] || "#555", 1.5);
  g.setLineDash([6, 4]); for (const [m, plan] of Object.entries(s.plans)) line(plan, colors[m] || "#0a0", 2); g.setLineDash([]);
  const info = Object.fromEntries(s.machines.map((m) => [m.name, m]));
  for (const [m, p] of Object.entries(s.poses)) {
    const [L, W] = info[m] ? [info[m].length, info[m].width] : [3, 2];
    g.save(); g.translate(X(p.x), Y(p.y)); g.rotate(-p.yaw);
    g.fillStyle = colors[m] || "#555"; g.globalAlpha = 0.8; g.fillRect(-L / 2 * k, -W / 2 * k, L * k, W * k);
    g.globalAlpha = 1; g.strokeStyle = "#000"; g.beginPath(); g.moveTo(0, 0); g.lineTo(L / 2 * k, 0); g.stroke();
    const arm = s.arms[m];
    if (arm) { // an excavator: its front, swung, as far out as the bucket tip
      g.rotate(-arm.swing); g.strokeStyle = colors[m] || "#555"; g.lineWidth = 3; g.beginPath(); g.moveTo(0, 0);
      const reach = arm.side.length ? arm.side[arm.side.length - 1][0] : 6; g.lineTo(reach * k, 0); g.stroke(); }
    g.restore();
    g.fillStyle = "#000"; g.fillText(`${m} (${p.x.toFixed(1)}, ${p.y.toFixed(1)})`, X(p.x) + 8, Y(p.y) - 8);
  }
}

// colours by the order of the machines the server sends (excavators first): tms_ur.site_map.PALETTE
const PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#ffd700", "#000080"];
function machineColors(s) { return Object.fromEntries(s.machines.map((m, i) => [m.name, PALETTE[i % PALETTE.length]])); }

function drawArm(s) {
  const c = document.getElementById("arm"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const arms = Object.entries(s.arms).filter(([, a]) => a.side.length);
  g.fillStyle = "#000"; g.fillText(arms.length ? `arm side view: ${arms.map(([m]) => m).join(", ")}` : "arm side view", 6, 12);
  if (!arms.length) return;
  const colors = machineColors(s);
  const k = 14, ox = 30, oy = c.height - 60;
  g.strokeStyle = "#888"; g.lineWidth = 1; g.beginPath(); g.moveTo(0, oy); g.lineTo(c.width, oy); g.stroke();
  for (const [m, arm] of arms) {
    g.strokeStyle = colors[m] || "#555"; g.lineWidth = 4; g.beginPath(); g.moveTo(ox, oy);
    for (const [r, z] of arm.side) g.lineTo(ox + r * k, oy - z * k);
    g.stroke();
  }
}
connect();
