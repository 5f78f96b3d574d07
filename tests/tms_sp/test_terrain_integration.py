"""Terrain in the DB across processes: the MuJoCo plant scans the mound, sensing and the terrain nodes run as their
own processes over DDS with one on-disk store, the excavator digs, and the heightmap action and the terrain services
answer with the dug terrain.

plant + com3_bridge + arm controller + planner (tests/arm_stack.py), tms_sp_sensing, tms_sd_terrain_dynamic,
tms_db_reader_heightmap, tms_ur_construction_terrain; the static terrain goes in through the tms_ss_terrain_static
command from a LAS file of the plant's first scan.
"""

from __future__ import annotations

import math
import signal
import subprocess

import numpy as np
import pytest

from tests.arm_stack import arm_stack  # noqa: F401 - a fixture, found by pytest through this module
from tests.rosproc import executable
from tests.tms_sp.test_terrain import _write_las
from tests.tms_sp.treeutil import ROOT
from tms_db import open_store
from tms_model.excavator import codes
from tms_model.site import load_site
from tms_sp import terrain as tr
from tms_sp.config import load_sensing_config
from tms_sp.pointcloud import xyz_from_cloud

pytestmark = pytest.mark.integration
SUCCEEDED, ABORTED = 4, 6
CFG = load_sensing_config()



def _static_cmd(db, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(executable("tms_sp", "tms_ss_terrain_static")), *map(str, args), "--db-path", str(db)],
                          capture_output=True, text=True, timeout=120)


def _call(stack, client, request, timeout: float = 30.0):
    assert stack.spin_until(client.service_is_ready, timeout), f"{client.srv_name} not available"
    fut = client.call_async(request)
    assert stack.spin_until(fut.done, timeout), f"{client.srv_name}: no answer"
    return fut.result()


def _heightmap(stack, action, kind: str, *, filename: str = ""):
    """(status, result) of a TmsdbTerrainImage goal."""
    from tms_msg_db.action import TmsdbTerrainImage

    assert action.wait_for_server(timeout_sec=30), "tms_db_reader_heightmap not available"
    goal = TmsdbTerrainImage.Goal(type=kind, filename=filename)
    fut = action.send_goal_async(goal)
    assert stack.spin_until(fut.done, 30), "no goal response"
    handle = fut.result()
    assert handle.accepted
    res = handle.get_result_async()
    assert stack.spin_until(res.done, 30), "no result"
    return res.result().status, res.result().result


def _mono16(result) -> tr.Heightmap:
    img = result.image
    assert img.encoding == "mono16" and img.step == 2 * img.width
    units = np.frombuffer(bytes(img.data), dtype="<u2").reshape(img.height, img.width).astype(np.int64)
    # pixel 0 = the site's ground: both heightmaps of this test are stored with z_min = mound.ground_z (0)
    return tr.Heightmap(z=units / tr.HEIGHT_SCALE, x_min=result.offset_x, y_min=result.offset_y,
                        x_max=result.offset_x + result.terrainheight, y_max=result.offset_y + result.terrainwidth,
                        z_min=0.0)


