"""Occupancy maps: a 2-D grid of occupancy probabilities over the map frame.

The in-memory layout follows the accumulator grid's: ``occupancy[row, col]`` with row 0 at the
map's lowest y (map y up) and column 0 at its lowest x. The ROS ``map_server`` format (a PGM
image with row 0 at the top, and a YAML file with ``resolution``, ``origin``, ``negate``,
``occupied_thresh`` and ``free_thresh``) is what maps are read from and written to, so a map made
with slam_toolbox, Cartographer or gmapping works as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError

UNKNOWN = -1.0  # occupancy of a cell nothing has been seen of


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid in the map frame (metres, x right, y up).

    ``occupancy`` (ny, nx): the probability that a cell is occupied, in [0, 1], or ``UNKNOWN``;
    ``resolution``: metres per cell; ``origin``: (x, y, yaw) of the lower-left corner of cell
    (0, 0), as map_server's ``origin`` (yaw must be 0: rotated maps are not supported);
    ``occupied_thresh`` / ``free_thresh``: a cell at or above the first is occupied, at or below
    the second free, in between unknown (map_server's trinary reading; its defaults).
    """

    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196

    def __post_init__(self) -> None:
        grid = np.asarray(self.occupancy, dtype=float)
        if grid.ndim != 2 or min(grid.shape) < 1:
            raise InputError(f"an occupancy map must be a 2-D grid, got shape {grid.shape}")
        known = grid[grid != UNKNOWN]
        if known.size and (not np.all(np.isfinite(known)) or known.min() < 0 or known.max() > 1):
            raise InputError("occupancy values must be in [0, 1], or -1 for unknown")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise InputError(f"map resolution must be positive, got {self.resolution!r} m")
        if abs(self.origin[2]) > 1e-9:
            raise InputError("rotated maps (origin yaw != 0) are not supported; re-export it")
        if not 0.0 <= self.free_thresh < self.occupied_thresh <= 1.0:
            raise InputError(
                f"map thresholds must satisfy 0 <= free ({self.free_thresh}) < occupied "
                f"({self.occupied_thresh}) <= 1"
            )
        object.__setattr__(self, "occupancy", grid)

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupancy.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) in metres."""
        ny, nx = self.shape
        x0, y0 = self.origin[0], self.origin[1]
        return x0, y0, x0 + nx * self.resolution, y0 + ny * self.resolution

    @property
    def occupied(self) -> np.ndarray:
        """(ny, nx) bool: cells at or above ``occupied_thresh``."""
        return self.occupancy >= self.occupied_thresh

    @property
    def free(self) -> np.ndarray:
        """(ny, nx) bool: known cells at or below ``free_thresh``."""
        return (self.occupancy != UNKNOWN) & (self.occupancy <= self.free_thresh)

    @property
    def unknown(self) -> np.ndarray:
        return ~(self.occupied | self.free)

    def cell_of(
        self, x: np.ndarray | float, y: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices of the cells holding the points (may lie outside)."""
        col = np.floor((np.asarray(x, dtype=float) - self.origin[0]) / self.resolution)
        row = np.floor((np.asarray(y, dtype=float) - self.origin[1]) / self.resolution)
        return row.astype(np.int64), col.astype(np.int64)

    def center_of(
        self, row: np.ndarray | int, col: np.ndarray | int
    ) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) in metres of the centres of cells (row, col)."""
        x = self.origin[0] + (np.asarray(col, dtype=float) + 0.5) * self.resolution
        y = self.origin[1] + (np.asarray(row, dtype=float) + 0.5) * self.resolution
        return x, y
