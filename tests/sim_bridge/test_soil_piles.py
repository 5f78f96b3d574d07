"""Soil piles at the start (the plant YAML's ``soil.piles``): the truncated cone's heights on the coarse grid and in
the fine patch, its volume against the cone's formula, and a malformed pile refused naming its key."""

import math

import numpy as np
import pytest
import yaml

from sim_bridge.config import load_plant
from sim_bridge.errors import SimConfigError
from sim_bridge.soil import HeightField
from tms_common.config import config_path, load_yaml

PLANT = config_path("sim", "design_embankment_plant.yaml")


def _frustum(base: float, top: float, height: float) -> float:
    return math.pi * height / 3.0 * (base * base + base * top + top * top)


def test_the_embankment_plant_has_its_pile_in_the_fine_patch_and_on_the_coarse_grid():
    spec = load_plant(PLANT)
    (pile,) = spec.soil.piles
    field = HeightField(spec.soil)
    bare = HeightField(load_plant(config_path("sim", "design_plant.yaml")).soil)
    # the same site without the pile: what the pile adds is the frustum's volume, to the grids' sampling error
    added = field.volume() - bare.volume()
    assert added == pytest.approx(_frustum(pile.base_radius, pile.top_radius, pile.height), rel=0.01)
    # heights by hand: the flat top, halfway down the slope, beyond the toe (the patch is 0.05 m: cell centres
    # within 0.025 m of the point)
    slope = pile.height / (pile.base_radius - pile.top_radius)
    assert field.height(pile.x, pile.y) == pytest.approx(pile.height)
    mid = (pile.base_radius + pile.top_radius) / 2.0
    assert field.height(pile.x + mid, pile.y) == pytest.approx(pile.height / 2.0, abs=0.03 * slope + 1e-6)
    assert field.height(pile.x, pile.y + pile.base_radius + 0.1) == pytest.approx(0.0)
    # the coarse view over the patch is the block mean: the pile shows there too
    row, col = int(np.argmin(np.abs(field.ys - pile.y))), int(np.argmin(np.abs(field.xs - pile.x)))
    assert field.h[row, col] == pytest.approx(pile.height)


@pytest.mark.parametrize("change, key", [({"top_radius": 3.0}, "piles"), ({"height": -0.1}, "height")])
def test_a_malformed_pile_is_refused_naming_its_key(tmp_path, change, key):
    data, _ = load_yaml(PLANT)
    data["soil"]["piles"][0].update(change)
    data["site"] = str(config_path(data["site"]))
    data["machines"] = {k: str(config_path(v)) for k, v in data["machines"].items()}
    path = tmp_path / "plant.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(SimConfigError, match=key):
        load_plant(path)
