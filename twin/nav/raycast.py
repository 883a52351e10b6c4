"""Casting laser beams through an occupancy map: the ranges a scanner would read at a pose.

Mapping, scan matching and Monte Carlo localization all need the same two things: where the
scanner is, given the base pose and the ``LaserMount``, and what each beam would hit in a map.
``raycast`` answers the second exactly for the grid: a beam travels from the scanner through
the cells it crosses (Amanatides and Woo's traversal, compiled) and stops where it enters the
first occupied cell; the range is the distance to that cell's boundary. Beams that leave the map
or reach ``max_range`` first read NaN ("no return"), as a ``Scan`` does. ``simulate_scan`` wraps
it into a ``Scan`` with optional range noise, which is how the tests make synthetic scans.

Unknown cells let beams through by default (a map's unexplored space is not a wall); pass
``block_unknown=True`` to stop at them instead.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.nav.maps import UNKNOWN, OccupancyMap

LMS200_MAX_RANGE = 8.0  # metres, the Peoplebot's SICK LMS200 in its 8 m mode


def lms200_angles(beams: int = 181) -> np.ndarray:
    """Beam bearings (rad) of a 180 degree LMS200 scan: -pi/2 (right) .. +pi/2 (left), evenly
    spaced; 181 beams at 1 degree or 361 at 0.5 degree."""
    if beams < 2:
        raise InputError(f"a scan needs at least 2 beams, got {beams}")
    return np.linspace(-math.pi / 2.0, math.pi / 2.0, beams)


def laser_pose(base: Pose2D, mount: LaserMount) -> Pose2D:
    """The scanner's pose in the map frame for a base at ``base`` (the mount's x, y are metres
    forward and left of the base origin; its yaw turns the scanner's zero beam)."""
    return base.compose(Pose2D(mount.x, mount.y, mount.yaw))


def scan_points_in_base(scan: Scan, mount: LaserMount) -> np.ndarray:
    """(k, 2) returns of ``scan`` in metres in the base frame (x forward, y left)."""
    points = scan.points()
    c, s = math.cos(mount.yaw), math.sin(mount.yaw)
    x = c * points[:, 0] - s * points[:, 1] + mount.x
    y = s * points[:, 0] + c * points[:, 1] + mount.y
    return np.stack([x, y], axis=1)


def raycast(
    occupancy_map: OccupancyMap,
    sensor: Pose2D,
    angles: np.ndarray,
    max_range: float,
    *,
    block_unknown: bool = False,
) -> np.ndarray:
    """Ranges (m) of beams at ``angles`` (rad, counter-clockwise from the sensor's heading) from
    a sensor at ``sensor`` (map frame) to the first occupied cell; NaN where a beam leaves the map
    or travels ``max_range`` metres without one. A sensor inside an occupied cell reads 0."""
    if not (math.isfinite(max_range) and max_range > 0):
        raise InputError(f"max_range must be a positive number of metres, got {max_range!r}")
    blocked = occupancy_map.occupied
    if block_unknown:
        blocked = blocked | (occupancy_map.occupancy == UNKNOWN)
    bearings = np.asarray(angles, dtype=float) + sensor.yaw
    out = np.empty(bearings.shape[0])
    x0, y0, _ = occupancy_map.origin
    _cast_rays(
        np.ascontiguousarray(blocked),
        x0,
        y0,
        occupancy_map.resolution,
        sensor.x,
        sensor.y,
        bearings,
        max_range,
        out,
    )
    return out


def simulate_scan(
    occupancy_map: OccupancyMap,
    base: Pose2D,
    mount: LaserMount | None = None,
    angles: np.ndarray | None = None,
    max_range: float = LMS200_MAX_RANGE,
    *,
    noise_m: float = 0.0,
    rng: np.random.Generator | None = None,
    timestamp: float = 0.0,
) -> Scan:
    """The ``Scan`` a laser on ``mount`` would read with the base at ``base``: ray-cast ranges
    plus Gaussian noise of ``noise_m`` metres (needs ``rng``), NaN for no return."""
    mount = mount or LaserMount()
    angles = lms200_angles() if angles is None else np.asarray(angles, dtype=float)
    ranges = raycast(occupancy_map, laser_pose(base, mount), angles, max_range)
    if noise_m > 0.0:
        if rng is None:
            raise InputError("range noise needs an explicit numpy Generator (rng)")
        ranges = ranges + rng.normal(0.0, noise_m, size=ranges.shape)
        ranges[(ranges < 0.0) | (ranges >= max_range)] = np.nan
    return Scan(angles=angles, ranges=ranges, timestamp=timestamp, max_range=max_range)


@njit(cache=True)
def clip_to_grid(
    gx: float, gy: float, dx: float, dy: float, nx: int, ny: int, t_end: float
) -> tuple[float, float]:
    """The part [t0, t1] of the ray (gx, gy) + t (dx, dy), 0 <= t <= t_end, inside the grid
    [0, nx] x [0, ny] (cell units); t0 > t1 when it misses the grid."""
    t0, t1 = 0.0, t_end
    if dx != 0.0:
        ta, tb = (0.0 - gx) / dx, (nx - gx) / dx
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    elif not 0.0 <= gx < nx:
        return 1.0, 0.0
    if dy != 0.0:
        ta, tb = (0.0 - gy) / dy, (ny - gy) / dy
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    elif not 0.0 <= gy < ny:
        return 1.0, 0.0
    return t0, t1


@njit(cache=True, inline="always")
def first_boundary(g: float, d: float, cell: int) -> tuple[float, float, int]:
    """For a ray coordinate at g (cells) moving by d per unit t in cell ``cell``: the t of the
    next cell boundary, the t between boundaries, and the step (+1 or -1; 0 when d == 0)."""
    if d > 0.0:
        return (cell + 1.0 - g) / d, 1.0 / d, 1
    if d < 0.0:
        return (cell - g) / d, -1.0 / d, -1
    return np.inf, np.inf, 0


@njit(cache=True)
def _cast_rays(blocked, x0, y0, res, sx, sy, bearings, max_range, out):
    ny, nx = blocked.shape
    gx, gy = (sx - x0) / res, (sy - y0) / res
    t_end = max_range / res
    for k in range(bearings.shape[0]):
        out[k] = np.nan
        dx, dy = math.cos(bearings[k]), math.sin(bearings[k])
        t0, t1 = clip_to_grid(gx, gy, dx, dy, nx, ny, t_end)
        if t0 > t1:
            continue
        ix = min(max(math.floor(gx + t0 * dx), 0), nx - 1)
        iy = min(max(math.floor(gy + t0 * dy), 0), ny - 1)
        tx, step_tx, sx_ = first_boundary(gx + t0 * dx, dx, ix)
        ty, step_ty, sy_ = first_boundary(gy + t0 * dy, dy, iy)
        tx += t0
        ty += t0
        t = t0
        while True:
            if blocked[iy, ix]:
                out[k] = t * res
                break
            if tx < ty:
                t = tx
                ix += sx_
                tx += step_tx
            else:
                t = ty
                iy += sy_
                ty += step_ty
            if t > t1 or ix < 0 or ix >= nx or iy < 0 or iy >= ny:
                break
