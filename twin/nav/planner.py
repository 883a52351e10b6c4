"""Path planning on an occupancy map: inflate obstacles, A* on the grid, straighten the path.

* **Inflation**: a cell is blocked when its centre is closer than the robot's ``radius`` plus a
  ``margin`` to an obstacle's face, read from the exact distance transform the localizer's
  likelihood field also uses (``twin.nav.distance``: distance between cell centres, less half a
  cell to reach the obstacle cell's face). Occupied cells are obstacles; unknown cells too
  unless ``unknown_is_obstacle=False``; beyond the map nothing is passable.
* **Search**: A* over the 8-connected grid (steps of 1 and sqrt 2 cells, octile heuristic), never
  cutting a corner between two cells of which one is blocked; compiled by numba with a binary
  heap.
* **Straightening**: from each waypoint the path is followed as far as a straight line stays on
  unblocked cells (every cell the segment touches, both at a corner crossing), so a path becomes
  a few legs. A point inside an unblocked cell may lie up to a cell's half-diagonal closer to an
  obstacle than the cell's centre: legs keep ``radius + margin - 0.91 resolution`` from obstacle
  cells, so a margin of one cell keeps the robot's radius clear (``leg_is_clear`` checks that
  exactly).

Coordinates at the API are metres in the map frame; errors a caller can cause are one line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numba import njit

from twin.core.errors import InputError, TwinError
from twin.core.geometry import Pose2D, require_finite
from twin.nav.distance import obstacle_distance, obstacle_mask
from twin.nav.maps import OccupancyMap

SQRT2 = math.sqrt(2.0)
Point = Pose2D | Sequence[float] | np.ndarray


class NoPathError(TwinError):
    """Start and goal lie in separate regions of the inflated map."""


@dataclass(frozen=True)
class Path:
    """A planned path: ``waypoints`` (k, 2) metres, start first and goal last, joined by
    straight legs; ``cells`` (n, 2) the A* path as (row, col) before straightening."""

    waypoints: np.ndarray
    cells: np.ndarray

    @property
    def length(self) -> float:
        """Metres along the legs."""
        return float(np.sum(np.hypot(*np.diff(self.waypoints, axis=0).T)))

    @property
    def legs(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The straight legs as ((x0, y0), (x1, y1)) pairs in metres."""
        points = [(float(x), float(y)) for x, y in self.waypoints]
        return list(pairwise(points))


# -- compiled kernels ------------------------------------------------------------------------


@njit(cache=True, inline="always")
def _heap_push(keys: np.ndarray, nodes: np.ndarray, size: int, key: float, node: int) -> int:
    i = size
    keys[i] = key
    nodes[i] = node
    while i > 0:
        parent = (i - 1) >> 1
        if keys[parent] <= keys[i]:
            break
        keys[i], keys[parent] = keys[parent], keys[i]
        nodes[i], nodes[parent] = nodes[parent], nodes[i]
        i = parent
    return size + 1


@njit(cache=True, inline="always")
def _heap_pop(keys: np.ndarray, nodes: np.ndarray, size: int) -> tuple[int, int]:
    """Remove the smallest key; returns (its node, the new size)."""
    top = nodes[0]
    size -= 1
    keys[0] = keys[size]
    nodes[0] = nodes[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        child = left
        if left + 1 < size and keys[left + 1] < keys[left]:
            child = left + 1
        if keys[i] <= keys[child]:
            break
        keys[i], keys[child] = keys[child], keys[i]
        nodes[i], nodes[child] = nodes[child], nodes[i]
        i = child
    return top, size


@njit(cache=True, inline="always")
def _octile(r: int, c: int, goal_r: int, goal_c: int) -> float:
    dr = abs(goal_r - r)
    dc = abs(goal_c - c)
    return max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True)
