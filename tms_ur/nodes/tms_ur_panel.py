"""``tms_ur_panel``: the web control panel and live site view.

Serves ``tms_ur/web/index.html`` over HTTP and a websocket at ``/ws`` on ``host:port`` (loopback by
default). The websocket pushes the site snapshot at ``rate_hz`` (>= 5 Hz) and takes commands
(``start``, ``cancel``, ``emergency``, ``confirm``) that become ROS messages:

| command | ROS |
|---|---|
| start task ids | ``/tms_ts/start`` (tms_msg/TaskIds) |
| cancel one id | ``/tms_ts/cancel`` (std_msgs/Int32) |
| emergency stop | ``/emergency_signal`` (std_msgs/Bool true) |
| confirm | ``/tms_ts/confirm`` (std_msgs/String "yes"), answers WaitForClick nodes |

Commands are taken only from the panel's own page (the handshake's ``Origin`` is ``http://`` + its ``Host``;
a loopback panel only under a loopback name) and, when a ``token`` is set (always off loopback), only with it
(``/ws?token=...``); a refused command gets one ``ack`` naming why (bad origin / missing token), is logged once
per connection and publishes nothing. Task ids are checked against int32 before a message is built
(``tms_ur.panel_core``).

Live view inputs: ``/tms_ts/status`` (tms_msg/TaskStatus), global-blackboard records read from tms_db
(``flag_records``), soil (``soil_topic``: std_msgs/Float64MultiArray with comma-separated labels in
layout.dim[0]), and per machine of ``machines`` (names; default the site's list, ``machines`` of config/site.yaml):
its pose (``pose_topics``, default ``/sim/truth/<name>/pose``: geometry_msgs/PoseStamped), its plan
(``/<name>/plan``: nav_msgs/Path) and its joints (``/<name>/joint_states``), shown after its description's type: an
excavator's arm side view, a carrier's vessel (and its load, ``/sim/truth/<name>/soil``), a dozer's blade.

The 3-D view (``/3d``, files of ``tms_ur/web3d``): ``/tf`` and ``/tf_static`` composed into each machine's link poses
in ``map`` (``panel_core.SiteTfView``), ``/urdf/<name>``, ``/terrain.json`` (the DB's newest static and dynamic
heightmaps). With ``replay`` (a rosbag2 directory) the panel subscribes to none of its input topics: it plays the
recording's messages of those topics into the same state (``panel_core.ReplayClock``; the page's slider sends
``{"op": "replay", "seek": <log time s>}`` / ``{"op": "replay", "play": true|false}``); the dynamic terrain is then the
newest replayed scan of ``points_topic`` rasterised as ``tms_sd_terrain_dynamic`` does.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import json
import threading
import time
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Bool, Float64MultiArray, Int32, String

from tf2_msgs.msg import TFMessage
from tms_common.errors import ConfigError, TmsError
from tms_common.node import run_node
from tms_common.params import startup_parameters
from tms_db import open_store
from tms_model.excavator.kinematics import ExcavatorKinematics
from tms_model.fleet import load_named
from tms_model.geometry import yaw_from_quaternion
from tms_model.machines import CRAWLER_DUMP, EXCAVATOR, Machine
from tms_model.site import load_site
from tms_model.urdf import machine_tree
from tms_msg.msg import TaskIds, TaskStatus
from tms_sp.config import load_sensing_config
from tms_sp.nodes.tms_sp_tf import LATCHED, TF_QOS
from tms_sp.pointcloud import xyz_from_cloud
from tms_sp.terrain import heightmap_from_blob, heightmap_from_points, latest_heightmap
from tms_ur.panel_core import (
    Access,
    CommandError,
    PanelConfig,
    ReplayClock,
    SiteState,
    SiteTfView,
    authorize,
    machine_info,
    parse_command,
    terrain_layer,
    websocket_access,
)
from tms_ur.recording import read_bag
from tms_ur.site_map import order_machines

WEB_DIR = Path(__file__).parent.parent / "web"
WEB3D_DIR = Path(__file__).parent.parent / "web3d"
STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/panel.js": ("panel.js", "text/javascript"),
          "/panel.css": ("panel.css", "text/css")}
#: The 3-D view's own files (tms_ur/web3d) by URL path.
STATIC_3D = {"/3d": ("index.html", "text/html; charset=utf-8"), "/site3d.js": ("site3d.js", "text/javascript")}
#: The npm packages' files the page imports (tms_ur/web3d/node_modules, installed by scripts/bootstrap.sh):
#: only these folders are served, only JavaScript.
MODULE_ROOTS = ("three/build/", "three/examples/jsm/", "urdf-loader/src/")
#: Terrain layers drawn, lowest first: the dynamic terrain from the mound scans over the static one.
TERRAIN_KINDS = ("static", "dynamic")


state_names = {0: "IDLE", 1: "RUNNING", 2: "SUCCESS", 3: "FAILURE", 4: "CANCELED"}


class PanelNode(Node):
    """ROS side of the panel: collects the live view into a SiteState and publishes commands."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("tms_ur_panel", **kwargs)
        d = startup_parameters(self)
        self.config = PanelConfig(
            host=d("host", "127.0.0.1").value,
            port=int(d("port", 8088).value),
            token=d("token", "").value,
            rate_hz=float(d("rate_hz", 5.0).value),
            flag_records=tuple(d("flag_records", [""]).value or ()),
            db_uri=d("db_uri", "").value,
            db_path=d("db_path", "").value,
        )
        site = load_site()
        names = [str(m) for m in d("machines", [""]).value if str(m)] or list(site.machines)
        # the page colours them in this order (excavators first, as the report's site map)
        machines = order_machines([load_named(name, site=site) for name in names])
        pose_topics = [str(e) for e in d("pose_topics", [""]).value if str(e)] or [
            f"{m.model_name}:/sim/truth/{m.model_name}/pose" for m in machines]
        self.lock = threading.Lock()
        self.site = SiteState(machines=[machine_info(m) for m in machines])
        self.kin = {m.model_name: ExcavatorKinematics(m) for m in machines if m.type == EXCAVATOR}
        trees = [machine_tree(m) for m in machines]
        self.urdf = {t.machine.model_name: t.urdf() for t in trees}
        self.tf_view = SiteTfView(trees)
        # replay: a rosbag2 directory played into the same state instead of the live topics
        self.replay_dir = str(d("replay", "").value)
        self._handlers: dict[str, Any] = {}
        self._replay_lock = threading.Lock()  # the timer and a seek from the page apply messages one at a time
        self.terrain: dict[str, dict] = {}  # kind -> terrain_layer of the newest stored heightmap
        if self.replay_dir:
            # the recording's scans make the dynamic terrain, rasterised as tms_sd_terrain_dynamic does (the live
            # DB's dynamic heightmap is of now, not of the recording); the static survey still comes from the DB
            self._scan_topic = str(d("points_topic", "/sim/sensors/mound/points").value)
            self._sensing = load_sensing_config()
            self._scan: tuple[int, Any] | None = None  # (log time ns, newest replayed scan)
            self._scan_layer: tuple[int, dict] | None = None
            self._current_log_time = 0
            self._subscribe(PointCloud2, self._scan_topic, self._on_replayed_scan, 2)
        self._subscribe(TFMessage, "/tf", self._on_tf, TF_QOS)
        self._subscribe(TFMessage, "/tf_static", self._on_tf, LATCHED)
        self.pub_start = self.create_publisher(TaskIds, "/tms_ts/start", 10)
        self.pub_cancel = self.create_publisher(Int32, "/tms_ts/cancel", 10)
        self.pub_emergency = self.create_publisher(Bool, "/emergency_signal", 10)
        self.pub_confirm = self.create_publisher(String, "/tms_ts/confirm", 10)
        self._subscribe(TaskStatus, "/tms_ts/status", self._on_status, 10)
        for entry in pose_topics:
            machine, _, topic = entry.partition(":")
            if not topic:
                raise ConfigError(f"tms_ur_panel: pose_topics entry {entry!r} must be 'machine:/topic'")
            self._subscribe(PoseStamped, topic, lambda m, name=machine: self._on_pose(name, m), 10)
        for m in machines:
            name = m.model_name
            self._subscribe(PathMsg, f"/{name}/plan", lambda msg, name=name: self._on_plan(name, msg), 10)
            self._subscribe(JointState, f"/{name}/joint_states", lambda msg, m=m: self._on_joints(m, msg), 10)
            if m.type == CRAWLER_DUMP:
                self._subscribe(Float64MultiArray, f"/sim/truth/{name}/soil",
                                lambda msg, name=name: self._on_carrier_soil(name, msg), 10)
        self._subscribe(Float64MultiArray, d("soil_topic", "/sim/truth/soil").value, self._on_soil, 10)
        self._store = None
        self._last_messages: dict[int, str] = {}
        self.create_timer(0.5, self._poll_db)
        self.replay: ReplayClock | None = None
        if self.replay_dir:
            self._load_replay()
        self._web = _WebThread(self)  # last: it serves this node's snapshot and commands

    # -- inputs ---------------------------------------------------------------------------
    def _subscribe(self, msg_type: Any, topic: str, callback: Any, qos: Any) -> None:
        """A live subscription, or in replay the handler of the topic's recorded messages."""
        if self.replay_dir:
            self._handlers[topic] = callback
        else:
            self.create_subscription(msg_type, topic, callback, qos)

    def _load_replay(self) -> None:
        """Read the recording's messages of the panel's topics (ConfigError naming the directory if unreadable)."""
        try:
            self._recorded = [m for m in read_bag(self.replay_dir) if m.topic in self._handlers]
            self.replay = ReplayClock([m.log_time_ns for m in self._recorded])
        except (TmsError, OSError) as exc:
            raise ConfigError(f"tms_ur_panel: replay {self.replay_dir!r}: {exc}") from None
        topics = sorted({m.topic for m in self._recorded})
        self.get_logger().info(f"replaying {len(self._recorded)} messages of {len(topics)} topics from "
                               f"{self.replay_dir}: {self.replay.end - self.replay.start:.1f} s")
        self._wall = time.monotonic()
        self.create_timer(0.05, self._replay_step)

    def _replay_step(self) -> None:
        with self._replay_lock:
            with self.lock:
                now = time.monotonic()
                self.replay.advance(now - self._wall)
                self._wall = now
            self._apply_due()

    def _apply_due(self) -> None:
        with self.lock:
            due = self.replay.due()
        for i in due:  # the handlers take self.lock themselves
            m = self._recorded[i]
            self._current_log_time = m.log_time_ns
            self._handlers[m.topic](m.msg)
        self._replay_terrain()

    def _on_replayed_scan(self, msg: Any) -> None:
        with self.lock:
            self._scan = (self._current_log_time, msg)

    def _replay_terrain(self) -> None:
        """Rasterise the newest replayed scan when it changed (only the newest: a seek applies many at once)."""
        with self.lock:
            scan = self._scan
        if scan is None or (self._scan_layer is not None and self._scan_layer[0] == scan[0]):
            return
        grid, ground = self._sensing.mound_grid, self._sensing.mound.ground_z
        source = f"{self._scan_topic} at log time {scan[0]} ns"
        try:
            hm = heightmap_from_points(xyz_from_cloud(scan[1], topic=self._scan_topic), cell=grid.resolution, box=grid,
                                       z_min=ground, source=source, min_coverage=0.2)
        except TmsError as exc:
            self.get_logger().warning(f"3-D view: replayed scan not drawn: {exc}", throttle_duration_sec=5.0)
            return
        layer = terrain_layer("dynamic", f"replay-{scan[0]}", hm.z, hm.x_min, hm.y_min, hm.x_max, hm.y_max)
        self._scan_layer = (scan[0], layer)
        with self.lock:
            self.terrain["dynamic"] = layer

    def _replay_command(self, seek: float | None, play: bool | None) -> str:
        if self.replay is None:
            raise CommandError("replay: this panel shows live topics (start it with replay:=<bag directory>)")
        with self._replay_lock:
            with self.lock:
                if play is not None:
                    self.replay.playing = play
                    self._wall = time.monotonic()
                if seek is not None and self.replay.seek(seek):
                    # back in time: the state is rebuilt from the recording's first message
                    self.tf_view = SiteTfView(list(self.tf_view.trees.values()))
                    self.site = SiteState(machines=self.site.machines)
                    self._scan = self._scan_layer = None
                    self.terrain.pop("dynamic", None)
            self._apply_due()
        return f"replay at {self.replay.t - self.replay.start:.3f} s" + (" playing" if self.replay.playing else "")

    def _on_tf(self, msg: TFMessage) -> None:
        with self.lock:
            for t in msg.transforms:
                tr, r = t.transform.translation, t.transform.rotation
                stamp = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9
                try:
                    self.tf_view.set(t.header.frame_id, t.child_frame_id, (tr.x, tr.y, tr.z), (r.x, r.y, r.z, r.w),
                                     stamp)
                except TmsError as exc:
                    self.get_logger().warning(f"3-D view: {exc}", throttle_duration_sec=5.0)

    def _on_status(self, msg: TaskStatus) -> None:
        tasks = []
        for t in msg.tasks:
            name = state_names.get(t.state, str(t.state))
            tasks.append({"task_id": t.task_id, "state": name, "running": list(t.running_leaves),
                          "message": t.message, "tree": t.tree_snapshot})
            if t.message and self._last_messages.get(t.task_id) != t.message and name in ("FAILURE", "CANCELED"):
                self._last_messages[t.task_id] = t.message
                with self.lock:
                    self.site.event("error" if name == "FAILURE" else "info", f"task {t.task_id}: {name}: {t.message}")
        with self.lock:
            self.site.tasks = tasks

    def _on_pose(self, machine: str, msg: PoseStamped) -> None:
        p = msg.pose.position
        with self.lock:
            self.site.set_pose(machine, p.x, p.y, yaw_from_quaternion(msg.pose.orientation))

    def _on_plan(self, machine: str, msg: PathMsg) -> None:
        pts = [[round(ps.pose.position.x, 2), round(ps.pose.position.y, 2)] for ps in msg.poses]
        with self.lock:
            self.site.set_plan(machine, pts)

    def _on_joints(self, machine: Machine, msg: JointState) -> None:
        joints = dict(zip(msg.name, msg.position, strict=False))
        with self.lock:
            self.site.set_joints(machine, joints, self.kin.get(machine.model_name))

    def _on_carrier_soil(self, machine: str, msg: Float64MultiArray) -> None:
        labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        values = dict(zip(labels, msg.data, strict=False))
        if "vessel" in values:
            with self.lock:
                self.site.set_load(machine, values["vessel"])

    def _on_soil(self, msg: Float64MultiArray) -> None:
        """Soil volumes [m^3]; labels come from ``layout.dim[0].label`` (comma-separated)."""
        labels = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        with self.lock:
            self.site.soil = {name: round(float(v), 3) for name, v in zip(labels, msg.data, strict=False)}

    def _poll_db(self) -> None:
        """Task catalogue and global-blackboard flags from tms_db (2 Hz)."""
        try:
            if self._store is None:
                self._store = open_store(uri=self.config.db_uri or None, path=self.config.db_path or None)
            catalogue = [{"task_id": t["task_id"], "description": t.get("description", ""),
                          "model_name": t.get("model_name", "")} for t in self._store.list_tasks()]
            flags = {}
            for record in self.config.flag_records:
                if not record:
                    continue
                try:
                    doc = self._store.get_record(record)
                except KeyError:
                    continue
                flags[record] = {k: v for k, v in doc.items()
                                 if k not in ("_id", "record_name", "model_name", "type", "timestamps", "description")
                                 and isinstance(v, (bool, int, float, str))}
        except Exception as exc:  # noqa: BLE001 - the panel keeps serving; the problem is shown in its log
            with self.lock:
                self.site.event("error", f"database: {type(exc).__name__}: {exc}")
            return
        terrain = self._read_terrain()
        with self.lock:
            self.site.task_catalogue = catalogue
            self.site.flags = flags
            self.terrain = terrain

    def _read_terrain(self) -> dict[str, dict]:
        """The newest heightmap of each of TERRAIN_KINDS in the DB (in replay: the static one, the dynamic one from
        the recording); a layer is decoded only when its file changed."""
        out = {}
        if self.replay_dir and self._scan_layer is not None:
            out["dynamic"] = self._scan_layer[1]
        for kind in TERRAIN_KINDS:
            if self.replay_dir and kind == "dynamic":
                continue
            try:
                doc, data = latest_heightmap(self._store, kind)
            except TmsError:
                continue  # none stored (yet): the view draws the other layer or flat ground
            file_id = str(doc["_id"])
            old = self.terrain.get(kind)
            if old is not None and old["id"] == file_id:
                out[kind] = old
                continue
            try:
                hm = heightmap_from_blob(data, doc, source=f"{kind} terrain {file_id}")
                out[kind] = terrain_layer(kind, file_id, hm.z, hm.x_min, hm.y_min, hm.x_max, hm.y_max)
            except TmsError as exc:
                self.get_logger().warning(f"3-D view: {exc}", throttle_duration_sec=5.0)
        return out

    def terrain_json(self) -> str:
        with self.lock:
            layers = [self.terrain[k] for k in TERRAIN_KINDS if k in self.terrain]
        return json.dumps({"version": _terrain_version(layers), "layers": layers})

    # -- outputs --------------------------------------------------------------------------
    def execute(self, text: str) -> str:
        """Run one browser command; returns a human-readable acknowledgement."""
        cmd = parse_command(text)
        if cmd.op == "start":
            self.pub_start.publish(TaskIds(task_ids=list(cmd.task_ids)))
            return f"start requested for task(s) {', '.join(map(str, cmd.task_ids))}"
        if cmd.op == "cancel":
            self.pub_cancel.publish(Int32(data=cmd.task_ids[0]))
            return f"cancel requested for task {cmd.task_ids[0]}"
        if cmd.op == "emergency":
            self.pub_emergency.publish(Bool(data=True))
            return "EMERGENCY STOP sent on /emergency_signal"
        if cmd.op == "replay":
            return self._replay_command(cmd.seek, cmd.play)
        self.pub_confirm.publish(String(data="yes"))
        return "confirmation sent"

    def snapshot(self) -> str:
        with self.lock:
            snap = self.site.snapshot()
            snap["tf"] = self.tf_view.snapshot()
            if self.replay is not None:
                snap["replay"] = self.replay.state()
            snap["terrain_version"] = _terrain_version([self.terrain[k] for k in TERRAIN_KINDS if k in self.terrain])
            return json.dumps(snap)

    def destroy_node(self) -> None:
        self._web.close()
        super().destroy_node()


