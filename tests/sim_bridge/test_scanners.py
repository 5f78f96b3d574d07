"""Simulated soil scans: the mound scan sees the mound's volume, the vessel scan the load volume."""

import numpy as np
import pytest

from sim_bridge.config import load_plant
from sim_bridge.scanners import mound_scan, pack_xyz, vessel_scan
from sim_bridge.soil import HeightField


def test_mound_scan_integrates_to_the_mound_volume():
    spec = load_plant(None)
    field = HeightField(spec.soil)
    rng = np.random.default_rng(0)
    spacing = 0.2
    pts = mound_scan(
        field, spec.soil.mound_center, spec.soil.mound_base_radius + 1.0, noise=0.0, rng=rng, spacing=spacing
    )
    assert pts.shape[1] == 3 and len(pts) > 500
    volume = float((pts[:, 2] - spec.soil.ground_z).sum()) * spacing**2
    assert volume == pytest.approx(field.mound_volume(), rel=0.05)


def test_vessel_scan_is_an_even_layer_of_the_load_volume_and_packs_to_float32():
    rng = np.random.default_rng(1)
    pts = vessel_scan(2.0, 3.6, 1.75, noise=0.0, rng=rng)
    assert float(pts[:, 2].mean()) * 3.6 * 1.75 == pytest.approx(2.0, rel=0.01)
    assert abs(pts[:, 0]).max() < 1.8 and abs(pts[:, 1]).max() < 0.875
    data, n = pack_xyz(pts)
    assert n == len(pts) and len(data) == 12 * n
