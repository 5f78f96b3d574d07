"""The soil height field: its volumes follow every change of the grid."""

import numpy as np

from sim_bridge.config import load_plant
from sim_bridge.soil import HeightField


def test_volumes_follow_every_deposit_and_cut_though_they_are_cached():
    """The volumes are cached per grid version: each deposit and cut must show in them at once."""
    field = HeightField(load_plant(None).soil)

    def fresh() -> tuple[float, float]:
        return (float((field.h - field.datum).sum() * field.cell_area),
                float((field.h - field.spec.ground_z).sum() * field.cell_area))
    v0, g0, m0 = field.volume(), field.ground_soil_volume(), field.mound_volume()
    assert (v0, g0) == fresh()
    cx, cy = field.spec.mound_center
    field.deposit(cx, cy, 0.5, 0.6)
    assert np.isclose(field.volume() - v0, 0.5) and np.isclose(field.ground_soil_volume() - g0, 0.5)
    assert np.isclose(field.mound_volume() - m0, 0.5)
    removed = field.cut((cx - 1.0, cy), (cx + 1.0, cy), field.spec.ground_z, width=1.0, lateral=(0.0, 1.0),
                        max_volume=0.3)
    assert removed > 0.0
    assert (field.volume(), field.ground_soil_volume()) == fresh()
    assert np.isclose(field.mound_volume() - m0, 0.5 - removed)
