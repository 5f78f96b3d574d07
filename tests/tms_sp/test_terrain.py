"""The terrain core without ROS: LAS / point cloud -> heightmap -> the original's 16-bit PNG and back, DEM, mesh,
points, and the heightmap in a real (embedded) store's GridFS; bad inputs named."""

from __future__ import annotations

import io

import laspy
import numpy as np
import pytest
from PIL import Image

from tms_db import open_store
from tms_sp import terrain as tr
from tms_sp.heightgrid import GridSpec

CELL = 0.1


def _mound_points(rng: np.random.Generator, spacing: float = 0.05) -> np.ndarray:
    """A cone mound (1.5 m high, 3 m base radius) on flat ground at z = 10 m, in survey-like coordinates."""
    xs = np.arange(100.0, 108.0, spacing)
    ys = np.arange(200.0, 206.0, spacing)
    gx, gy = np.meshgrid(xs, ys)
    r = np.hypot(gx - 104.0, gy - 203.0)
    z = 10.0 + np.clip(1.5 * (1 - r / 3.0), 0.0, None)
    pts = np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])
    return pts[rng.permutation(len(pts))]


def _surface(x, y):
    return 10.0 + np.clip(1.5 * (1 - np.hypot(x - 104.0, y - 203.0) / 3.0), 0.0, None)


def _write_las(path, pts: np.ndarray) -> None:
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.offsets = pts.min(axis=0) if len(pts) else np.zeros(3)
    header.scales = np.array([0.001, 0.001, 0.001])
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))


def test_las_to_heightmap_png_round_trip_within_the_encoding(tmp_path):
    pts = _mound_points(np.random.default_rng(1))
    las = tmp_path / "survey.las"
    _write_las(las, pts)
    hm = tr.heightmap_from_file(las, cell=CELL)
    assert (hm.x_min, hm.y_min) == pytest.approx((100.0, 200.0), abs=1e-3)
    assert hm.cols == 80 and hm.rows == 60  # 7.95 m / 0.1 -> 80 cells, 5.95 m -> 60
    assert hm.z_min == pytest.approx(10.0, abs=1e-3)  # pixel 0 = the lowest point, as the original
    # image order: row 0 is north; the mound's summit cell holds about 1.5 m above ground
    xc, yc = hm.centres()
    assert yc[0, 0] > yc[-1, 0] and xc[0, 0] < xc[0, -1]
    assert np.abs(hm.z - _surface(xc, yc)).max() < 0.06  # cell medians + 3x3 median filter on a 0.5 m/m slope
    png = tr.encode_png(hm)
    img = Image.open(io.BytesIO(png))
    assert img.format == "PNG" and img.mode == "I;16" and img.size == (80, 60)
    units = np.asarray(img).astype(float)
    assert units.max() == pytest.approx((hm.z.max() - hm.z_min) * 4096, abs=0.51)  # z * 4096
    back = tr.heightmap_from_png(png, x_min=hm.x_min, y_min=hm.y_min, size_x=hm.x_max - hm.x_min,
                                size_y=hm.y_max - hm.y_min, z_min=hm.z_min)
    assert np.abs(back.z - hm.z).max() <= 0.5 / tr.HEIGHT_SCALE + 1e-9
    assert back.height_at(105.05, 203.05) == pytest.approx(_surface(105.05, 203.05), abs=0.02)


def test_array_input_and_empty_cells_interpolated():
    pts = _mound_points(np.random.default_rng(2), spacing=0.1)
    # holes with no point: a 1 m square on flat ground, a 0.6 m one on the 0.5 m/m slope; interpolated
    flat = (np.abs(pts[:, 0] - 100.8) < 0.5) & (np.abs(pts[:, 1] - 200.8) < 0.5)
    slope = (np.abs(pts[:, 0] - 105.5) < 0.3) & (np.abs(pts[:, 1] - 203.0) < 0.3)
    hm = tr.heightmap_from_points(pts[~(flat | slope)], cell=0.2)
    assert np.isfinite(hm.z).all()
    assert hm.height_at(100.8, 200.8) == pytest.approx(10.0, abs=1e-6)
    xc, yc = hm.centres()
    row, col = int((hm.y_max - 203.0) / hm.cell_y), int((105.5 - hm.x_min) / hm.cell_x)
    # (the hole's edge cells hold part of their points only: a slope x a few cm of bias)
    assert hm.z[row, col] == pytest.approx(_surface(xc[row, col], yc[row, col]), abs=0.05)
    # sparse points (one per 0.2 m) on 0.1 m cells: the slope stays a slope, no steps of nearest filling
    sparse = _mound_points(np.random.default_rng(3), spacing=0.2)
    # one cell in four holds a point (at its centre), the others are interpolated: the slope without steps
    fine = tr.heightmap_from_points(sparse, cell=0.1, box=GridSpec(99.95, 199.95, 107.95, 205.95, 0.1))
    xc, yc = fine.centres()
    assert np.percentile(np.abs(fine.z - _surface(xc, yc)), 90) < 0.02
    box = GridSpec(102.0, 201.0, 106.0, 205.0, 0.2)
    sub = tr.heightmap_from_points(pts, cell=0.25, box=box, z_min=9.0)
    assert (sub.cols, sub.rows, sub.z_min) == (16, 16, 9.0)


