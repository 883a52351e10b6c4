"""What a camera could have seen: per patch column, how visible an object would be at each
distance along the column's wedge.

A detector's silence is evidence against an object only where the object could have been seen:
a column looking at the back of the sofa says nothing about the coffee table behind it. A view's
``ColumnVisibility`` holds, for each of its patch columns, a profile over distance from the
camera (bins of ``step`` metres): 1 where an object standing there would have been in view, 0
where something hid it or the camera's field of view missed it, fractions in between. The grid
weighs each wedge's coverage of a cell by the profile at the cell's distance
(``twin.core.coverage.add_coverage``), so a hidden cell neither gains nor loses. How profiles are
made (from rendered depth in the twin, from the twin's model rendered at the robot's localized
pose on the robot) is the business of the layers above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError


@dataclass(frozen=True)
class ColumnVisibility:
    """``profiles`` (n_columns, n_bins) in [0, 1]: column c's visibility of an object whose
    distance from the camera falls in bin b = floor(d / ``step``); beyond the last bin, none."""

    profiles: np.ndarray
    step: float

    def __post_init__(self) -> None:
        profiles = np.ascontiguousarray(self.profiles, dtype=float)
        if profiles.ndim != 2 or profiles.shape[1] == 0:
            raise InputError(
                f"visibility profiles must be (columns, bins), got shape {profiles.shape}"
            )
        if not np.all(np.isfinite(profiles)) or profiles.min() < 0 or profiles.max() > 1:
            raise InputError("visibility profiles must be finite values in [0, 1]")
        if not (math.isfinite(self.step) and self.step > 0):
            raise InputError(f"visibility step must be a positive distance, got {self.step!r}")
        object.__setattr__(self, "profiles", profiles)

    @property
    def reach(self) -> float:
        """Metres covered by the profiles."""
        return self.profiles.shape[1] * self.step

    @classmethod
    def everywhere(cls, columns: int, reach: float, step: float = 0.05) -> ColumnVisibility:
        """Every column sees everything up to ``reach`` metres (the paper's assumption)."""
        return cls(np.ones((columns, max(1, math.ceil(reach / step)))), step)


@dataclass(frozen=True)
class SupportLevels:
    """Where an object could stand: per cell of a plan grid, the heights (m above the floor) of
    the horizontal surfaces there (the floor, seats, table tops, shelves), NaN-padded.

    ``levels`` is (ny, nx, k), row 0 at ``y_min``; outside the grid only the floor (0 m) is a
    support. Visibility asks whether an object standing on some support of a cell would have been
    in view; without a model of the room, ``anywhere`` offers every height up to ``max_height``.
    """

    x_min: float
    y_min: float
    cell_size: float
    levels: np.ndarray

    def __post_init__(self) -> None:
        levels = np.asarray(self.levels, dtype=float)
        if levels.ndim != 3 or levels.shape[2] == 0 or min(levels.shape[:2]) == 0:
            raise InputError(f"support levels must be (rows, cols, k), got shape {levels.shape}")
        finite = levels[np.isfinite(levels)]
        if finite.size and finite.min() < 0:
            raise InputError("support levels must be heights >= 0 m above the floor")
        if not (math.isfinite(self.cell_size) and self.cell_size > 0):
            raise InputError(f"support cell size must be positive, got {self.cell_size!r}")
        object.__setattr__(self, "levels", levels)

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(..., k) support heights under the points (x, y) (metres), NaN-padded."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        ny, nx, k = self.levels.shape
        col = np.floor((x - self.x_min) / self.cell_size).astype(int)
        row = np.floor((y - self.y_min) / self.cell_size).astype(int)
        inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        floor_only = np.full(k, np.nan)
        floor_only[0] = 0.0
        out = np.broadcast_to(floor_only, (*x.shape, k)).copy()
        out[inside] = self.levels[row[inside], col[inside]]
        return out

    @classmethod
    def anywhere(
        cls,
        extent: tuple[float, float, float, float],
        cell_size: float = 0.1,
        max_height: float = 2.0,
        step: float = 0.2,
    ) -> SupportLevels:
        """No model of the room: an object may stand at any height from 0 to ``max_height``."""
        x_min, y_min, x_max, y_max = extent
        nx = max(1, math.ceil((x_max - x_min) / cell_size))
        ny = max(1, math.ceil((y_max - y_min) / cell_size))
        heights = np.arange(0.0, max_height + 1e-9, step)
        return cls(x_min, y_min, cell_size, np.broadcast_to(heights, (ny, nx, len(heights))))