class _WebThread:
    """The HTTP/websocket server on its own asyncio loop and thread, so the node spins like any other.

    The constructor returns once the socket is bound, and raises :class:`ConfigError` when it cannot be.
    """

    def __init__(self, node: PanelNode) -> None:
        self.loop = asyncio.new_event_loop()
        self._ready: concurrent.futures.Future = concurrent.futures.Future()
        self._task: asyncio.Task | None = None
        self._thread = threading.Thread(target=self._run, args=(node,), daemon=True, name="tms-ur-web")
        self._thread.start()
        try:
            self._ready.result(timeout=10.0)
        except OSError as exc:
            raise ConfigError(f"tms_ur_panel: cannot serve on {node.config.host}:{node.config.port}: {exc}") from None

    def _run(self, node: PanelNode) -> None:
        asyncio.set_event_loop(self.loop)
        self._task = self.loop.create_task(_serve(node, self._ready))
        try:
            self.loop.run_until_complete(self._task)
        except asyncio.CancelledError:
            pass
        except Exception as exc:  # noqa: BLE001 - a bind error goes to the constructor; later ones to the log
            if not self._ready.done():
                self._ready.set_exception(exc)
            else:
                node.get_logger().error(f"web server stopped: {type(exc).__name__}: {exc}")
        finally:
            self.loop.close()

    def close(self) -> None:
        if self._thread.is_alive():
            self.loop.call_soon_threadsafe(lambda: self._task is not None and self._task.cancel())
            self._thread.join(timeout=2.0)



