"""Random target placement on the furniture's top surfaces, for generality runs.

A candidate spot is drawn uniformly over the furniture's footprints (weighted by area) with a
random yaw; it is kept when the surface under all four corners of the object's footprint is
level (within 1 cm: a real top, not a backrest or a vase) and lies between ``min_height`` and
``max_height`` (what a 1 m-high camera looking level can see).
"""

from __future__ import annotations

import math

import numpy as np

from twin.core.errors import TwinError
from twin.core.geometry import Pose2D
from twin.sim.world import World

LEVEL_TOLERANCE = 0.01  # metres


def random_surface_pose(
    world: World,
    body: str,
    rng: np.random.Generator,
    min_height: float = 0.3,
    max_height: float = 1.3,
    tries: int = 2000,
) -> Pose2D:
    """Move ``body`` to a random level spot on a furniture top; returns its new pose."""
    size = world.footprint(body).polygon
    half = 0.5 * (size.max(axis=0) - size.min(axis=0))
    radius = float(np.hypot(*half))
    tops = [world.footprint(name) for name in world.furniture()]
    areas = np.array([max(f.aabb[2] - f.aabb[0], 0) * max(f.aabb[3] - f.aabb[1], 0) for f in tops])
    for _ in range(tries):
        top = tops[rng.choice(len(tops), p=areas / areas.sum())]
        xmin, ymin, xmax, ymax = top.aabb
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        yaw = float(rng.uniform(-math.pi, math.pi))
        c, s = math.cos(yaw), math.sin(yaw)
        corners = [
            (x + c * dx - s * dy, y + s * dx + c * dy)
            for dx in (-half[0], half[0])
            for dy in (-half[1], half[1])
        ]
        heights = [world.surface_height(cx, cy, exclude=body) for cx, cy in [(x, y), *corners]]
        level = max(heights) - min(heights) <= LEVEL_TOLERANCE
        if level and min_height <= heights[0] <= max_height and _inside(top.polygon, corners):
            return world.place_static_body(body, x, y, yaw)
    raise TwinError(
        f"found no level spot for {body!r} (radius {radius:.2f} m) on the furniture "
        f"between {min_height} and {max_height} m in {tries} tries"
    )


def _inside(polygon: np.ndarray, points: list[tuple[float, float]]) -> bool:
    """Whether every point lies inside the convex, counter-clockwise ``polygon``."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    for px, py in points:
        rel = np.array([px, py]) - polygon
        if np.any(edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0] < 0):
            return False
    return True