def test_heightmap_png_file_input(tmp_path):
    units = np.arange(6 * 4, dtype=np.uint16).reshape(6, 4) * 1000
    path = tmp_path / "hm.png"
    Image.fromarray(units).save(path)
    hm = tr.heightmap_from_file(path, cell=0.5, x_min=3.0, y_min=-1.0, z_min=2.0)
    assert (hm.cols, hm.rows, hm.x_max, hm.y_max) == (4, 6, 5.0, 2.0)
    assert hm.z[5, 3] == pytest.approx(2.0 + 23000 / 4096)
    assert hm.height_at(4.9, -0.9) == pytest.approx(2.0 + 23000 / 4096)  # south-east = last row, last column


def test_bad_inputs_name_the_culprit(tmp_path):
    with pytest.raises(tr.TerrainError, match=r"nothere\.las: no such LAS/LAZ file"):
        tr.heightmap_from_file(tmp_path / "nothere.las", cell=CELL)
    fake = tmp_path / "fake.las"
    fake.write_text("x,y,z\n1,2,3\n")
    with pytest.raises(tr.TerrainError, match=r"fake\.las: not a readable LAS/LAZ file"):
        tr.heightmap_from_file(fake, cell=CELL)
    empty = tmp_path / "empty.las"
    _write_las(empty, np.zeros((0, 3)))
    with pytest.raises(tr.TerrainError, match=r"empty\.las: the LAS file holds no point"):
        tr.heightmap_from_file(empty, cell=CELL)
    with pytest.raises(tr.TerrainError, match=r"scan: empty point cloud"):
        tr.heightmap_from_points(np.zeros((0, 3)), cell=CELL, source="scan")
    with pytest.raises(tr.TerrainError, match=r"scan: expected points of shape"):
        tr.heightmap_from_points(np.zeros((4, 2)), cell=CELL, source="scan")
    rgb = tmp_path / "colour.png"
    Image.fromarray(np.zeros((4, 4, 3), dtype=np.uint8)).save(rgb)
    with pytest.raises(tr.TerrainError, match=r"colour\.png: heightmap must be a 16-bit grayscale PNG, got mode RGB"):
        tr.heightmap_from_file(rgb, cell=CELL)
    tall = tr.Heightmap(z=np.array([[0.0, 17.0]]), x_min=0, y_min=0, x_max=2, y_max=1, z_min=0.0)
    with pytest.raises(tr.TerrainError, match=r"tall: relief 17\.000 m .* exceeds"):
        tr.encode_png(tall, source="tall")


def test_dem_mesh_points_and_8bit_image():
    z = np.array([[3.0, 2.0, 1.0], [2.0, 1.0, 0.0]])  # row 0 north; rises to the north-west
    hm = tr.Heightmap(z=z, x_min=10.0, y_min=20.0, x_max=13.0, y_max=22.0, z_min=0.0)
    data, width, height, res, origin = tr.dem(hm)
    assert (width, height, res, origin) == (3, 2, 1.0, (10.0, 20.0))
    assert data == [42, -43, -128, 127, 42, -43]  # row 0 = south, -128..127 lowest..highest
    mesh = tr.colored_mesh(hm)
    assert mesh.vertices.shape == (6, 3) and mesh.triangles.shape == (4, 3)
    assert mesh.vertices[0].tolist() == [10.5, 21.5, 3.0]
    for tri in mesh.triangles:  # counter-clockwise seen from above: upward faces
        a, b, c = mesh.vertices[tri]
        assert np.cross(b - a, c - a)[2] > 0
    # slope 1 m/m down to the east and 1 m/m down to the south: the normal leans east and south
    assert mesh.normals[1] == pytest.approx(np.array([1.0, -1.0, 1.0]) / np.sqrt(3.0))
    assert mesh.colors.min() >= 0.0 and mesh.colors.max() <= 1.0
    assert mesh.colors[0].sum() > mesh.colors[5].sum()  # the high corner is lighter
    big = tr.Heightmap(z=np.zeros((300, 400)), x_min=0, y_min=0, x_max=40, y_max=30, z_min=0)
    assert len(tr.colored_mesh(big, max_vertices=10000).vertices) <= 10000
    raw, n = tr.cloud_xyzrgb(hm)
    pts = np.frombuffer(raw, dtype="<f4").reshape(n, 6)
    assert n == 6 and pts[5, :3].tolist() == [12.5, 20.5, 0.0]
    img = tr.image_8bit(np.array([[0, 255, 256, 65535]]))
    assert img.shape == (1, 4, 3) and img[0, :, 0].tolist() == [0, 0, 1, 255]