def _expand(
    blocked: np.ndarray, start_r: int, start_c: int, goal_r: int, goal_c: int
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Best-first search over the 8-connected grid of unblocked cells from the start: A* to the
    goal (octile heuristic), or, with ``goal_r < 0``, Dijkstra over every reachable cell.
    Returns (cost in cells per flat index, parent per flat index, goal reached). Diagonal steps
    need both side cells unblocked."""
    ny, nx = blocked.shape
    total = ny * nx
    g = np.full(total, np.inf)
    parent = np.full(total, -1, dtype=np.int64)
    closed = np.zeros(total, dtype=np.bool_)
    keys = np.empty(8 * total + 1)
    nodes = np.empty(8 * total + 1, dtype=np.int64)
    start = start_r * nx + start_c
    goal = goal_r * nx + goal_c if goal_r >= 0 else -1
    # a hair of weight on the heuristic breaks ties towards the goal (far fewer expansions)
    tie = 1.0 + 1e-6 if goal >= 0 else 0.0
    g[start] = 0.0
    size = _heap_push(keys, nodes, 0, tie * _octile(start_r, start_c, goal_r, goal_c), start)
    found = False
    while size > 0:
        node, size = _heap_pop(keys, nodes, size)
        if closed[node]:
            continue
        if node == goal:
            found = True
            break
        closed[node] = True
        r = node // nx
        c = node - r * nx
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dr == 0 and dc == 0:
                    continue
                rr = r + dr
                cc = c + dc
                if rr < 0 or rr >= ny or cc < 0 or cc >= nx or blocked[rr, cc]:
                    continue
                step = 1.0
                if dr != 0 and dc != 0:
                    if blocked[r, cc] or blocked[rr, c]:
                        continue
                    step = SQRT2
                neighbour = rr * nx + cc
                if closed[neighbour]:
                    continue
                cost = g[node] + step
                if cost < g[neighbour]:
                    g[neighbour] = cost
                    parent[neighbour] = node
                    key = cost + tie * _octile(rr, cc, goal_r, goal_c)
                    size = _heap_push(keys, nodes, size, key, neighbour)
    return g, parent, found


@njit(cache=True)
def astar(blocked: np.ndarray, start_r: int, start_c: int, goal_r: int, goal_c: int) -> np.ndarray:
    """Shortest 8-connected path of unblocked cells from start to goal, (n, 2) (row, col) from
    start to goal, or (0, 2) if there is none. Diagonal steps need both side cells unblocked."""
    nx = blocked.shape[1]
    _, parent, found = _expand(blocked, start_r, start_c, goal_r, goal_c)
    if not found:
        return np.empty((0, 2), dtype=np.int64)
    start = start_r * nx + start_c
    goal = goal_r * nx + goal_c
    count = 1
    node = goal
    while node != start:
        node = parent[node]
        count += 1
    path = np.empty((count, 2), dtype=np.int64)
    node = goal
    for k in range(count - 1, -1, -1):
        path[k, 0] = node // nx
        path[k, 1] = node % nx
        node = parent[node]
    return path


@njit(cache=True)
def grid_distances(blocked: np.ndarray, start_r: int, start_c: int) -> np.ndarray:
    """(ny, nx) length in cells of the shortest 8-connected path of unblocked cells from the
    start to every cell (the same moves as ``astar``); inf where none reaches."""
    g, _, _ = _expand(blocked, start_r, start_c, -1, -1)
    return g.reshape(blocked.shape)


@njit(cache=True, inline="always")
def _free(blocked: np.ndarray, r: int, c: int) -> bool:
    return 0 <= r < blocked.shape[0] and 0 <= c < blocked.shape[1] and not blocked[r, c]


@njit(cache=True)
def segment_clear(blocked: np.ndarray, u0: float, v0: float, u1: float, v1: float) -> bool:
    """Whether every cell a segment touches is unblocked; (u, v) are continuous cell
    coordinates (cell (r, c) spans u in [c, c + 1), v in [r, r + 1)). Where the segment passes
    exactly through a cell corner, both side cells count (a robot cannot slip between them)."""
    c = math.floor(u0)
    r = math.floor(v0)
    c_end = math.floor(u1)
    r_end = math.floor(v1)
    if not _free(blocked, r, c) or not _free(blocked, r_end, c_end):
        return False
    du = u1 - u0
    dv = v1 - v0
    step_c = 1 if du > 0 else -1
    step_r = 1 if dv > 0 else -1
    if du != 0.0:
        delta_c = abs(1.0 / du)
        next_c = ((c + 1 - u0) if du > 0 else (u0 - c)) * delta_c
    else:
        delta_c = np.inf
        next_c = np.inf
    if dv != 0.0:
        delta_r = abs(1.0 / dv)
        next_r = ((r + 1 - v0) if dv > 0 else (v0 - r)) * delta_r
    else:
        delta_r = np.inf
        next_r = np.inf
    for _ in range(abs(c_end - c) + abs(r_end - r)):
        if r == r_end and c == c_end:
            break
        if abs(next_c - next_r) <= 1e-12:
            if not _free(blocked, r, c + step_c) or not _free(blocked, r + step_r, c):
                return False
            c += step_c
            r += step_r
            next_c += delta_c
            next_r += delta_r
        elif next_c < next_r:
            c += step_c
            next_c += delta_c
        else:
            r += step_r
            next_r += delta_r
        if not _free(blocked, r, c):
            return False
    return True


@njit(cache=True)
def straighten(blocked: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Indices of the points (n, 2 cell coordinates) to keep: from each kept point, the
    farthest point reached before a straight line first crosses a blocked cell."""
    n = points.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    count = 1
    i = 0
    while i < n - 1:
        j = i + 1
        k = i + 2
        while k < n and segment_clear(
            blocked, points[i, 0], points[i, 1], points[k, 0], points[k, 1]
        ):
            j = k
            k += 1
        keep[count] = j
        count += 1
        i = j
    return keep[:count]


# -- the planner -----------------------------------------------------------------------------


def _xy(point: Point, name: str) -> tuple[float, float]:
    if isinstance(point, Pose2D):
        return point.x, point.y
    values = np.asarray(point, dtype=float).ravel()
    if values.size < 2:
        raise InputError(f"{name} must be (x, y) in metres, got {point!r}")
    require_finite(name, float(values[0]), float(values[1]))
    return float(values[0]), float(values[1])


class PathPlanner:
    """Plans on one map for a round robot of ``radius`` (m), kept ``margin`` (m) further off.

    ``distance`` may hand in ``obstacle_distance(map, unknown_is_obstacle)`` already computed
    (with ``unknown_is_obstacle=False`` it is the localizer's field too).
    """

    def __init__(
        self,
        occupancy_map: OccupancyMap,
        radius: float,
        margin: float = 0.05,
        *,
        unknown_is_obstacle: bool = True,
        distance: np.ndarray | None = None,
    ) -> None:
        if not (math.isfinite(radius) and radius >= 0):
            raise InputError(f"robot radius must be zero or positive, got {radius!r} m")
        if not (math.isfinite(margin) and margin >= 0):
            raise InputError(f"planning margin must be zero or positive, got {margin!r} m")
        self.map = occupancy_map
        self.radius = float(radius)
        self.margin = float(margin)
        self.unknown_is_obstacle = unknown_is_obstacle
        if distance is None:
            distance = obstacle_distance(occupancy_map, unknown_is_obstacle)
        distance = np.asarray(distance, dtype=float)
        if distance.shape != occupancy_map.shape:
            raise InputError(
                f"distance field shape {distance.shape} does not match the map's "
                f"{occupancy_map.shape}"
            )
        self.distance = distance
        half = occupancy_map.resolution / 2.0
        #: (ny, nx) bool: cells the robot's centre must not enter
        self.blocked = np.ascontiguousarray(distance - half < self.clearance)
        self._map_blocked = self.blocked.copy()
        #: obstacles found since (``add_obstacle``): (x, y, radius) in metres
        self.added: list[tuple[float, float, float]] = []

    def add_obstacle(self, x: float, y: float, radius: float) -> None:
        """Plan around a disc of ``radius`` m at (``x``, ``y``) m that the map does not hold
        (what a bumper felt: a toy on the floor is below the laser's plane), inflated like the
        map's obstacles; ``forget_obstacles`` drops them all."""
        if not all(math.isfinite(v) for v in (x, y, radius)) or radius < 0:
            raise InputError(
                f"an obstacle needs a finite place and a radius >= 0 m, got {(x, y, radius)}"
            )
        rows, cols = np.indices(self.blocked.shape)
        cx, cy = self.map.center_of(rows, cols)
        half = self.map.resolution / 2.0
        near = np.hypot(cx - x, cy - y) - radius - half < self.clearance
        self.blocked = np.ascontiguousarray(self.blocked | near)
        self.added.append((float(x), float(y), float(radius)))

    def forget_obstacles(self) -> None:
        """Back to the map's obstacles only (a new mission in a world that may have changed)."""
        self.blocked = self._map_blocked.copy()
        self.added = []

    @property
    def clearance(self) -> float:
        """Metres every unblocked cell centre keeps from obstacle faces: radius + margin."""
        return self.radius + self.margin

    def _cell(self, point: tuple[float, float], name: str) -> tuple[int, int]:
        """The free cell holding a point, or a one-line error saying why it is not free."""
        x, y = point
        row, col = (int(v) for v in self.map.cell_of(x, y))
        ny, nx = self.map.shape
        if not (0 <= row < ny and 0 <= col < nx):
            x0, y0, x1, y1 = self.map.extent
            raise InputError(
                f"{name} ({x:.2f}, {y:.2f}) m lies outside the map "
                f"(x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f} m)"
            )
        if self.blocked[row, col]:
            reach = self.clearance + 2.0 * self.map.resolution
            boxes = _obstacle_boxes(
                self.map, x - reach, y - reach, x + reach, y + reach, self.unknown_is_obstacle
            )
            face = float(np.min(_segment_box_distances(x, y, x, y, *boxes), initial=reach))
            felt = [math.hypot(x - ox, y - oy) - r for ox, oy, r in self.added]
            if felt and min(felt) < face:  # what a bumper felt, not the map, is nearest
                face = max(0.0, min(felt))
                where = f"{face:.2f} m from what the bumper felt"
            else:
                where = "inside an obstacle" if face == 0.0 else f"{face:.2f} m from an obstacle"
            raise InputError(
                f"{name} ({x:.2f}, {y:.2f}) m is {where}, closer than the robot's radius "
                f"{self.radius:.2f} m + margin {self.margin:.2f} m; {self._nearest_free(x, y)}"
            )
        return row, col

    def _start_cell(self, point: tuple[float, float], tolerance: float) -> tuple[int, int]:
        try:
            return self._cell(point, "start")
        except InputError:
            if tolerance <= 0.0:
                raise
            rows, cols = np.nonzero(~self.blocked)
            if rows.size == 0:
                raise
            cx, cy = self.map.center_of(rows, cols)
            gaps = np.hypot(cx - point[0], cy - point[1])
            k = int(np.argmin(gaps))
            if gaps[k] > tolerance:
                raise
            return int(rows[k]), int(cols[k])

    def _nearest_free(self, x: float, y: float) -> str:
        rows, cols = np.nonzero(~self.blocked)
        if rows.size == 0:
            return f"no cell of the map is {self.clearance:.2f} m clear of obstacles"
        cx, cy = self.map.center_of(rows, cols)
        gaps = np.hypot(cx - x, cy - y)
        k = int(np.argmin(gaps))
        return (
            f"the nearest free cell is {gaps[k]:.2f} m away at "
            f"({float(cx[k]):.2f}, {float(cy[k]):.2f}) m"
        )

    def _grid_point(self, x: float, y: float) -> tuple[float, float]:
        res = self.map.resolution
        return (x - self.map.origin[0]) / res, (y - self.map.origin[1]) / res

    def plan(self, start: Point, goal: Point, start_tolerance: float = 0.0) -> Path:
        """The shortest grid path from ``start`` to ``goal`` (metres, or Pose2D), straightened
        into legs. ``InputError`` if either lies off the map or too near an obstacle,
        ``NoPathError`` if no path of the robot's width joins them.

        ``start_tolerance`` (m): a start this close to a free cell starts there (a robot that
        ended its last leg a centimetre inside the margin, as localization leaves it, can leave
        again); the path still begins at ``start``."""
        a, b = _xy(start, "start"), _xy(goal, "goal")
        start_cell = self._start_cell(a, start_tolerance)
        goal_cell = self._cell(b, "goal")
        cells = astar(self.blocked, *start_cell, *goal_cell)
        if len(cells) == 0:
            unknown = (
                "; unknown cells count as obstacles (unknown_is_obstacle=True)"
                if self.unknown_is_obstacle and self.map.unknown.any()
                else ""
            )
            raise NoPathError(
                f"no path from start ({a[0]:.2f}, {a[1]:.2f}) m to goal ({b[0]:.2f}, "
                f"{b[1]:.2f}) m: they lie in separate free regions for a robot of radius "
                f"{self.radius:.2f} m + margin {self.margin:.2f} m, which needs gaps at least "
                f"{2 * self.clearance:.2f} m wide{unknown}"
            )
        x, y = self.map.center_of(cells[:, 0], cells[:, 1])
        points = np.stack([x, y], axis=1)
        points[0], points[-1] = a, b
        if len(points) == 1:
            points = np.array([a, b])
        res = self.map.resolution
        grid = (points - np.array(self.map.origin[:2])) / res
        keep = straighten(self.blocked, np.ascontiguousarray(grid))
        return Path(waypoints=points[keep], cells=cells)

    def distances_from(self, start: Point, start_tolerance: float = math.inf) -> np.ndarray:
        """(ny, nx) metres along the shortest grid path from ``start`` to every cell of the map
        (inf where the robot cannot go): one search prices every goal at once, e.g. all the
        places a view could be taken from. The grid path is an upper bound of the straightened
        legs' length (by at most ~8 %). A start inside the inflated obstacles (a robot that
        ended a leg a hair too close) starts from the nearest free cell within
        ``start_tolerance`` metres (as ``plan`` does); farther, nothing is reachable."""
        x, y = _xy(start, "start")
        try:
            row, col = self._start_cell((x, y), start_tolerance)
        except InputError:
            return np.full(self.map.shape, np.inf)
        return grid_distances(self.blocked, row, col) * self.map.resolution

    def leg_is_clear(self, a: Point, b: Point) -> bool:
        """Whether the straight leg a -> b (metres) touches only unblocked cells of this
        planner's inflated map (the test the planner straightens with)."""
        (ax, ay), (bx, by) = _xy(a, "a"), _xy(b, "b")
        return bool(
            segment_clear(self.blocked, *self._grid_point(ax, ay), *self._grid_point(bx, by))
        )


def leg_is_clear(
    occupancy_map: OccupancyMap,
    a: Point,
    b: Point,
    radius: float,
    *,
    unknown_is_obstacle: bool = True,
) -> bool:
    """Whether a disc of ``radius`` (m) can slide straight from a to b (metres) touching no
    obstacle cell (occupied; unknown too unless ``unknown_is_obstacle=False``), exactly: the
    distance from the segment to every obstacle cell's square is at least ``radius``. Beyond
    the map's edge counts as unknown. Use it before driving a leg on a map that may have
    changed since planning."""
    (ax, ay), (bx, by) = _xy(a, "a"), _xy(b, "b")
    if not (math.isfinite(radius) and radius >= 0):
        raise InputError(f"leg radius must be zero or positive, got {radius!r} m")
    x_lo, x_hi = min(ax, bx) - radius, max(ax, bx) + radius
    y_lo, y_hi = min(ay, by) - radius, max(ay, by) + radius
    mx0, my0, mx1, my1 = occupancy_map.extent
    inside = mx0 <= min(ax, bx) and max(ax, bx) < mx1 and my0 <= min(ay, by) and max(ay, by) < my1
    if not inside:
        return False
    if unknown_is_obstacle and (x_lo < mx0 or x_hi > mx1 or y_lo < my0 or y_hi > my1):
        return False
    boxes = _obstacle_boxes(occupancy_map, x_lo, y_lo, x_hi, y_hi, unknown_is_obstacle)
    return bool(np.all(_segment_box_distances(ax, ay, bx, by, *boxes) >= radius))


def _obstacle_boxes(
    occupancy_map: OccupancyMap,
    x_lo: float,
    y_lo: float,
    x_hi: float,
    y_hi: float,
    unknown_is_obstacle: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(left, bottom, right, top) metres of the obstacle cells meeting a window of the map."""
    res = occupancy_map.resolution
    ny, nx = occupancy_map.shape
    r0, c0 = (int(v) for v in occupancy_map.cell_of(x_lo, y_lo))
    r1, c1 = (int(v) for v in occupancy_map.cell_of(x_hi, y_hi))
    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, ny - 1), min(c1, nx - 1)
    if r1 < r0 or c1 < c0:
        empty = np.zeros(0)
        return empty, empty, empty, empty
    window = obstacle_mask(occupancy_map, unknown_is_obstacle)[r0 : r1 + 1, c0 : c1 + 1]
    rows, cols = np.nonzero(window)
    left = occupancy_map.origin[0] + (cols + c0) * res
    bottom = occupancy_map.origin[1] + (rows + r0) * res
    return left, bottom, left + res, bottom + res


def _segment_box_distances(
    ax: float,
    ay: float,
    bx: float,
    by: float,
    x0: np.ndarray,
    y0: np.ndarray,
    x1: np.ndarray,
    y1: np.ndarray,
) -> np.ndarray:
    """Distance (m) from segment a-b to each axis-aligned box [x0, x1] x [y0, y1]: 0 where they
    meet, else the least of the end points' distances to the box and the box corners' distances
    to the segment (two convex shapes apart are closest at a vertex of one of them)."""
    dx, dy = bx - ax, by - ay
    # Liang-Barsky: does the segment meet the box?
    t0 = np.zeros_like(x0)
    t1 = np.ones_like(x0)
    meets = np.ones(x0.shape, dtype=bool)
    for p, q in ((-dx, ax - x0), (dx, x1 - ax), (-dy, ay - y0), (dy, y1 - ay)):
        if p == 0.0:
            meets &= q >= 0.0
        elif p < 0.0:
            t0 = np.maximum(t0, q / p)
        else:
            t1 = np.minimum(t1, q / p)
    meets &= t0 <= t1

    def point_to_box(px: float, py: float) -> np.ndarray:
        ex = np.maximum(np.maximum(x0 - px, px - x1), 0.0)
        ey = np.maximum(np.maximum(y0 - py, py - y1), 0.0)
        return np.hypot(ex, ey)

    best = np.minimum(point_to_box(ax, ay), point_to_box(bx, by))
    length2 = dx * dx + dy * dy
    for cx, cy in ((x0, y0), (x1, y0), (x0, y1), (x1, y1)):
        t = np.clip(((cx - ax) * dx + (cy - ay) * dy) / length2, 0.0, 1.0) if length2 else 0.0
        best = np.minimum(best, np.hypot(ax + t * dx - cx, ay + t * dy - cy))
    return np.where(meets, 0.0, best)
