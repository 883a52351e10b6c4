"""Every view of a mission as numbers, so the mission can be fused again without flying it.

A view's contribution to the grid is fully described by where the camera stood (its plan
position), the bearing wedges of its patch columns, each object's column values and, when a
visibility model ran, the columns' visibility profiles. ``ViewLog`` keeps these for every view
(refused ones too, marked), is saved in the run folder as ``views.npz`` with each checkpoint,
and ``fuse_into`` replays it into any grid: another fusion rule, with or without visibility, with
direction bins, or the first k views only. Replaying with the mission's own settings gives the
mission's grid exactly (tested), so what a comparison of rules measures is the rule alone: the
robot, the frames and the detector are the same.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from twin.core.errors import FileFormatError, InputError
from twin.core.grid import AccumulatorGrid
from twin.core.height import HeightCheck, HeightEstimate, estimate_height
from twin.core.store import load_arrays, save_arrays
from twin.core.visibility import ColumnVisibility

VIEW_LOG_FORMAT = "twin-view-log"
VIEW_LOG_VERSION = 1


@dataclass(frozen=True)
class LoggedView:
    """One view: the camera's plan position (m), its columns' bearing intervals (n, 2) in
    radians, each object's n column values (NaN for an object the view was not taken for),
    the visibility profiles (or None) and whether the
    mission fused it (a view whose pose was too uncertain is logged but not fused); and, for
    heights (``twin.core.height``), each object's best-patch elevation per column (radians;
    None in logs written before heights were kept) and the camera's height (m)."""

    origin: tuple[float, float]
    wedges: np.ndarray
    values: dict[str, np.ndarray]
    visibility: ColumnVisibility | None
    fused: bool = True
    elevations: dict[str, np.ndarray] | None = None
    camera_height: float = 1.0


def fuse_view(
    grid: AccumulatorGrid,
    view: LoggedView,
    max_range: float | None,
    *,
    visibility: bool = True,
    height_check: HeightCheck | Mapping[str, HeightCheck] | None = None,
) -> None:
    """Fuse one view into ``grid`` (every object it holds), with its visibility profiles unless
    ``visibility`` is False; with a ``height_check`` (one for all objects, or each object's
    own) each object's profiles are weighed by where its best patches' rows allow it to stand
    (``twin.core.height.HeightCheck``), one object at a time."""
    seen = view.visibility if visibility else None
    # A view taken for some objects only (NaN values for the rest) is fused into theirs.
    names = [name for name in grid.objects if np.isfinite(view.values[name]).all()]
    if not names:
        return
    if height_check is None or seen is None or view.elevations is None:
        values = {name: view.values[name] for name in names}
        grid.fuse_all(view.origin, view.wedges, values, max_range, seen)
        return
    for name in names:
        check = height_check[name] if isinstance(height_check, Mapping) else height_check
        shaped = check.shape(
            seen, view.origin, view.wedges, view.elevations[name], view.camera_height
        )
        grid.fuse_all(view.origin, view.wedges, {name: view.values[name]}, max_range, shaped)


