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
