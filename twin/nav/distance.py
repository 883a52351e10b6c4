"""Exact Euclidean distance transforms of grid masks: the field both localizer and planner need.

The likelihood-field measurement model (Thrun, Burgard & Fox, *Probabilistic Robotics*, 6.4)
asks, for a beam's end point, how far the nearest obstacle is; the planner inflates obstacles by
the robot's radius. Both read one field: for every cell the distance from its centre to the
centre of the nearest obstacle cell. It is computed exactly in O(cells) by Felzenszwalb and
Huttenlocher's lower envelope of parabolas (*Distance Transforms of Sampled Functions*, 2012),
once along the columns and once along the rows, compiled by numba.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from twin.core.errors import InputError
from twin.nav.maps import OccupancyMap


@njit(cache=True)
def _envelope_1d(f: np.ndarray, out: np.ndarray, v: np.ndarray, z: np.ndarray) -> None:
    """out[q] = min_p (q - p)^2 + f[p] over the finite f[p]; inf everywhere if none is finite.

    ``v`` (n,) and ``z`` (n + 1,) are scratch: the parabolas of the lower envelope and the
    boundaries between them. Infinite samples are left out of the envelope (their parabolas
    are never the minimum), which keeps inf - inf out of the intersection formula.
    """
    n = f.shape[0]
    k = -1
    for q in range(n):
        fq = f[q]
        if fq == np.inf:
            continue
        if k < 0:
            k = 0
            v[0] = q
            z[0] = -np.inf
            z[1] = np.inf
            continue
        while True:
            p = v[k]
            s = ((fq + q * q) - (f[p] + p * p)) / (2.0 * (q - p))
            if s > z[k]:
                break
            k -= 1  # z[0] is -inf, so k never drops below 0
        k += 1
        v[k] = q
        z[k] = s
        z[k + 1] = np.inf
    if k < 0:
        for q in range(n):
            out[q] = np.inf
        return
    j = 0
    for q in range(n):
        while z[j + 1] < q:
            j += 1
        p = v[j]
        out[q] = (q - p) * (q - p) + f[p]


@njit(cache=True)
def squared_distance_cells(mask: np.ndarray) -> np.ndarray:
    """(ny, nx) squared distance, in cells², from each cell to the nearest True cell of
    ``mask``; inf everywhere if the mask holds no True cell."""
    ny, nx = mask.shape
    n = max(ny, nx)
    v = np.empty(n, dtype=np.int64)
    z = np.empty(n + 1)
    line = np.empty(n)
    result = np.empty(n)
    columns = np.empty((ny, nx))
    for c in range(nx):
        for r in range(ny):
            line[r] = 0.0 if mask[r, c] else np.inf
        _envelope_1d(line[:ny], result[:ny], v, z)
        for r in range(ny):
            columns[r, c] = result[r]
    out = np.empty((ny, nx))
    for r in range(ny):
        _envelope_1d(columns[r], out[r], v, z)
    return out


def distance_transform(mask: np.ndarray, resolution: float = 1.0) -> np.ndarray:
    """Exact Euclidean distance (in units of ``resolution``, e.g. metres) from every cell centre
    to the nearest centre of a True cell of ``mask`` (0 on True cells, inf if there are none)."""
    grid = np.asarray(mask)
    if grid.ndim != 2 or min(grid.shape) < 1:
        raise InputError(f"a distance transform needs a 2-D mask, got shape {grid.shape}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(f"the distance transform's resolution must be positive, got {resolution}")
    squared = squared_distance_cells(np.ascontiguousarray(grid, dtype=np.bool_))
    return np.sqrt(squared) * resolution


def obstacle_mask(occupancy_map: OccupancyMap, unknown_is_obstacle: bool = False) -> np.ndarray:
    """(ny, nx) bool: the map's occupied cells, and its unknown ones if asked."""
    mask = occupancy_map.occupied
    return mask | occupancy_map.unknown if unknown_is_obstacle else mask


def obstacle_distance(occupancy_map: OccupancyMap, unknown_is_obstacle: bool = False) -> np.ndarray:
    """(ny, nx) metres from each cell centre to the centre of the nearest obstacle cell.

    With ``unknown_is_obstacle=False`` this is the likelihood field's distance and can be handed
    to both ``MonteCarloLocalizer`` and ``PathPlanner`` (``distance=``) so a map is transformed
    once.
    """
    mask = obstacle_mask(occupancy_map, unknown_is_obstacle)
    return distance_transform(mask, occupancy_map.resolution)


def signed_surface_distance(
    occupancy_map: OccupancyMap, distance: np.ndarray | None = None
) -> np.ndarray:
    """(ny, nx) metres from each cell centre to the nearest edge between occupied and other
    cells: positive outside obstacles, negative inside them (centres next to an edge read
    ±resolution/2).

    Why not the plain distance to occupied centres: read between cell centres, that field is
    flat across a whole occupied cell and rises only half a cell out, so a scan whose end points
    sit on a wall's face prefers the pose that pushes them half a cell into it. This field
    crosses zero on the face itself. ``distance`` may pass ``obstacle_distance(map)``.
    """
    occupied = occupancy_map.occupied
    half = occupancy_map.resolution / 2.0
    if distance is None:
        distance = distance_transform(occupied, occupancy_map.resolution)
    inside = distance_transform(~occupied, occupancy_map.resolution)
    return np.where(occupied, half - inside, distance - half)
