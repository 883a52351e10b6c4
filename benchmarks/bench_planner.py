"""Time path planning on 10 x 8 m maps of 5 cm cells (200 x 160 cells).

    python benchmarks/bench_planner.py

Prints the inflation (distance transform and threshold), A* plus straightening for a few
start/goal pairs on an office with a door, a serpentine maze (the longest paths a map this size
holds) and a search that finds no path (every reachable cell expanded), and the two leg checks.
The goal is a plan in well under 100 ms. Times are medians of wall time per call.
"""

from __future__ import annotations

import time

import numpy as np
from bench_mcl import RES, office_map

from twin.core.errors import TwinError
from twin.nav.maps import OccupancyMap
from twin.nav.planner import PathPlanner, leg_is_clear

RADIUS, MARGIN = 0.25, 0.05


def maze_map() -> OccupancyMap:
    """10 x 8 m with walls across the room, alternately open at the right and left end, so
    that every path from bottom to top snakes through 1.2 m corridors."""
    nx, ny = round(10.0 / RES), round(8.0 / RES)
    x = (np.arange(nx) + 0.5) * RES
    y = (np.arange(ny) + 0.5) * RES
    gx, gy = np.meshgrid(x, y)
    solid = (gx < 0.1) | (gx > 9.9) | (gy < 0.1) | (gy > 7.9)
    for k, wall_y in enumerate(np.arange(1.3, 7.9, 1.3)):
        across = (gy >= wall_y) & (gy <= wall_y + 0.1)
        solid |= across & ((gx < 8.8) if k % 2 == 0 else (gx > 1.2))
    return OccupancyMap(solid.astype(float), RES)


def median_ms(call, repeats: int = 30) -> tuple[float, object]:
    result = call()  # compile / warm
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - t)
    return 1e3 * float(np.median(times)), result


def plan_or_error(planner: PathPlanner, start, goal):
    try:
        return planner.plan(start, goal)
    except TwinError as error:
        return error


def main() -> None:
    office, maze = office_map(), maze_map()
    ny, nx = office.shape
    print(f"maps 10 x 8 m at {RES} m ({nx} x {ny} cells); robot radius {RADIUS} + margin {MARGIN}")
    ms, _ = median_ms(lambda: PathPlanner(office, RADIUS, MARGIN))
    print(f"  inflation (distance transform + threshold): {ms:7.2f} ms")
    planner = PathPlanner(office, RADIUS, MARGIN)
    cases = [
        ("office, across the room through the door", planner, (1.0, 0.6), (9.3, 5.5)),
        ("office, around the desk", planner, (0.6, 7.3), (2.0, 4.8)),
        ("office, short hop", planner, (1.0, 0.6), (2.0, 1.5)),
        (
            "maze, bottom to top (snaking)",
            PathPlanner(maze, RADIUS, MARGIN),
            (0.6, 0.6),
            (9.3, 7.4),
        ),
        # 0.5 m radius + margin needs 1.1 m: the 1 m door is shut, the search empties the left half
        (
            "office, no path (robot too wide)",
            PathPlanner(office, 0.5, MARGIN),
            (1.0, 1.0),
            (9.0, 5.5),
        ),
    ]
    print("  plan = A* + straightening:")
    for name, who, start, goal in cases:
        ms, result = median_ms(lambda who=who, s=start, g=goal: plan_or_error(who, s, g))
        if isinstance(result, TwinError):
            what = f"{type(result).__name__}"
        else:
            what = (
                f"{len(result.cells)} cells -> {len(result.waypoints) - 1} legs, "
                f"{result.length:.2f} m"
            )
        print(f"    {name:42s} {ms:7.2f} ms  ({what})")
    path = planner.plan((1.0, 0.6), (9.3, 5.5))
    a, b = path.legs[0]
    ms, _ = median_ms(lambda: planner.leg_is_clear(a, b), 200)
    print(
        f"  planner.leg_is_clear (grid, a {np.hypot(*np.subtract(b, a)):.1f} m leg): {ms:7.3f} ms"
    )
    ms, _ = median_ms(lambda: leg_is_clear(office, a, b, RADIUS), 200)
    print(f"  leg_is_clear (exact, the same leg):        {ms:7.3f} ms")


if __name__ == "__main__":
    main()
