"""Path planning (twin.nav.planner): inflation, A*, straightened legs, and the errors.

Maps are rasterised at 5 cm from geometry (walls, furniture boxes, round pillars), and paths are
checked against that geometry, not only against the grid the planner saw.
"""

from __future__ import annotations

import heapq
import math
from itertools import pairwise

import numpy as np
import pytest

from twin.core.errors import InputError, TwinError
from twin.core.geometry import Pose2D
from twin.nav.distance import obstacle_distance
from twin.nav.maps import UNKNOWN, OccupancyMap
from twin.nav.planner import NoPathError, PathPlanner, astar, leg_is_clear, segment_clear

RES = 0.05
RADIUS = 0.25
Box = tuple[float, float, float, float]
Circle = tuple[float, float, float]


def room(
    width: float, height: float, boxes: list[Box], circles: list[Circle] = (), sub: int = 4
) -> tuple[OccupancyMap, list[Box], list[Circle]]:
    """A walled room (walls 0.1 m inside its edges) with furniture; occupied where any of a
    cell's sub x sub sample points is inside something, free elsewhere. Returns the map and
    the geometry it was drawn from."""
    t = 0.1
    walls = [
        (0.0, 0.0, width, t),
        (0.0, height - t, width, height),
        (0.0, 0.0, t, height),
        (width - t, 0.0, width, height),
    ]
    boxes = walls + list(boxes)
    nx, ny = round(width / RES), round(height / RES)
    offsets = (np.arange(sub) + 0.5) / sub * RES
    xs = (np.arange(nx)[:, None] * RES + offsets).ravel()
    ys = (np.arange(ny)[:, None] * RES + offsets).ravel()
    gx, gy = np.meshgrid(xs, ys)
    inside = np.zeros(gx.shape, dtype=bool)
    for x0, y0, x1, y1 in boxes:
        inside |= (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    for cx, cy, r in circles:
        inside |= np.hypot(gx - cx, gy - cy) <= r
    occupied = inside.reshape(ny, sub, nx, sub).any(axis=(1, 3))
    return OccupancyMap(occupied.astype(float), RES), boxes, list(circles)


def clearance_to_geometry(points: np.ndarray, boxes: list[Box], circles: list[Circle]) -> float:
    """Least distance (m) from any of the points (n, 2) to the true obstacles."""
    x, y = points[:, 0:1], points[:, 1:2]
    b = np.array(boxes)
    ex = np.maximum(np.maximum(b[:, 0] - x, x - b[:, 2]), 0.0)
    ey = np.maximum(np.maximum(b[:, 1] - y, y - b[:, 3]), 0.0)
    best = np.hypot(ex, ey).min()
    for cx, cy, r in circles:
        best = min(best, float((np.hypot(x - cx, y - cy) - r).min()))
    return float(best)


def densify(waypoints: np.ndarray, step: float = 0.005) -> np.ndarray:
    parts = []
    for a, b in pairwise(waypoints):
        n = max(2, math.ceil(np.hypot(*(b - a)) / step) + 1)
        parts.append(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
    return np.concatenate(parts)


FURNITURE: list[Box] = [(2.0, 1.5, 3.2, 2.3), (5.0, 4.0, 6.5, 4.8), (6.8, 0.1, 7.9, 1.0)]
PILLARS: list[Circle] = [(4.0, 3.0, 0.3), (1.5, 4.5, 0.25)]
FURNISHED, FURNISHED_BOXES, FURNISHED_CIRCLES = room(10.0, 8.0, FURNITURE, PILLARS)


def divided(door: float) -> tuple[OccupancyMap, list[Box], list[Circle]]:
    """An 8 x 6 m room split by a wall at x = 4 m with a door ``door`` metres wide centred at
    y = 3 m (its jambs' faces at 3 -/+ door / 2)."""
    wall = [(3.95, 0.0, 4.05, 3.0 - door / 2), (3.95, 3.0 + door / 2, 4.05, 6.0)]
    return room(8.0, 6.0, wall)


# -- paths ------------------------------------------------------------------------------------


def test_a_path_keeps_the_robot_clear_of_the_furniture_in_a_few_straight_legs():
    planner = PathPlanner(FURNISHED, RADIUS)
    start, goal = (0.6, 0.6), (8.8, 7.2)
    path = planner.plan(start, goal)
    np.testing.assert_allclose(path.waypoints[0], start)
    np.testing.assert_allclose(path.waypoints[-1], goal)
    assert len(path.waypoints) <= 6
    assert not planner.blocked[path.cells[:, 0], path.cells[:, 1]].any()
    steps = np.diff(path.cells, axis=0)
    assert np.all(np.abs(steps).max(axis=1) == 1)  # 8-connected, no jumps
    grid_length = RES * np.sum(np.hypot(steps[:, 0], steps[:, 1]))
    assert path.length <= grid_length + RES
    assert path.length >= math.dist(start, goal)
    for a, b in path.legs:
        assert planner.leg_is_clear(a, b)
        assert leg_is_clear(FURNISHED, a, b, RADIUS)
    # against the furniture itself, not only its picture in the grid
    assert clearance_to_geometry(densify(path.waypoints), FURNISHED_BOXES, FURNISHED_CIRCLES) >= (
        RADIUS
    )


def test_a_straight_shot_is_one_leg():
    path = PathPlanner(FURNISHED, RADIUS).plan(Pose2D(0.6, 6.0, 1.0), (9.0, 6.0))
    assert len(path.waypoints) == 2
    assert path.length == pytest.approx(8.4)
    # the pillar at (4, 3) stands 0.2 m below the line y = 3.5: one detour around it
    assert len(PathPlanner(FURNISHED, RADIUS).plan((0.6, 3.5), (9.0, 3.5)).waypoints) == 3


def test_start_and_goal_in_the_same_cell():
    path = PathPlanner(FURNISHED, RADIUS).plan((5.01, 6.01), (5.02, 6.02))
    assert len(path.waypoints) == 2 and path.length == pytest.approx(math.hypot(0.01, 0.01))


@pytest.mark.parametrize("door", [0.70, 0.90])
def test_the_path_goes_through_a_door_wide_enough(door):
    occupancy, boxes, circles = divided(door)
    path = PathPlanner(occupancy, RADIUS).plan((1.5, 1.0), (6.5, 1.0))
    crossing = densify(path.waypoints)
    at_wall = crossing[np.abs(crossing[:, 0] - 4.0) < 0.06]
    assert np.all(np.abs(at_wall[:, 1] - 3.0) < door / 2)  # through the door, nowhere else
    assert clearance_to_geometry(crossing, boxes, circles) >= RADIUS
    for a, b in path.legs:
        assert leg_is_clear(occupancy, a, b, RADIUS)


@pytest.mark.parametrize("door", [0.40, 0.55])
def test_a_door_too_narrow_is_a_clear_error(door):
    occupancy, _, _ = divided(door)
    with pytest.raises(NoPathError, match=r"needs gaps at least 0\.60 m wide") as caught:
        PathPlanner(occupancy, RADIUS).plan((1.5, 1.0), (6.5, 1.0))
    assert "\n" not in str(caught.value) and isinstance(caught.value, TwinError)
    # a thinner robot fits
    PathPlanner(occupancy, door / 2 - 0.1, margin=0.0).plan((1.5, 1.0), (6.5, 1.0))


def test_a_start_or_goal_too_near_an_obstacle_says_where_free_space_is():
    planner = PathPlanner(FURNISHED, RADIUS)
    with pytest.raises(InputError, match=r"start \(2\.50, 1\.40\) m is 0\.10 m from an obst"):
        planner.plan((2.5, 1.4), (5.0, 6.0))
    with pytest.raises(InputError, match=r"the nearest free cell is 0\.2\d m away") as caught:
        planner.plan((2.5, 1.4), (5.0, 6.0))
    assert "\n" not in str(caught.value)
    with pytest.raises(InputError, match=r"goal \(4\.00, 3\.00\) m is inside an obstacle"):
        planner.plan((5.0, 6.0), (4.0, 3.0))  # the pillar's centre
    with pytest.raises(InputError, match="outside the map"):
        planner.plan((5.0, 6.0), (12.0, 3.0))
    with pytest.raises(InputError, match="start must be finite"):
        planner.plan((math.nan, 1.0), (5.0, 6.0))


def test_unknown_space_is_an_obstacle_only_when_asked():
    grid = np.zeros((60, 80))
    grid[:, 38:42] = UNKNOWN  # an unexplored band across the room
    unexplored = OccupancyMap(grid, RES)
    with pytest.raises(NoPathError, match="unknown cells count as obstacles"):
        PathPlanner(unexplored, RADIUS).plan((1.0, 1.0), (3.5, 2.0))
    path = PathPlanner(unexplored, RADIUS, unknown_is_obstacle=False).plan((1.0, 1.0), (3.5, 2.0))
    assert len(path.waypoints) == 2
    a, b = path.legs[0]
    assert not leg_is_clear(unexplored, a, b, RADIUS)
    assert leg_is_clear(unexplored, a, b, RADIUS, unknown_is_obstacle=False)


def test_the_planner_can_share_the_localizers_distance_field():
    shared = obstacle_distance(FURNISHED)
    planner = PathPlanner(FURNISHED, RADIUS, unknown_is_obstacle=False, distance=shared)
    own = PathPlanner(FURNISHED, RADIUS, unknown_is_obstacle=False)
    np.testing.assert_array_equal(planner.blocked, own.blocked)
    with pytest.raises(InputError, match="shape"):
        PathPlanner(FURNISHED, RADIUS, distance=shared[:-1])


def test_inflation_keeps_cell_centres_radius_plus_margin_from_faces():
    planner = PathPlanner(FURNISHED, RADIUS, margin=0.05)
    rows, cols = np.nonzero(~planner.blocked)
    x, y = FURNISHED.center_of(rows, cols)
    centres = np.stack([x, y], axis=1)
    # the map's obstacles are at most a cell larger than the geometry, never smaller
    assert clearance_to_geometry(centres, FURNISHED_BOXES, FURNISHED_CIRCLES) >= 0.30
    rows, cols = np.nonzero(planner.blocked & FURNISHED.free)
    x, y = FURNISHED.center_of(rows, cols)
    near = np.stack([x, y], axis=1)
    assert clearance_to_geometry(near, FURNISHED_BOXES, FURNISHED_CIRCLES) < 0.30


def test_bad_planner_arguments_are_errors():
    with pytest.raises(InputError, match="radius"):
        PathPlanner(FURNISHED, -0.1)
    with pytest.raises(InputError, match="margin"):
        PathPlanner(FURNISHED, 0.2, margin=math.inf)
    with pytest.raises(InputError, match="radius"):
        leg_is_clear(FURNISHED, (1.0, 1.0), (2.0, 2.0), math.nan)
    with pytest.raises(InputError, match="goal"):
        PathPlanner(FURNISHED, 0.2).plan((1.0, 1.0), (2.0,))


# -- A* against Dijkstra ----------------------------------------------------------------------


def dijkstra_cost(blocked: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """Reference: the least 8-connected cost with the same no-corner-cutting rule."""
    ny, nx = blocked.shape
    best = {start: 0.0}
    queue = [(0.0, start)]
    while queue:
        cost, (r, c) = heapq.heappop(queue)
        if (r, c) == goal:
            return cost
        if cost > best[(r, c)]:
            continue
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if (dr, dc) == (0, 0) or not (0 <= rr < ny and 0 <= cc < nx) or blocked[rr, cc]:
                    continue
                if dr and dc and (blocked[r, cc] or blocked[rr, c]):
                    continue
                new = cost + (math.sqrt(2) if dr and dc else 1.0)
                if new < best.get((rr, cc), math.inf):
                    best[(rr, cc)] = new
                    heapq.heappush(queue, (new, (rr, cc)))
    return math.inf


@pytest.mark.parametrize("seed", range(12))
def test_astar_finds_the_shortest_grid_path(seed):
    rng = np.random.default_rng(seed)
    blocked = rng.random((25, 30)) < 0.3
    start, goal = (0, 0), (24, 29)
    blocked[start] = blocked[goal] = False
    path = astar(blocked, *start, *goal)
    expected = dijkstra_cost(blocked, start, goal)
    if math.isinf(expected):
        assert path.shape == (0, 2)
        return
    assert tuple(path[0]) == start and tuple(path[-1]) == goal
    assert not blocked[path[:, 0], path[:, 1]].any()
    steps = np.diff(path, axis=0)
    for (r, c), (dr, dc) in zip(path[:-1], steps, strict=True):
        assert max(abs(dr), abs(dc)) == 1
        if dr and dc:
            assert not blocked[r, c + dc] and not blocked[r + dr, c]
    assert np.sum(np.hypot(steps[:, 0], steps[:, 1])) == pytest.approx(expected, rel=1e-5)


# -- leg checks -------------------------------------------------------------------------------


def test_segment_clear_sees_every_cell_the_segment_touches():
    blocked = np.zeros((5, 5), dtype=bool)
    blocked[2, 2] = True
    assert not segment_clear(blocked, 0.5, 0.5, 4.5, 4.5)  # straight through the centre
    assert not segment_clear(blocked, 0.5, 2.2, 4.5, 2.7)  # along its row
    assert segment_clear(blocked, 0.5, 1.5, 4.5, 1.5)  # the row below
    assert not segment_clear(blocked, 1.5, 1.5, 2.0, 2.0)  # ending on its corner
    assert segment_clear(blocked, 0.2, 0.9, 4.8, 1.9)
    blocked[:] = False
    blocked[1, 2] = blocked[2, 1] = True
    assert not segment_clear(blocked, 1.5, 1.5, 2.5, 2.5)  # no slipping between two corners
    assert not segment_clear(blocked, 0.5, 0.5, 5.5, 0.5)  # off the grid


def test_leg_is_clear_is_exact_against_a_dense_check():
    grid = np.zeros((40, 40))
    grid[18:22, 10:30] = 1.0  # a bar from x 0.5..1.5, y 0.9..1.1
    grid[5, 5] = 1.0  # a single cell at x 0.25..0.30, y 0.25..0.30
    bar = OccupancyMap(grid, RES)
    boxes = [(0.5, 0.9, 1.5, 1.1), (0.25, 0.25, 0.30, 0.30)]
    rng = np.random.default_rng(0)
    decided = 0
    for _ in range(400):
        a, b = rng.uniform(0.3, 1.7, 2), rng.uniform(0.3, 1.7, 2)
        radius = rng.uniform(0.0, 0.3)
        true_gap = clearance_to_geometry(densify(np.array([a, b]), 0.0005), boxes, [])
        if abs(true_gap - radius) < 0.002:
            continue  # too close to call by sampling
        decided += 1
        assert leg_is_clear(bar, a, b, radius, unknown_is_obstacle=False) == (true_gap >= radius)
    assert decided > 350
    assert not leg_is_clear(bar, (0.1, 0.1), (3.0, 0.1), 0.05)  # leaves the map


def test_one_search_prices_every_goal_as_plan_would():
    from twin.nav.planner import PathPlanner

    cells = np.zeros((60, 60))
    cells[0:50, 29:31] = 1.0  # a wall from the bottom, open at the top
    planner = PathPlanner(OccupancyMap(cells, 0.05), radius=0.1, margin=0.0)
    field = planner.distances_from((0.5, 0.5))
    for goal in ((2.5, 0.5), (0.5, 2.5), (2.2, 2.8)):
        row, col = (int(v) for v in planner.map.cell_of(*goal))
        length = planner.plan((0.5, 0.5), goal).length
        assert length <= field[row, col] + 1e-9 <= 1.09 * length + 0.1  # grid path: an upper bound
    # a start a hair inside the margin leaves from the nearest free cell; deep inside, nothing
    assert np.isfinite(planner.distances_from((1.40, 0.5), start_tolerance=0.1)).any()
    assert np.isinf(planner.distances_from((1.48, 0.5), start_tolerance=0.01)).all()