def test_heightmaps_in_the_store_latest_by_type_and_pruned(tmp_path):
    store = open_store(path=tmp_path / "db")
    try:
        hm = tr.Heightmap(z=np.full((4, 5), 1.25), x_min=1.0, y_min=2.0, x_max=6.0, y_max=6.0, z_min=1.0)
        fid = tr.store_heightmap(store, hm, kind="static", ident=tr.STATIC_ID, filename="site.png",
                                time="2026-01-01T00:00:00.000000")
        doc = store.find_blobs({"type": "static"})[0]
        assert doc["_id"] == fid and doc["filename"] == "site.png" and doc["id"] == 3030
        assert (doc["height"], doc["width"], doc["elevation"], doc["offset_x"], doc["offset_y"]) == (
            5.0, 4.0, 0.25, 1.0, 2.0)
        for k in range(5):
            dyn = tr.Heightmap(z=np.full((4, 5), 1.0 + k / 10), x_min=1.0, y_min=2.0, x_max=6.0, y_max=6.0, z_min=1.0)
            tr.store_heightmap(store, dyn, kind="dynamic", ident=tr.DYNAMIC_ID, filename="dyn.png",
                              time=f"2026-01-01T00:00:0{k}.000000", keep=3)
        dyns = store.find_blobs({"type": "dynamic"})
        assert [d["time"][-9:-7] for d in dyns] == ["02", "03", "04"]  # the two oldest pruned
        doc, data = tr.latest_heightmap(store, "dynamic")
        back = tr.heightmap_from_blob(data, doc)
        assert back.z == pytest.approx(np.full((4, 5), 1.4), abs=1e-4)
        assert (back.x_min, back.y_max) == (1.0, 6.0)
        doc, _ = tr.latest_heightmap(store, "static", ident=3030, filename="site.png")
        assert doc["_id"] == fid
        with pytest.raises(tr.TerrainError, match=r"no 'heightmap' terrain stored"):
            tr.latest_heightmap(store, "heightmap")
        with pytest.raises(tr.TerrainError, match=r"no 'static' terrain stored named 'other.png'"):
            tr.latest_heightmap(store, "static", filename="other.png")
        with pytest.raises(tr.TerrainError, match=r"static terrain: empty filename"):
            tr.store_heightmap(store, hm, kind="static", ident=1, filename="", time="t")
        assert len(store.find_blobs({"type": "static"})) == 1  # nothing stored by the refused call
    finally:
        store.close()


def test_reader_core_images_as_the_original_and_errors(tmp_path):
    """tms_db.heightmap, the core of tms_db_reader_heightmap: newest by type, bgr8 as the original's reader, mono16."""
    from tms_db.errors import RecordNotFound, ValidationError
    from tms_db.heightmap import find_heightmap, image_of

    store = open_store(path=tmp_path / "db")
    try:
        hm = tr.Heightmap(z=np.array([[0.0, 1.0, 2.5]]), x_min=0.0, y_min=0.0, x_max=3.0, y_max=1.0, z_min=0.0)
        tr.store_heightmap(store, hm, kind="static", ident=3030, filename="a.png", time="2026-01-01T00:00:01.000000")
        hm2 = tr.Heightmap(z=np.array([[0.5, 1.0, 2.0]]), x_min=0.0, y_min=0.0, x_max=3.0, y_max=1.0, z_min=0.0)
        tr.store_heightmap(store, hm2, kind="static", ident=3030, filename="b.png", time="2026-01-01T00:00:02.000000")
        store.put_blob(b"not an image", filename="late.pcd", time="2026-01-01T00:00:09.000000", type="static", id=3030)
        doc, data = find_heightmap(store, "static")
        assert doc["filename"] == "b.png"  # the newest heightmap by time (the .pcd is newer, not a heightmap)
        assert tr.latest_heightmap(store, "static")[0]["filename"] == "b.png"
        doc, data = find_heightmap(store, "static", 3030, "a.png")
        mono = image_of(data, "mono16")
        assert (mono["encoding"], mono["width"], mono["height"], mono["step"]) == ("mono16", 3, 1, 6)
        assert np.frombuffer(mono["data"], "<u2").tolist() == [0, 4096, 10240]
        bgr = image_of(data)
        assert (bgr["encoding"], bgr["step"]) == ("bgr8", 9)
        assert np.frombuffer(bgr["data"], np.uint8).tolist() == [0, 0, 0, 16, 16, 16, 40, 40, 40]
        tex = io.BytesIO()
        Image.fromarray(np.array([[[255, 0, 10]]], dtype=np.uint8)).save(tex, format="PNG")
        assert np.frombuffer(image_of(tex.getvalue())["data"], np.uint8).tolist() == [10, 0, 255]  # RGB -> BGR
        with pytest.raises(RecordNotFound, match=r"no 'dynamic' terrain stored with id 3031"):
            find_heightmap(store, "dynamic", 3031)
        with pytest.raises(ValidationError, match=r"terrain type 'mesh': must be one of static, heightmap"):
            find_heightmap(store, "mesh")
        with pytest.raises(ValidationError, match=r"x.png: the stored file is not a PNG image"):
            image_of(b"not an image", source="x.png")
        with pytest.raises(ValidationError, match=r"image encoding 'rgb8'"):
            image_of(data, "rgb8")
    finally:
        store.close()


