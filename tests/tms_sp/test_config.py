"""tms_sp.config: machines by site name, their facts from their kinds' descriptions, written once."""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

import tms_db
from tests.tms_sp.treeutil import ROOT
from tms_common.errors import ConfigError
from tms_db.cli import seed
from tms_model.fleet import load_named, machine_kind
from tms_model.machines import CRAWLER_DUMP
from tms_model.site import load_site
from tms_sp.config import load_sensing_config
from tms_sp.processor import SiteSensing

SENSING_YAML = yaml.safe_load((ROOT / "config" / "tms_sp" / "sensing.yaml").read_text())


def _site_carriers() -> list[str]:
    site = load_site()
    return [n for n in site.machines if load_named(n, site=site).type == CRAWLER_DUMP]


def test_each_carrier_of_the_site_senses_its_own_kinds_vessel():
    carriers = _site_carriers()
    kinds = {machine_kind(c) for c in carriers}
    assert {"ic120", "mst110cr"} <= kinds  # an MST and the IC120 among them
    cfg = load_sensing_config(carriers=carriers)
    assert cfg.carriers == tuple(carriers)
    for c in carriers:
        g, m = cfg.vessels[c], load_named(c)
        assert (g.inner_length, g.inner_width, g.capacity, g.hinge_xyz, g.floor_above_hinge, g.rim_above_hinge) == (
            m.vessel.inner_length, m.vessel.inner_width, m.vessel.capacity, m.vessel.hinge_xyz,
            m.vessel.floor_above_hinge, m.vessel.rim_above_hinge), c
    ic, mst = cfg.vessels["ic120_1"], cfg.vessels["mst110cr_2"]
    # the MST's vessel is not the IC120's: size, hinge, floor and rim all its own
    assert ic.inner_width != mst.inner_width and ic.capacity != mst.capacity and ic.hinge_xyz != mst.hinge_xyz
    assert ic.floor_above_hinge != mst.floor_above_hinge and ic.rim_above_hinge != mst.rim_above_hinge
    assert cfg.vessels["ic120_2"] == ic == cfg.vessel_geometry("ic120")  # one kind, one vessel


def test_sensing_switches_to_the_vessel_of_the_carrier_it_follows(tmp_path):
    """The release point over a carrier is computed on that carrier's own vessel (floor height and hinge)."""
    cfg = dataclasses.replace(load_sensing_config(carriers=["ic120_1", "mst110cr_2"]),
                              blackboard_records=("GLOBAL_BLACKBOARD_FLEET",))
    store = tms_db.open_store(path=tmp_path / "db")
    seed(store, ROOT / "config" / "seeds" / "fleet.yaml")
    sensing = SiteSensing(cfg, store)
    assert sensing.carrier == "ic120_1" and sensing.vessel_geom == cfg.vessels["ic120_1"]
    p1 = cfg.points[cfg.arrival_point]
    heights = {}
    for carrier in ("ic120_1", "mst110cr_2"):
        sensing.select_carrier(carrier)
        g = sensing.vessel_geom
        assert g == cfg.vessels[carrier]
        spec = g.grid_spec(cfg.resolution)
        xg, yg = spec.centres()
        empty = np.column_stack([xg.ravel(), yg.ravel(), np.zeros(xg.size)])
        sensing.on_carrier_pose(0.0, p1)
        v = sensing.on_vessel_points(empty)
        assert v.volume == pytest.approx(0.0, abs=1e-9)
        pose = store.get_parameter(cfg.excavator, cfg.release_record)
        # tip height in the excavator's frame (base at the map origin, flat site): hinge + rim + clearance
        heights[carrier] = pose["z"]
        assert pose["z"] == pytest.approx(g.hinge_xyz[2] + g.rim_above_hinge + cfg.vessel.clearance)
    assert heights["ic120_1"] != heights["mst110cr_2"]


def test_the_bucket_width_is_the_excavators_description():
    cfg = load_sensing_config()
    bucket = load_named(cfg.excavator).bucket
    assert cfg.excavation.bucket_radius == bucket.width / 2 and cfg.excavation.bucket_volume == bucket.capacity
    assert "bucket_radius" not in SENSING_YAML["excavation"]


def test_names_from_yaml_or_parameters(tmp_path: Path):
    # the ZX120 has no planner file (config/tms_rp/<kind>_planner.yaml): sensing writes it no approach record
    sensing = tmp_path / "sensing.yaml"
    sensing.write_text(re.sub(r"(?m)^  approach_record: .*$", "  approach_record: null",
                              (ROOT / "config" / "tms_sp" / "sensing.yaml").read_text()))
    cfg = load_sensing_config(sensing, excavator="zx120", carriers=["mst2200"])
    assert cfg.excavator == "zx120" and cfg.carriers == ("mst2200",)
    assert cfg.vessel_geom.capacity == load_named("mst2200").vessel.capacity
    assert cfg.excavation.bucket_volume == load_named("zx120").bucket.capacity
    default = load_sensing_config()
    assert (default.excavator, default.carriers) == (SENSING_YAML["excavator"], tuple(SENSING_YAML["carriers"]))
    # with an approach record, the excavator's planner gives its height: no planner file, no sensing
    with pytest.raises(ConfigError, match=r"sensing.yaml:\d+: excavation.approach_record: .*zx120_planner.yaml"):
        load_sensing_config(excavator="zx120", carriers=["mst2200"])


def test_no_machine_name_or_kind_in_the_packages_code_strings():
    """Names come from parameters and config files: no string literal in tms_sp names a site machine or kind
    (docstrings may, as prose)."""
    site = load_site()
    words = sorted({*site.machines, *(m.kind for m in site.machines.values())}, key=len, reverse=True)
    pattern = re.compile(r"(?<![A-Za-z0-9])(" + "|".join(map(re.escape, words)) + r")(?![A-Za-z0-9])")
    found = []
    for path in sorted((ROOT / "tms_sp").rglob("*.py")):
        tree = ast.parse(path.read_text())
        docs = {id(n.body[0].value) for n in ast.walk(tree)
                if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
                if pattern.search(node.value):
                    found.append(f"{Path(path).relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert not found, "\n".join(found)
