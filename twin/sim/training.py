"""Training views for the detector: the target alone, rendered with exact masks.

The views mimic the robot's camera: the same field of view and image size, looking at the target
from a given horizontal range and from ``camera_drop`` metres above its centre (0.4 m: the
robot's 1.0 m camera over a box standing on a 0.45 m coffee table). Masks come from MuJoCo's
segmentation rendering, so they are exact to the pixel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from twin.core.errors import InputError
from twin.sim.render import FrameRenderer
from twin.sim.world import World

DEFAULT_DISTANCES = (1.0, 1.5, 2.0, 3.0)
DEFAULT_ANGLES = tuple(2.0 * math.pi * k / 8 for k in range(8))


def training_views(
    distances: Sequence[float] = DEFAULT_DISTANCES,
    angles: Sequence[float] = DEFAULT_ANGLES,
    camera_drop: float = 0.4,
    target: str | None = None,
    scene: str = "training_stage",
    width: int = 320,
    height: int = 240,
) -> tuple[np.ndarray, np.ndarray]:
    """Render the target from every (distance, angle) pair.

    ``distances`` are horizontal ranges in metres; ``angles`` (radians) place the camera around
    the target, measured in the target's frame from its printed front (+x) counter-clockwise.
    Returns ``images`` (N, H, W, 3) uint8 RGB and ``masks`` (N, H, W) bool, N = distances x
    angles, distance-major.
    """
    if not distances or not angles:
        raise InputError("training_views needs at least one distance and one angle")
    for d in distances:
        if not (math.isfinite(d) and 0.2 <= d <= 10.0):
            raise InputError(f"training distance {d!r} m is outside [0.2, 10] m")
    if not (math.isfinite(camera_drop) and abs(camera_drop) < 3.0):
        raise InputError(f"camera_drop {camera_drop!r} m must be finite and within 3 m")
    world = World(scene)
    target = target or (world.targets() or (None,))[0]
    if target is None:
        raise InputError(f"scene {world.path.name} declares no target; pass target=")
    body = world.body_id(target)
    geoms = np.flatnonzero(world.model.geom_bodyid == body)
    centre = world.data.xpos[body].copy()
    yaw = world.body_pose(target).yaw

    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = centre
    images, masks = [], []
    with FrameRenderer(world.model, width, height) as renderer:
        for distance in distances:
            camera.distance = math.hypot(distance, camera_drop)
            camera.elevation = -math.degrees(math.atan2(camera_drop, distance))
            for angle in angles:
                # MuJoCo's azimuth is the direction the camera looks, in degrees
                camera.azimuth = math.degrees(yaw + angle + math.pi)
                images.append(renderer.render(world.data, camera))
                masks.append(np.isin(renderer.segment(world.data, camera), geoms))
    return np.stack(images), np.stack(masks)