def test_dynamic_terrain_core_stores_scans_and_keeps_the_newest(tmp_path):
    store = open_store(path=tmp_path / "db")
    try:
        box = GridSpec(102.0, 201.0, 106.0, 205.0, 0.1)
        dyn = tr.DynamicTerrain(store, box, 0.1, 10.0, keep=2)
        pts = _mound_points(np.random.default_rng(4), spacing=0.1)
        # a dynamic point cloud as the original's tms_db_writer_gridfs stores it: same type and id, not a heightmap
        cloud = store.put_blob(b"0,0,128,63", filename=None, time="2026-01-01T00:00:00.500000", type="dynamic",
                               id=3031, height=1, width=1, point_step=4, row_step=4, is_bigendian=False,
                               is_dense=True, fields=[])
        ids = [dyn.on_points(pts, time=f"2026-01-01T00:00:0{k}.000000") for k in range(3)]
        assert cloud in [d["_id"] for d in store.find_blobs({"type": "dynamic"})]  # not pruned with the heightmaps
        store.delete_blob(cloud)
        docs = store.find_blobs({"type": "dynamic"})
        assert [d["_id"] for d in docs] == ids[1:] and dyn.written == 3
        d = docs[0]
        assert (d["id"], d["offset_x"], d["offset_y"], d["offset_z"]) == (3031, 102.0, 201.0, 10.0)
        hm = tr.heightmap_from_blob(store.get_blob(ids[-1]), docs[-1])
        assert (hm.cols, hm.rows) == (40, 40)
        assert hm.height_at(105.05, 203.05) == pytest.approx(_surface(105.05, 203.05), abs=0.03)
        with pytest.raises(tr.TerrainError, match=r"/scan: no point inside x \[102\.00, 106\.00\]"):
            dyn.on_points(pts + [50.0, 0.0, 0.0], source="/scan")
        with pytest.raises(tr.TerrainError, match=r"/scan: empty point cloud"):
            dyn.on_points(np.zeros((0, 3)), source="/scan")
        assert len(store.find_blobs({"type": "dynamic"})) == 2  # nothing stored by the refused scans
        with pytest.raises(tr.TerrainError, match=r"dynamic terrain: keep must be >= 1, got 0"):
            tr.DynamicTerrain(store, box, 0.1, 0.0, keep=0)
    finally:
        store.close()


def test_static_command_stores_a_png_placed_on_the_map_and_refuses_bad_files(tmp_path, capsys):
    from tms_sp.terrain_static import main

    png = tmp_path / "hm.png"
    Image.fromarray(np.full((3, 4), 8192, dtype=np.uint16)).save(png)
    db = tmp_path / "db"
    assert main([str(png), "--x-min", "5", "--y-min", "-2", "--size-x", "8", "--size-y", "6", "--z-min", "1",
                 "--db-path", str(db)]) == 0
    assert "static hm.png: 4 x 3 cells" in capsys.readouterr().out
    with open_store(path=db) as store:
        (doc,) = store.find_blobs({"type": "static"})
        assert (doc["height"], doc["width"], doc["elevation"], doc["offset_x"], doc["id"]) == (8.0, 6.0, 2.0, 5.0, 3030)
    assert main([str(tmp_path / "none.laz"), "--db-path", str(db)]) == 1
    assert "tms_ss_terrain_static: " in capsys.readouterr().err
    flat = tmp_path / "eight.png"
    Image.fromarray(np.zeros((3, 3), dtype=np.uint8)).save(flat)
    assert main([str(flat), "--db-path", str(db)]) == 1
    assert "eight.png: heightmap must be a 16-bit grayscale PNG, got mode L" in capsys.readouterr().err
    with open_store(path=db) as store:
        assert len(store.find_blobs({"type": "static"})) == 1
