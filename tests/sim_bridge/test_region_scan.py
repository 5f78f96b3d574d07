"""The scan of a rectangle (a design's work area): it samples the fine patch where there is one, the coarse grid
elsewhere, and the plant node's region parameters are checked with errors naming them."""

import numpy as np
import pytest

from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.nodes.sim_plant import SimPlantNode
from sim_bridge.scanners import ScanRegion, region_scan
from sim_bridge.soil import HeightField
from tms_common.config import config_path


@pytest.fixture(scope="module")
def field():
    return HeightField(load_plant(config_path("sim", "design_plant.yaml")).soil)


def test_region_scan_reads_fine_patch_steps_that_the_coarse_grid_averages_away(field):
    f = field.fine
    assert f is not None and f.res == pytest.approx(0.05)
    # a 5 cm wide, 0.3 m deep slot in the patch: one fine column, a quarter of a coarse cell
    col = int(round((-5.0 - f.x0) / f.res))
    f.h[:, col] -= 0.3
    field._sync(slice(0, f.ny), slice(0, f.nx))
    pts = region_scan(field, ScanRegion(-6.0, -1.0, -4.0, 1.0, 0.05), noise=0.0, rng=np.random.default_rng(0))
    assert pts.shape == (40 * 40, 3)
    in_slot = np.isclose(pts[:, 0], -5.0 + 0.025)
    assert in_slot.sum() == 40
    assert np.allclose(pts[in_slot, 2], -0.3)  # the fine cell's height, not the coarse block mean (-0.075)
    assert np.allclose(pts[~in_slot, 2], 0.0)
    f.h[:, col] += 0.3
    field._sync(slice(0, f.ny), slice(0, f.nx))


def test_region_scan_outside_the_patch_reads_coarse_cells_and_clips_to_the_grid(field):
    g = field
    pts = region_scan(g, ScanRegion(g.x0 - 1.0, g.y0 - 1.0, g.x0 + 0.4, g.y0 + 0.4, 0.2), noise=0.0,
                      rng=np.random.default_rng(0))
    assert len(pts) == 4  # only the 2 x 2 points inside the grid
    assert pts[:, 0].min() >= g.x0 and pts[:, 1].min() >= g.y0


def test_region_scan_noise_and_bad_regions(field):
    pts = region_scan(field, ScanRegion(-6.0, -6.0, -4.0, 6.0, 0.05), noise=0.02, rng=np.random.default_rng(3))
    assert float(np.std(pts[:, 2])) == pytest.approx(0.02, rel=0.1)
    with pytest.raises(ValueError, match="empty rectangle"):
        region_scan(field, ScanRegion(0.0, 0.0, -1.0, 1.0, 0.05), noise=0.0, rng=np.random.default_rng(0))
    assert "spacing must be > 0" in ScanRegion(0.0, 0.0, 1.0, 1.0, 0.0).problem()
    assert ScanRegion(0.0, 0.0, 1.0, 1.0, 0.1).problem() is None


class _Value:
    def __init__(self, value):
        self.value = value


def _params(**given):
    return lambda name, default: _Value(given.get(name, default))


def test_plant_region_parameters_default_to_none_and_name_the_parameter_when_wrong():
    assert SimPlantNode._region_parameters(_params()) == (None, 0.0)
    region, period = SimPlantNode._region_parameters(_params(region_scan=[-8.0, -8.0, -2.0, 8.0],
                                                             region_scan_period_s=2.0))
    assert region == ScanRegion(-8.0, -8.0, -2.0, 8.0, 0.05) and period == 2.0
    with pytest.raises(SimConfigError, match="region_scan: \\[x_min"):
        SimPlantNode._region_parameters(_params(region_scan=[1.0, 2.0]))
    with pytest.raises(SimConfigError, match="region_scan / region_scan_spacing: empty rectangle"):
        SimPlantNode._region_parameters(_params(region_scan=[1.0, 2.0, 0.0, 3.0]))
    with pytest.raises(SimConfigError, match="region_scan_period_s"):
        SimPlantNode._region_parameters(_params(region_scan=[0.0, 0.0, 1.0, 1.0], region_scan_period_s=-1.0))
