// The panel's 3-D site view: terrain from the DB's heightmaps, every machine from its URDF posed from /tf (the panel
// forwards each link's pose in map), soil heaps, task labels, three cameras and WebXR. Map frame: z up.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { VRButton } from "three/examples/jsm/webxr/VRButton.js";
import { CSS2DRenderer, CSS2DObject } from "three/examples/jsm/renderers/CSS2DRenderer.js";
import URDFLoader from "urdf-loader";

THREE.Object3D.DEFAULT_UP.set(0, 0, 1);
const token = new URLSearchParams(location.search).get("token");
const q = token ? `?token=${encodeURIComponent(token)}` : "";
document.getElementById("link-2d").href = "/" + q;

const view = document.getElementById("view");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setSize(view.clientWidth, view.clientHeight);
renderer.xr.enabled = true;  // the immersive mode (VRButton below)
view.append(renderer.domElement);
const labels = new CSS2DRenderer();
labels.setSize(view.clientWidth, view.clientHeight);
labels.domElement.style.cssText = "position:absolute;top:0;left:0;pointer-events:none";
view.append(labels.domElement);
document.body.append(VRButton.createButton(renderer));

const scene = new THREE.Scene();
scene.background = new THREE.Color(0xa9c6e0);
scene.add(new THREE.HemisphereLight(0xffffff, 0x665544, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(-30, -40, 80);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(50, view.clientWidth / view.clientHeight, 0.1, 2000);
camera.position.set(0, -60, 50);
const controls = new OrbitControls(camera, renderer.domElement);

// ---- inspection object for tests and tools (read-only copies of what is drawn) ----
const machines = {};     // name -> {links: {frame: Group}, label, heap, info}
const terrain = { version: null, layers: [], meshes: [] };
const tfStamp = {};      // name -> stamp [s] of the /tf poses drawn
const tfChain = {};      // name -> {child frame: stamp [s]} of the /tf edges from its base up to map
let fps = 0, frames = 0;
window.site3d = Object.freeze({
  machineNames: () => Object.keys(machines),
  loaded: (name) => !!(machines[name] && machines[name].ready),
  links: (name) => Object.fromEntries(Object.entries(machines[name]?.links ?? {}).map(
    ([f, g]) => [f, Array.from(g.matrixWorld.elements)])),
  stamp: (name) => tfStamp[name] ?? null,
  chain: (name) => tfChain[name] ?? null,
  terrainVersion: () => terrain.version,
  terrainLayers: () => terrain.layers.map((l) => ({ kind: l.kind, id: l.id, rows: l.rows, cols: l.cols })),
  heightAt: (x, y) => heightAt(x, y),
  terrainBounds: (kind) => {
    const l = terrain.layers.find((x) => x.kind === kind);
    return l ? { x_min: l.x_min, y_min: l.y_min, x_max: l.x_max, y_max: l.y_max } : null;
  },
  label: (name) => machines[name]?.label.element.textContent ?? null,
  heap: (name) => machines[name]?.heap.visible ? machines[name].heap.scale.x : 0,
  fps: () => fps,
  frames: () => frames,
  camera: () => cameraMode.value,
});

// ---- terrain ----
function heightAt(x, y) {
  for (let i = terrain.layers.length - 1; i >= 0; i--) {  // the top layer (dynamic) first
    const l = terrain.layers[i];
    if (x < l.x_min || x > l.x_max || y < l.y_min || y > l.y_max) continue;
    const cx = (l.x_max - l.x_min) / l.cols, cy = (l.y_max - l.y_min) / l.rows;
    const c = Math.min(l.cols - 1, Math.floor((x - l.x_min) / cx));
    const r = Math.min(l.rows - 1, Math.floor((l.y_max - y) / cy));
    return l.z[r * l.cols + c];
  }
  return null;
}

function layerMesh(l, index) {
  const cx = (l.x_max - l.x_min) / l.cols, cy = (l.y_max - l.y_min) / l.rows;
  const pos = new Float32Array(l.rows * l.cols * 3), col = new Float32Array(l.rows * l.cols * 3);
  let zmin = Infinity, zmax = -Infinity;
  for (const z of l.z) { zmin = Math.min(zmin, z); zmax = Math.max(zmax, z); }
  const span = Math.max(zmax - zmin, 0.01), c = new THREE.Color();
  for (let r = 0; r < l.rows; r++) for (let k = 0; k < l.cols; k++) {
    const i = r * l.cols + k, z = l.z[i];
    pos.set([l.x_min + (k + 0.5) * cx, l.y_max - (r + 0.5) * cy, z + 0.01 * index], 3 * i);
    c.setHSL(0.09, 0.45, 0.3 + 0.35 * (z - zmin) / span);
    col.set([c.r, c.g, c.b], 3 * i);
  }
  const idx = [];
  for (let r = 0; r + 1 < l.rows; r++) for (let k = 0; k + 1 < l.cols; k++) {
    const a = r * l.cols + k, b = a + 1, d = a + l.cols, e = d + 1;
    idx.push(a, d, b, b, d, e);
  }
  const g = new THREE.BufferGeometry();
  g.setAttribute("position", new THREE.BufferAttribute(pos, 3));
  g.setAttribute("color", new THREE.BufferAttribute(col, 3));
  g.setIndex(idx);
  g.computeVertexNormals();
  return new THREE.Mesh(g, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
}

// flat ground under the heightmaps (PlaneGeometry lies in x-y: the map's ground plane), just below them
const ground = new THREE.Mesh(new THREE.PlaneGeometry(400, 400), new THREE.MeshLambertMaterial({ color: 0x9a9a86 }));
ground.position.z = -0.05;
scene.add(ground);

let terrainLoading = false;
async function loadTerrain(version) {
  if (terrainLoading || version === terrain.version) return;
  terrainLoading = true;
  try {
    const t = await (await fetch("/terrain.json" + q)).json();
    for (const m of terrain.meshes) { scene.remove(m); m.geometry.dispose(); }
    terrain.meshes = t.layers.map(layerMesh);
    for (const m of terrain.meshes) scene.add(m);
    terrain.layers = t.layers;
    terrain.version = t.version;
  } finally { terrainLoading = false; }
}

// ---- machines ----
const loader = new URDFLoader();
const palette = [0xe8a33c, 0x3c8de8, 0x6cc04a, 0xd9534f, 0x9b59b6, 0x1abc9c, 0xf1c40f, 0x7f8c8d, 0xe67e22, 0x34495e];
const machineSelect = document.getElementById("machine"), cameraMode = document.getElementById("camera");

async function addMachine(info, index) {
  const entry = { links: {}, ready: false, info };
  machines[info.name] = entry;
  const text = await (await fetch(`/urdf/${encodeURIComponent(info.name)}` + q)).text();
  const robot = loader.parse(text);
  const material = new THREE.MeshLambertMaterial({ color: palette[index % palette.length] });
  // Links are placed directly from their map poses: each link's visuals move into a group of the scene.
  for (const [frame, link] of Object.entries(robot.links)) {
    const group = new THREE.Group();
    group.visible = false;  // until /tf places it
    for (const child of [...link.children]) {
      if (!child.isURDFVisual) continue;
      child.traverse((o) => { if (o.isMesh) o.material = material; });
      group.add(child);
    }
    scene.add(group);
    entry.links[frame] = group;
  }
  const div = document.createElement("div");
  div.className = "label";
  div.textContent = info.name;
  entry.label = new CSS2DObject(div);
  scene.add(entry.label);
  entry.heap = new THREE.Mesh(new THREE.ConeGeometry(1, 0.6, 24), new THREE.MeshLambertMaterial({ color: 0x8b5a2b }));
  entry.heap.rotation.x = Math.PI / 2;  // cone axis along map z
  entry.heap.visible = false;
  scene.add(entry.heap);
  machineSelect.append(new Option(info.name, info.name));
  entry.ready = true;
}

function findFrame(entry, link) {
  return Object.keys(entry.links).find((f) => f === link || f.endsWith("/" + link));
}

function heapScale(volume) {  // a cone of height 0.6 r holding `volume` m^3
  return Math.cbrt((3 * volume) / (0.6 * Math.PI));
}

function labelText(name, s) {
  const mine = new Set(s.catalogue.filter((t) => t.model_name === name).map((t) => t.task_id));
  const lines = [name];
  for (const t of s.tasks) {
    if (!mine.has(t.task_id)) continue;
    lines.push(`task ${t.task_id} ${t.state}` + (t.running.length ? `: ${t.running.join(", ")}` : ""));
  }
  return lines.join("\n");
}

function apply(s) {
  s.machines.forEach((info, i) => { if (!machines[info.name]) addMachine(info, i); });
  if (s.terrain_version !== terrain.version) loadTerrain(s.terrain_version);
  for (const [name, entry] of Object.entries(machines)) {
    if (!entry.ready) continue;
    const tf = s.tf[name];
    if (tf) {
      for (const [frame, p] of Object.entries(tf.links)) {
        const g = entry.links[frame];
        if (!g) continue;
        g.position.set(p[0], p[1], p[2]);
        g.quaternion.set(p[3], p[4], p[5], p[6]);
        g.visible = true;
        g.updateMatrixWorld(true);
      }
      tfStamp[name] = tf.stamp;
      tfChain[name] = tf.chain;
    }
    const base = entry.links[findFrame(entry, "base_link")];
    if (base) entry.label.position.copy(base.position).add(new THREE.Vector3(0, 0, 5));
    entry.label.element.textContent = labelText(name, s);
    // soil: an excavator's bucket (the plant's bucket volume), a carrier's vessel (its own load)
    const volume = entry.info.type === "excavator" ? (s.soil.bucket ?? 0) : (s.vessels[name]?.load ?? 0);
    const holder = entry.links[findFrame(entry, entry.info.type === "excavator" ? "bucket_link" : "vessel_pin_link")];
    entry.heap.visible = !!holder && volume > 0.005;
    if (entry.heap.visible) {
      const k = heapScale(volume);
      entry.heap.scale.set(k, k, k);
      entry.heap.position.copy(holder.position).add(new THREE.Vector3(0, 0, 0.3 * k));
    }
  }
  if (!framed) frameSite();
  const shown = Object.entries(tfStamp).map(([n, t]) => `${n} ${t.toFixed(3)}`).join("  ");
  document.getElementById("stamp").textContent = shown ? `/tf stamps: ${shown}` : "";
  replayBar(s.replay);
}

// ---- cameras ----
let framed = false;
function frameSite() {  // the bird's-eye camera looks at the machines once all have been placed
  const bases = Object.values(machines).map((e) => e.links[findFrame(e, "base_link")]).filter((g) => g && g.visible);
  if (!bases.length || bases.length < Object.keys(machines).length) return;
  const c = new THREE.Vector3();
  for (const g of bases) c.add(g.position);
  c.divideScalar(bases.length);
  controls.target.copy(c);
  camera.position.copy(c).add(new THREE.Vector3(-6, -26, 18));
  framed = true;
}

const tmp = new THREE.Vector3();
function updateCamera() {
  const entry = machines[machineSelect.value];
  if (cameraMode.value === "bird" || !entry) { controls.enabled = true; controls.update(); return; }
  controls.enabled = false;
  const seat = cameraMode.value === "seat";
  const g = entry.links[findFrame(entry, seat ? "body_link" : "base_link")] ?? entry.links[findFrame(entry, "base_link")];
  if (!g) return;
  // seat: in the cab (left front of the upper body, eye height); follow: behind and above the machine
  const eye = seat ? new THREE.Vector3(0.3, 0.6, 2.4) : new THREE.Vector3(-14, 0, 9);
  const look = seat ? new THREE.Vector3(10, 0.6, 0.5) : new THREE.Vector3(0, 0, 1);
  camera.position.copy(eye.applyMatrix4(g.matrixWorld));
  camera.lookAt(tmp.copy(look).applyMatrix4(g.matrixWorld));
}

// ---- replay bar (shown when the panel plays a recording) ----
const replayEl = document.getElementById("replay"), slider = document.getElementById("slider");
let replayState = null, dragging = false;
function replayBar(r) {
  replayState = r ?? null;
  replayEl.classList.toggle("on", !!r);
  if (!r) return;
  document.getElementById("play").textContent = r.playing ? "pause" : "play";
  document.getElementById("replay-t").textContent = `${(r.t - r.start).toFixed(2)} / ${(r.end - r.start).toFixed(2)} s`;
  if (!dragging && r.end > r.start) slider.value = String(Math.round(1000 * (r.t - r.start) / (r.end - r.start)));
}
slider.addEventListener("pointerdown", () => { dragging = true; });
slider.addEventListener("change", () => {
  dragging = false;
  if (replayState) send({ op: "replay", seek: replayState.start + (replayState.end - replayState.start) * slider.value / 1000 });
});
document.getElementById("play").addEventListener("click", () => {
  if (replayState) send({ op: "replay", play: !replayState.playing });
});
window.site3dReplay = (cmd) => send({ op: "replay", ...cmd });  // for tests: seek to a stamp [s] / play / pause

// ---- connection and loop ----
let ws = null;
function send(obj) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(obj)); }
function connect() {
  const conn = document.getElementById("conn");
  ws = new WebSocket(`ws://${location.host}/ws${q}`);
  ws.onopen = () => { conn.textContent = "connected"; conn.className = "ok"; };
  ws.onclose = () => { conn.textContent = "disconnected"; conn.className = "bad"; setTimeout(connect, 1000); };
  ws.onmessage = (ev) => { const s = JSON.parse(ev.data); if (s.type === "state") apply(s); };
}
connect();

let last = performance.now(), counted = 0;
renderer.setAnimationLoop(() => {
  updateCamera();
  renderer.render(scene, camera);
  labels.render(scene, camera);
  frames++; counted++;
  const now = performance.now();
  if (now - last >= 1000) { fps = (1000 * counted) / (now - last); counted = 0; last = now; }
});
window.addEventListener("resize", () => {
  camera.aspect = view.clientWidth / view.clientHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(view.clientWidth, view.clientHeight);
  labels.setSize(view.clientWidth, view.clientHeight);
});