def test_static_and_dynamic_terrain_through_the_db_while_the_excavator_digs(arm_stack, procs, ros_node,  # noqa: F811
                                                                             tmp_path):
    from rclpy.action import ActionClient
    from sensor_msgs.msg import PointCloud2

    from tms_db.cli import seed
    from tms_msg_db.action import TmsdbTerrainImage
    from tms_msg_db.srv import ColoredMeshSrv, DemSrv, TerrainStaticSrv, TmsdbTerrainImageSrv
    from tms_msg_rp.action import TmsRpZx200ExcavateSimple

    db = tmp_path / "db"
    with open_store(path=db) as store:
        seed(store, ROOT / "config" / "seeds" / "paper.yaml")
    stack = arm_stack(ic120_pose="P1")
    site = load_site()
    mound = site.mound
    assert mound.ground_z == 0.0, "the test compares heightmaps whose pixel 0 is z = 0"

    # the plant's first scan -> a LAS survey -> the static terrain, through the command
    scans: list = []
    ros_node.create_subscription(PointCloud2, "/sim/sensors/mound/points", scans.append, 2)
    assert stack.spin_until(lambda: scans, 30), "no mound scan from the plant"
    pts0 = xyz_from_cloud(scans[-1])
    las = tmp_path / "site_survey.las"
    _write_las(las, pts0)
    done = _static_cmd(db, las, "--z-min", "0", "--resolution", "0.1")
    assert done.returncode == 0, done.stderr
    assert "static site_survey.png" in done.stdout

    sensing = procs([executable("tms_sp", "tms_sp_sensing"), "--ros-args", "-p", f"db_path:={db}",
                     "-p", "use_sim_time:=true"], name="tms_sp_sensing")
    dynamic = procs([executable("tms_sp", "tms_sd_terrain_dynamic"), "--ros-args", "-p", f"db_path:={db}",
                     "-p", "use_sim_time:=true", "-p", "keep:=3"], name="tms_sd_terrain_dynamic")
    reader = procs([executable("tms_db", "tms_db_reader_heightmap"), "--ros-args", "-p", f"db_path:={db}",
                    "-p", "image_encoding:=mono16"], name="tms_db_reader_heightmap")
    services = procs([executable("tms_sp", "tms_ur_construction_terrain"), "--ros-args", "-p", f"db_path:={db}"],
                     name="tms_ur_construction_terrain")
    assert dynamic.wait_for("dynamic terrain:", 60), dynamic.output
    assert reader.wait_for("tms_db_reader_heightmap ready", 60), reader.output
    assert services.wait_for("terrain services ready", 60), services.output
    action = ActionClient(ros_node, TmsdbTerrainImage, "tms_db_reader_heightmap")

    # nothing of a type stored: the goal aborts naming it (the original would wait forever)
    status, res = _heightmap(stack, action, "heightmap")
    assert status == ABORTED and res.result is False and "no 'heightmap' terrain stored" in res.msg, res.msg
    status, res = _heightmap(stack, action, "mesh_of_mars")
    assert status == ABORTED and "terrain type 'mesh_of_mars'" in res.msg, res.msg

    status, res = _heightmap(stack, action, "static", filename="site_survey.png")
    assert status == SUCCEEDED and res.result, res.msg
    static = _mono16(res)
    assert res.type == "static" and res.filename == "site_survey.png"
    assert res.terrainelevation == pytest.approx(mound.height, abs=0.1)
    with open_store(path=db) as store:
        assert stack.spin_until(lambda: len(store.find_blobs({"type": "dynamic"})) >= 1, 30), dynamic.output

    status, res = _heightmap(stack, action, "dynamic")
    assert status == SUCCEEDED and res.result, res.msg
    before = _mono16(res)
    xs, ys = before.centres()
    inner = np.hypot(xs - mound.cx, ys - mound.cy) < mound.base_radius + 0.5
    st = np.vectorize(static.height_at)(xs, ys)
    diff0 = np.abs(before.z - st)[inner]
    # Two scans (2 cm noise, one point per 0.2 m, so one cell in four measured and the rest filled from the
    # nearest) on differently aligned grids (the survey's from its lowest x, y; the dynamic one the sensing box):
    # on the 0.6 m/m slopes a cell's height steps 6 cm, so they agree to a few centimetres, not to 1/4096 m.
    print(f"before the dig, |dynamic - static|: median {np.median(diff0):.4f} m, p90 {np.percentile(diff0, 90):.4f} m, "
          f"max {diff0.max():.4f} m over {diff0.size} cells")
    assert np.median(diff0) < 0.03 and np.percentile(diff0, 90) < 0.08, (np.median(diff0), diff0.max())

    # the dig, as tms_sp computes a target: the near slope, 0.35 m below the surface, a 1.5 m drag
    x = mound.cx - 0.65
    r = abs(x - mound.cx)
    surface = mound.ground_z + mound.height * (1.0 if r <= mound.top_radius else
                                               (mound.base_radius - r) / (mound.base_radius - mound.top_radius))
    g = TmsRpZx200ExcavateSimple.Goal()
    g.position_with_angle.position.x, g.position_with_angle.position.y = x, mound.cy
    g.position_with_angle.position.z = surface - 0.35
    g.position_with_angle.theta_w = math.radians(45.0)
    g.position_with_angle.offset = 1.5
    mound0 = stack.soil[0]
    status, plan = stack.run("excavate", g, timeout=180)
    assert status == SUCCEEDED and plan.error_code.val == codes.SUCCESS, plan.message
    stack.spin(1.0)
    assert stack.soil[0] < mound0 - 0.2, (mound0, stack.soil)
    with open_store(path=db) as store:
        t_dug = store.find_blobs({"type": "dynamic"})[-1]["time"]
        # a scan after the dig stored; at most keep (3) dynamic heightmaps kept
        assert stack.spin_until(lambda: store.find_blobs({"type": "dynamic"})[-1]["time"] > t_dug, 30)
        stack.spin(1.5)
        dyn_docs = store.find_blobs({"type": "dynamic"})
        assert 1 <= len(dyn_docs) <= 3, [d["time"] for d in dyn_docs]
        assert all(d["id"] == tr.DYNAMIC_ID and d["filename"] == "dynamic_terrain.png" for d in dyn_docs)

    status, res = _heightmap(stack, action, "dynamic")
    assert status == SUCCEEDED and res.result and res.type == "dynamic", res.msg
    after = _mono16(res)
    assert after.z.shape == before.z.shape
    diff = after.z - st  # dug terrain minus the static survey
    # the cut: the strip the bucket swept (its width 2 x bucket_radius, from the tip target back by the drag)
    half = CFG.excavation.bucket_radius
    cut = (xs > x - 1.5) & (xs < x) & (np.abs(ys - mound.cy) < half) & inner
    # the physical plant's bucket meets the soil's resistance and cuts a shallower, shorter strip than the kinematic
    # one did (0.37-0.40 m deep there, 0.24 m in a run on it): well beyond the scanner's 2 cm noise either way
    assert diff[cut].min() < -0.15, diff[cut].min()
    assert np.mean(diff[cut] < -0.1) > 0.1, np.sort(diff[cut])[:10]
    # elsewhere, well away from the strip (and from the spill at its edges): the survey within the scan noise
    far = inner & ((np.abs(ys - mound.cy) > half + 1.0) | (xs > mound.cx + 1.0))
    off = np.abs(diff[far])
    print(f"after the dig: cut strip min {diff[cut].min():.4f} m, {np.mean(diff[cut] < -0.1):.0%} of its "
          f"{cut.sum()} cells > 0.1 m lower; elsewhere |dynamic - static| median {np.median(off):.4f} m, "
          f"p90 {np.percentile(off, 90):.4f} m; dynamic before vs after elsewhere: median "
          f"{np.median(np.abs(after.z - before.z)[far]):.4f} m")
    assert np.median(off) < 0.03 and np.percentile(off, 90) < 0.08, (np.median(off), off.max())
    # the same grid before and after: elsewhere they differ by the scan noise only
    assert np.median(np.abs(after.z - before.z)[far]) < 0.02

    # the services answer from the DB; the dynamic terrain stopped first, so that they see the same heightmap
    dynamic.signal(signal.SIGINT)
    assert dynamic.wait(30) == 0, dynamic.output
    status, res = _heightmap(stack, action, "dynamic")
    assert status == SUCCEEDED and res.result, res.msg
    after = _mono16(res)
    clients = {name: ros_node.create_client(t, f"/output/terrain/{name}") for name, t in (
        ("static_srv", TerrainStaticSrv), ("dem_srv", DemSrv), ("mesh_srv", ColoredMeshSrv),
        ("heightmap_srv", TmsdbTerrainImageSrv))}
    cloud = _call(stack, clients["static_srv"], TerrainStaticSrv.Request(type="static")).pointcloud2
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "r", "g", "b"] and cloud.point_step == 24
    assert cloud.width == static.rows * static.cols and len(cloud.data) == 24 * cloud.width
    grid = _call(stack, clients["dem_srv"], DemSrv.Request(type="dynamic")).occupancy_grid
    assert (grid.info.width, grid.info.height) == (after.cols, after.rows)
    assert grid.info.origin.position.x == pytest.approx(after.x_min)
    assert min(grid.data) == -128 and max(grid.data) == 127 and len(grid.data) == after.rows * after.cols
    mesh = _call(stack, clients["mesh_srv"], ColoredMeshSrv.Request(type="dynamic")).colored_mesh
    assert len(mesh.vertices) == after.rows * after.cols and len(mesh.triangles) > 0
    assert len(mesh.vertex_colors) == len(mesh.vertices) == len(mesh.vertex_normals)
    top = max(v.z for v in mesh.vertices)
    assert top == pytest.approx(float(after.z.max()), abs=1e-3)
    img = _call(stack, clients["heightmap_srv"], TmsdbTerrainImageSrv.Request(type="dynamic"))
    assert img.type == "dynamic" and img.image.encoding == "bgr8" and img.image.width == after.cols
    hi = np.frombuffer(bytes(img.image.data), dtype=np.uint8).reshape(img.image.height, img.image.width, 3)
    # the original's 8-bit image: the high byte of each 16-bit unit (1/16 m), the same in B, G and R
    assert np.array_equal(hi[:, :, 0], (np.rint(after.z * tr.HEIGHT_SCALE).astype(np.int64) >> 8).astype(np.uint8))
    empty = _call(stack, clients["dem_srv"], DemSrv.Request(type="heightmap")).occupancy_grid
    assert empty.info.width == 0 and len(empty.data) == 0
    assert services.wait_for("terrain request for type 'heightmap': no 'heightmap' terrain stored", 10), \
        services.output

    # bad inputs to the command: named, nothing stored
    with open_store(path=db) as store:
        n_static = len(store.find_blobs({"type": "static"}))
    missing = _static_cmd(db, tmp_path / "nothere.las")
    assert missing.returncode == 1 and "nothere.las: no such LAS/LAZ file" in missing.stderr, missing.stderr
    notlas = tmp_path / "notes.las"
    notlas.write_text("this is not a point cloud\n")
    bad = _static_cmd(db, notlas)
    assert bad.returncode == 1 and "notes.las: not a readable LAS/LAZ file" in bad.stderr, bad.stderr
    empty_las = tmp_path / "empty.las"
    _write_las(empty_las, np.zeros((0, 3)))
    nopts = _static_cmd(db, empty_las)
    assert nopts.returncode == 1 and "empty.las: the LAS file holds no point" in nopts.stderr, nopts.stderr
    assert "Traceback" not in missing.stderr + bad.stderr + nopts.stderr
    with open_store(path=db) as store:
        assert len(store.find_blobs({"type": "static"})) == n_static
    for p in (sensing, reader, services):
        assert p.popen.poll() is None, p.output