async def _serve(node, ready: concurrent.futures.Future) -> None:
    from websockets.asyncio.server import serve
    from websockets.datastructures import Headers
    from websockets.http11 import Response

    config: PanelConfig = node.config
    clients: set = set()

    def process_request(connection, request):
        url = urlsplit(request.path)
        token = parse_qs(url.query).get("token", [None])[0]
        ok, reason = authorize(config, connection.remote_address[0], token)
        if not ok:
            node.get_logger().warning(f"refused {connection.remote_address[0]} {url.path}: {reason}")
            return connection.respond(403, f"403 Forbidden: {reason}\n")
        if url.path == "/ws":
            return None
        if url.path in STATIC:
            name, ctype = STATIC[url.path]
            return _ok((WEB_DIR / name).read_bytes(), ctype)
        if url.path in STATIC_3D:
            name, ctype = STATIC_3D[url.path]
            return _ok((WEB3D_DIR / name).read_bytes(), ctype)
        if url.path == "/terrain.json":
            return _ok(node.terrain_json().encode(), "application/json")
        if url.path.startswith("/urdf/"):
            urdf = node.urdf.get(url.path[len("/urdf/"):])
            if urdf is None:
                return connection.respond(404, f"404 Not Found: no machine {url.path[6:][:60]!r} on this panel\n")
            return _ok(urdf.encode(), "application/xml")
        if url.path.startswith("/modules/"):
            path = _module_file(url.path[len("/modules/"):])
            if path is None:
                return connection.respond(404, "404 Not Found\n")
            return _ok(path.read_bytes(), "text/javascript", cache=True)
        return connection.respond(404, "404 Not Found\n")

    def _ok(body: bytes, ctype: str, cache: bool = False):
        return Response(200, "OK", Headers([("Content-Type", ctype), ("Content-Length", str(len(body))),
                                            ("Cache-Control", "max-age=3600" if cache else "no-store")]), body)

    def access_of(ws) -> Access:
        request = ws.request
        token = parse_qs(urlsplit(request.path).query).get("token", [None])[0]
        return websocket_access(config, request.headers.get_all("Origin"), _one(request.headers, "Host"), token)

    async def handler(ws) -> None:
        access = access_of(ws)
        peer = ws.remote_address[0] if ws.remote_address else "?"
        origin = ", ".join(ws.request.headers.get_all("Origin")) or "none"
        logged = False
        if access.view:
            clients.add(ws)
        try:
            async for text in ws:
                if not access.commands:
                    # Checked before the text is even parsed: nothing from this connection reaches ROS.
                    # Logged once per connection, so a page looping on send cannot flood the log.
                    if not logged:
                        logged = True
                        line = f"refused commands from {peer} (Origin: {origin[:80]}): {access.refusal}"
                        node.get_logger().warning(line)
                        with node.lock:
                            node.site.event("error", line)
                    reply = {"type": "ack", "ok": False, "refused": access.kind,
                             "text": f"refused: {access.refusal}"}
                    await ws.send(json.dumps(reply))
                    continue
                try:
                    reply = {"type": "ack", "ok": True, "text": node.execute(text)}
                except CommandError as exc:
                    reply = {"type": "ack", "ok": False, "text": str(exc)}
                except Exception as exc:  # noqa: BLE001 - one bad command must not end the operator's connection
                    node.get_logger().error(f"command failed: {type(exc).__name__}: {exc}")
                    reply = {"type": "ack", "ok": False, "text": f"internal error: {type(exc).__name__}: {exc}"}
                with node.lock:
                    node.site.event("info" if reply["ok"] else "error", reply["text"])
                await ws.send(json.dumps(reply))
        finally:
            clients.discard(ws)

    async def broadcast() -> None:
        period = 1.0 / config.rate_hz
        while True:
            if clients:
                text = node.snapshot()
                await asyncio.gather(*(c.send(text) for c in list(clients)), return_exceptions=True)
            await asyncio.sleep(period)

    async with serve(handler, config.host, config.port, process_request=process_request) as server:
        node.get_logger().info(f"panel on http://{config.host}:{config.port}/")
        # The token itself is not printed: whoever set the parameter has it, log readers need not.
        needs = " (commands need the configured token: open the page with ?token=...)" if config.token else ""
        print(f"tms_ur_panel: serving http://{config.host}:{config.port}/{needs}", flush=True)
        broadcaster = asyncio.get_running_loop().create_task(broadcast())
        ready.set_result(True)
        try:
            await server.serve_forever()
        finally:
            broadcaster.cancel()


def _terrain_version(layers: list[dict]) -> str:
    return ",".join(f"{layer['kind']}:{layer['id']}" for layer in layers)


def _module_file(rel: str) -> Path | None:
    """The installed npm file for ``/modules/<rel>``, None unless it is a .js file under MODULE_ROOTS."""
    if not rel.endswith(".js") or not rel.startswith(MODULE_ROOTS) or ".." in rel.split("/"):
        return None
    root = (WEB3D_DIR / "node_modules").resolve()
    path = (root / rel).resolve()
    return path if path.is_relative_to(root) and path.is_file() else None


def _one(headers, name: str) -> str | None:
    """The header's value; None when absent or repeated (two Host headers name no single origin)."""
    values = headers.get_all(name)
    return values[0] if len(values) == 1 else None


def main() -> int:
    return run_node(PanelNode)