class ViewLog:
    """The views of one mission, in order (see the module docstring)."""

    def __init__(self, objects: Sequence[str], max_range: float | None) -> None:
        if not objects:
            raise InputError("a view log needs at least one object")
        self.objects = tuple(objects)
        self.max_range = max_range
        self.views: list[LoggedView] = []

    def __len__(self) -> int:
        return len(self.views)

    def append(self, view: LoggedView) -> None:
        if sorted(view.values) != sorted(self.objects):
            raise InputError(f"a logged view must give values for {list(self.objects)}")
        if self.views and view.wedges.shape != self.views[0].wedges.shape:
            raise InputError(
                f"a logged view has {len(view.wedges)} columns, the log's views "
                f"{len(self.views[0].wedges)}; one mission's views share one detector"
            )
        self.views.append(view)

    def truncate(self, n: int) -> None:
        """Keep the first ``n`` views (a resumed mission continues after its last checkpoint)."""
        del self.views[n:]

    def fuse_into(
        self,
        grid: AccumulatorGrid,
        *,
        visibility: bool = True,
        views: int | None = None,
        only_fused: bool = True,
        height_check: HeightCheck | Mapping[str, HeightCheck] | None = None,
    ) -> AccumulatorGrid:
        """Fuse the first ``views`` views (all by default) into ``grid``, as the mission did;
        ``visibility`` False ignores the logged profiles (the paper's "every cell in a wedge is
        seen"); ``only_fused`` skips the views the mission refused; ``height_check`` the
        mission's (``fuse_view``). Returns ``grid``."""
        for view in self.views[:views]:
            if only_fused and not view.fused:
                continue
            fuse_view(grid, view, self.max_range, visibility=visibility, height_check=height_check)
        return grid

    # -- files ---------------------------------------------------------------------------

    def save(self, path: str | os.PathLike[str], compress: bool = True) -> Path:
        """Write the log atomically (``.npz`` with a JSON header; ``compress=False``: faster,
        larger)."""
        n = len(self.views)
        columns = self.views[0].wedges.shape[0] if n else 0
        bins = max((v.visibility.profiles.shape[1] for v in self.views if v.visibility), default=0)
        profiles = np.zeros((n, columns, bins))
        steps = np.zeros(n)
        widths = np.zeros(n, dtype=np.int64)
        for i, view in enumerate(self.views):
            if view.visibility is not None:
                widths[i] = view.visibility.profiles.shape[1]
                profiles[i, :, : widths[i]] = view.visibility.profiles
                steps[i] = view.visibility.step
        header = {"objects": list(self.objects), "max_range": self.max_range}
        arrays = {
            "origins": np.array([v.origin for v in self.views], dtype=float).reshape(n, 2),
            "wedges": np.array([v.wedges for v in self.views], dtype=float).reshape(n, columns, 2),
            "values": np.array(
                [[v.values[name] for name in self.objects] for v in self.views], dtype=float
            ).reshape(n, len(self.objects), columns),
            "profiles": profiles,
            "profile_steps": steps,
            "profile_bins": widths,
            "fused": np.array([v.fused for v in self.views], dtype=bool),
            "elevations": np.array(
                [
                    [
                        v.elevations[name] if v.elevations else np.full(columns, np.nan)
                        for name in self.objects
                    ]
                    for v in self.views
                ],
                dtype=float,
            ).reshape(n, len(self.objects), columns),
            "camera_heights": np.array([v.camera_height for v in self.views], dtype=float),
        }
        return save_arrays(path, VIEW_LOG_FORMAT, VIEW_LOG_VERSION, header, arrays, compress)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ViewLog:
        """Read a log written by ``save``; a defect is a one-line ``FileFormatError``."""
        header, arrays = load_arrays(path, VIEW_LOG_FORMAT, VIEW_LOG_VERSION)
        try:
            objects = [str(name) for name in header["objects"]]
            max_range = header["max_range"]
            origins, wedges, values = arrays["origins"], arrays["wedges"], arrays["values"]
            profiles, steps, fused = arrays["profiles"], arrays["profile_steps"], arrays["fused"]
            # Logs written before the reach was kept: every view of a mission had the same.
            widths = arrays.get("profile_bins", np.full(len(steps), profiles.shape[2]))
            n = len(origins)
            # Logs written before heights were kept have no elevations.
            elevations = arrays.get("elevations", np.full(values.shape, np.nan))
            camera_heights = arrays.get("camera_heights", np.ones(n))
            consistent = (
                wedges.shape[:1] == values.shape[:1] == profiles.shape[:1] == (n,)
                and len(steps) == len(fused) == len(widths) == len(camera_heights) == n
                and elevations.shape == values.shape
                and values.shape[1] == len(objects)
                and bool(np.all(widths <= profiles.shape[2]))
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FileFormatError(f"{path}: not a complete view log ({exc})") from None
        if not consistent:
            raise FileFormatError(f"{path}: the view log's arrays disagree in size; it is damaged")
        log = cls(objects, None if max_range is None else float(max_range))
        for i in range(n):
            seen = None
            if steps[i] > 0:
                # Each view's own reach: beyond it a ranged rule's views count no coverage.
                seen = ColumnVisibility(profiles[i, :, : widths[i]], float(steps[i]))
            log.append(
                LoggedView(
                    (float(origins[i, 0]), float(origins[i, 1])),
                    wedges[i],
                    {name: values[i, k] for k, name in enumerate(objects)},
                    seen,
                    bool(fused[i]),
                    None
                    if np.isnan(elevations[i]).all()
                    else {name: elevations[i, k] for k, name in enumerate(objects)},
                    float(camera_heights[i]),
                )
            )
        return log

    def height(self, name: str, target: tuple[float, float]) -> HeightEstimate | None:
        """How high object ``name`` stands at plan position ``target`` (m), from the rows its
        best patches were found in across the fused views (``twin.core.height``); None when
        no fused view with elevations looks toward it."""
        views = [v for v in self.views if v.fused and v.elevations is not None]
        if not views:
            return None
        return estimate_height(
            target,
            np.array([v.origin for v in views], dtype=float),
            np.array([v.wedges for v in views], dtype=float),
            np.array([v.values[name] for v in views], dtype=float),
            np.array([v.elevations[name] for v in views], dtype=float),
            np.array([v.camera_height for v in views], dtype=float),
            [v.visibility.profiles if v.visibility else None for v in views],
            np.array([v.visibility.step if v.visibility else 0.0 for v in views]),
            self.max_range,
        )
