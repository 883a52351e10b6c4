"""Depth from the laser map, for a visibility model where there is no model of the room.

A real camera gives no depth and a robot without a scene file has only its occupancy map. The
map is one slice through the room, at the laser's height (0.3 m on the Peoplebot), so this treats
every occupied cell as an obstacle from the floor up to ``wall_height``: an honest fallback that
makes low furniture and table tops into walls (the camera is taken to see nothing past a sofa,
though it sees over it) and cannot know of anything the laser passes under. Free and unknown
cells are empty, the floor is a plane at height 0, and there is no ceiling. The depth image it
gives goes to ``twin.core.visibility.visibility_from_depth`` as a rendered one would.
"""

from __future__ import annotations

import math

import numpy as np

from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.nav.maps import OccupancyMap
from twin.nav.raycast import raycast

# Bearings cast per image column: a tilted camera's pixel rays turn away from their column's
# bearing with the row, so walls are found on a table this much finer than the columns, and
# each pixel takes the nearest entry (a few millimetres sideways at 5 m).
_BEARINGS_PER_COLUMN = 8


def depth_from_map(
    occupancy: OccupancyMap,
    camera: CameraModel,
    *,
    origin: tuple[float, float],
    axis: float,
    tilt: float,
    camera_height: float,
    wall_height: float = 2.0,
    max_range: float = 20.0,
) -> np.ndarray:
    """H x W float32 metres along each pixel's ray (row 0 at the top, NaN: nothing within
    ``max_range`` metres horizontally and no floor) to the floor or the first occupied cell,
    taken as a wall ``wall_height`` metres tall, for ``camera`` with its optical centre at
    ``origin`` (x, y metres) and ``camera_height`` metres up, its axis at bearing ``axis`` and
    elevation ``tilt`` (radians, positive up)."""
    for name, value in (("origin", origin[0]), ("origin", origin[1]), ("axis", axis)):
        if not math.isfinite(value):
            raise InputError(f"map depth {name} must be finite, got {value!r}")
    if not (math.isfinite(tilt) and abs(tilt) < math.pi / 2):
        raise InputError(f"map depth tilt must be within +-90 degrees, got {tilt!r} rad")
    if not (math.isfinite(wall_height) and 0.0 < camera_height < wall_height):
        raise InputError(
            f"map depth needs 0 < camera height ({camera_height!r} m) < wall height "
            f"({wall_height!r} m): a camera above the walls would see their tops, not modelled"
        )
    if not (math.isfinite(max_range) and max_range > 0):
        raise InputError(f"map depth max_range must be a positive distance, got {max_range!r}")

    height, width, focal = camera.height, camera.width, camera.focal_px
    # each pixel's ray in the camera frame: 1 ahead, `left` and `up` per unit ahead
    left = ((width / 2.0 - (np.arange(width) + 0.5)) / focal)[None, :]
    up = ((height / 2.0 - (np.arange(height) + 0.5)) / focal)[:, None]
    cos_t, sin_t = math.cos(tilt), math.sin(tilt)
    ahead_level = cos_t - up * sin_t  # (H, 1) horizontal part along the axis
    rise = sin_t + up * cos_t  # (H, 1) vertical part
    bearing = np.arctan2(left, ahead_level)  # (H, W) radians off the axis, positive left
    horizontal = np.hypot(left, ahead_level)  # (H, W) per unit of ray parameter
    length = np.sqrt(1.0 + left**2 + up**2)  # (H, W) metres of ray per unit of parameter

    lo, hi = float(bearing.min()), float(bearing.max())
    table = np.linspace(lo, hi, _BEARINGS_PER_COLUMN * width)
    walls = raycast(occupancy, Pose2D(origin[0], origin[1], axis), table, max_range)
    walls = np.where(np.isnan(walls), np.inf, walls)
    spacing = (hi - lo) / (table.size - 1) if hi > lo else 1.0
    wall = walls[np.clip(np.rint((bearing - lo) / spacing).astype(int), 0, table.size - 1)]

    with np.errstate(divide="ignore", invalid="ignore"):
        to_wall = wall / horizontal  # ray parameter at the wall, inf if none
        to_floor = np.where(rise < 0, camera_height / -np.minimum(rise, -1e-12), np.inf)
        # the ray meets a wall below its top, unless it reached the floor first
        over = camera_height + to_wall * rise > wall_height
        hit = np.minimum(to_floor, np.where(over, np.inf, to_wall))
    depth = np.where(np.isfinite(hit), hit * length, np.nan)
    return depth.astype(np.float32)
