"""Offscreen rendering of the site to PNG (for reports), when an OpenGL backend is available.

MuJoCo needs a GL context: ``MUJOCO_GL=egl`` (headless GPU/Mesa EGL, the default chosen here when
the variable is unset) or ``osmesa``. Without one, :func:`render_png` raises
:class:`~sim_bridge.errors.SimError` saying so; the plant itself never needs a display.
"""

from __future__ import annotations

import os

# MuJoCo picks its GL backend when it is first imported: offscreen unless the caller chose one
os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path

import mujoco

from sim_bridge.errors import SimError
from sim_bridge.plant import Plant

__all__ = ["render_png", "render_rgb"]


def render_rgb(plant: Plant, *, width: int = 960, height: int = 540, lookat=(8.0, 2.0, 0.0), distance: float = 38.0,
               azimuth: float = -60.0, elevation: float = -35.0):  # numpy image
    """An RGB image (H x W x 3, uint8) of the site with the current terrain, machines and soil."""
    site = plant.model
    site.set_terrain(plant.ground.h, plant.spec.soil.ground_z)
    try:
        renderer = mujoco.Renderer(site.model, height, width)
    except Exception as exc:  # MuJoCo raises several GL error types
        raise SimError(f"offscreen rendering not available (MUJOCO_GL={os.environ['MUJOCO_GL']}): {exc}") from exc
    try:
        cam = mujoco.MjvCamera()
        cam.lookat[:] = lookat
        cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
        renderer.update_scene(site.data, camera=cam)
        return renderer.render()
    finally:
        renderer.close()


def render_png(plant: Plant, path: str | Path, **view) -> Path:  # forwarded to render_rgb
    """Render the site and write a PNG; returns the path."""
    import matplotlib.image  # third-party, slow to import: only when a snapshot is written

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(path, render_rgb(plant, **view))
    return path
