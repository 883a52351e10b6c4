"""Time one accumulator-grid fuse, and how it grows with grid size, supersampling and columns.

    python benchmarks/bench_grid.py

The reference case is the paper's: a 50 x 50 grid of 0.1 m cells, 10x supersampling, one view
of 32 patch columns spanning a 45 degree field of view. Prints median microseconds per fuse.

It also prints what the viewpoint-bias correction costs: one ``fuse_all`` of several objects
with 1 and 8 direction bins (the coverage pass is the same; 8 bins add the scatter of the seen
cells into their bins), and one ``layer`` read (8 bins: a mean per bin, then a sum).
"""

from __future__ import annotations

import math
import time

import numpy as np

from twin.core.grid import AccumulatorGrid, GridSpec


def fuse_time_us(
    cells: int,
    supersample: int,
    columns: int,
    repeats: int = 300,
    objects: int = 1,
    direction_bins: int = 1,
) -> float:
    """Median wall time of one ``fuse_all`` of ``objects`` layers, over views from random poses
    inside the grid, in microseconds."""
    spec = GridSpec(0.0, 0.0, cells * 0.1, cells * 0.1, 0.1)
    names = [f"object{i}" for i in range(objects)]
    grid = AccumulatorGrid(names, spec, supersample=supersample, direction_bins=direction_bins)
    rng = np.random.default_rng(0)
    edges = np.linspace(-math.radians(22.5), math.radians(22.5), columns + 1)
    values = {name: rng.random(columns) for name in names}
    grid.fuse_all((1.0, 1.0), np.stack([edges[:-1], edges[1:]], axis=1), values)  # compile
    times = []
    for _ in range(repeats):
        x, y = rng.uniform(0, cells * 0.1, size=2)
        heading = rng.uniform(-math.pi, math.pi)
        intervals = np.stack([edges[:-1], edges[1:]], axis=1) + heading
        start = time.perf_counter()
        grid.fuse_all((x, y), intervals, values)
        times.append(time.perf_counter() - start)
    return 1e6 * float(np.median(times))


def layer_time_us(cells: int, direction_bins: int, repeats: int = 300) -> float:
    """Median wall time of one ``layer`` read after 50 views, in microseconds."""
    spec = GridSpec(0.0, 0.0, cells * 0.1, cells * 0.1, 0.1)
    grid = AccumulatorGrid(["target"], spec, direction_bins=direction_bins)
    rng = np.random.default_rng(0)
    edges = np.linspace(-math.radians(22.5), math.radians(22.5), 33)
    for _ in range(50):
        intervals = np.stack([edges[:-1], edges[1:]], axis=1) + rng.uniform(-math.pi, math.pi)
        grid.fuse("target", rng.uniform(0, cells * 0.1, size=2), intervals, rng.random(32))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        grid.layer("target")
        times.append(time.perf_counter() - start)
    return 1e6 * float(np.median(times))


def main() -> None:
    print("one fuse, median over 300 views from random poses (microseconds)")
    print(f"  reference 50x50 cells, supersample 10, 32 columns: {fuse_time_us(50, 10, 32):8.1f}")
    print("  grid cells per side (supersample 10, 32 columns):")
    for cells in (25, 50, 100, 200):
        print(f"    {cells:4d}: {fuse_time_us(cells, 10, 32):8.1f}")
    print("  supersample (50x50, 32 columns):")
    for s in (1, 5, 10, 20):
        print(f"    {s:4d}: {fuse_time_us(50, s, 32):8.1f}")
    print("  columns (50x50, supersample 10):")
    for columns in (8, 16, 32, 64):
        print(f"    {columns:4d}: {fuse_time_us(50, 10, columns):8.1f}")
    print("  direction bins (supersample 10, 32 columns): fuse_all of 4 objects / layer read")
    for cells in (50, 200):
        for bins in (1, 8):
            fuse = fuse_time_us(cells, 10, 32, objects=4, direction_bins=bins)
            read = layer_time_us(cells, bins)
            print(f"    {cells}x{cells}, B = {bins}: {fuse:8.1f} / {read:8.1f}")


if __name__ == "__main__":
    main()
