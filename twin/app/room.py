"""What the room looks like to the detector without the sought object: a baseline per cell.

A persistent look-alike — the fruit bowl that scores like the rice box from every stop — gains
evidence every time it is seen, and the estimate goes to it whenever the target is weakened.
The twin knows the room: the calibration's frames (other poses than any mission's, the lights
varied) are fused, the object's own columns left out, into a grid; what a cell gains there per
full view of it is what the room gains it without the object. A mission's grid subtracts that,
view by view, in proportion to how much of the cell each view saw
(``AccumulatorGrid(baseline=...)``), so a cell counts only for looking more like the object than
the room usually does. Only the positive part is subtracted: the room's ordinary silence stays
evidence against the object.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from twin.app.view_log import LoggedView, ViewLog
from twin.core.fusion import FusionRule, make_rule
from twin.core.geometry import CameraModel, Pose2D
from twin.core.grid import AccumulatorGrid, GridSpec
from twin.core.visibility import ColumnVisibility, SupportLevels, TallMap, visibility_from_depth

MIN_SEEN = 1.0  # full views of a cell before its baseline is trusted
# A cell the room's views saw too little of takes the largest baseline of the trusted cells
# within this many cells (its neighbours look like it), else the room's median. Left at 0 it
# would be the one place a look-alike gains in full, and the argmax seeks exactly such places:
# the apartment's rice box lost to a 0.1 m hole in front of the living room's bookcase.
FILL_CELLS = 3


def room_log(
    name: str,
    poses: np.ndarray,
    depths: np.ndarray,
    scores: list[np.ndarray],
    truth: list[np.ndarray],
    camera: CameraModel,
    column_spans: np.ndarray,
    supports: SupportLevels,
    object_height: float,
    reach: float,
    camera_height: float = 1.0,
    tall: TallMap | None = None,
    tilt: float = 0.0,
) -> ViewLog:
    """The calibration frames as a view log of the room without ``name``: each frame's column
    scores over its wedges, visibility from its depth, and the columns that touch the object
    (``truth`` not 0) seen nowhere, so they say nothing about the room. ``tilt`` (radians) is
    the head's in every frame."""
    log = ViewLog([name], reach)
    for (x, y, yaw), depth, values, labels in zip(poses, depths, scores, truth, strict=True):
        seen = visibility_from_depth(
            depth, camera, column_spans, origin=(x, y), axis=yaw, tilt=tilt,
            camera_height=camera_height, supports=supports, object_height=object_height,
            reach=reach, tall=tall,
        )  # fmt: skip
        profiles = np.where((np.asarray(labels) == 0)[:, None], seen.profiles, 0.0)
        wedges = camera.wedges(Pose2D(x, y, yaw), 0.0, column_spans, tilt)
        visibility = ColumnVisibility(profiles, seen.step)
        log.append(LoggedView((x, y), wedges, {name: np.asarray(values)}, visibility))
    return log


def room_baselines(
    logs: Mapping[str, ViewLog],
    rules: Mapping[str, FusionRule],
    spec: GridSpec,
    supersample: int,
) -> dict[str, np.ndarray]:
    """Per object, what a full view of each cell adds to it under ``rules[name]`` in the room
    without the object (0 where it adds nothing or takes away). A cell the room's views saw
    less than ``MIN_SEEN`` times is filled from its trusted neighbours (``fill_unseen``)."""
    out = {}
    for name, log in logs.items():
        gained = AccumulatorGrid([name], spec, rules[name], supersample)
        log.fuse_into(gained)
        # How much of each cell the room's views saw (every weight 1, scaled by visibility).
        seen = AccumulatorGrid([name], spec, make_rule("accumulate"), supersample)
        for view in log.views:
            ones = {name: np.ones(len(view.wedges))}
            seen.fuse_all(view.origin, view.wedges, ones, log.max_range, view.visibility)
        share = seen.evidence(name)
        per_view = np.divide(
            gained.evidence(name), share, out=np.zeros(spec.shape), where=share >= MIN_SEEN
        )
        out[name] = fill_unseen(np.maximum(per_view, 0.0), share >= MIN_SEEN)
    return out


def fill_unseen(baseline: np.ndarray, trusted: np.ndarray, cells: int = FILL_CELLS) -> np.ndarray:
    """``baseline`` with every untrusted cell given the largest trusted value within ``cells``
    cells (a square neighbourhood, grown one ring at a time), and what is still unfilled the
    median of the trusted cells (0 if none is trusted): never less than the room says nearby,
    never a hole for the argmax to fall into."""
    out = np.where(trusted, baseline, 0.0)
    known = np.asarray(trusted, dtype=bool).copy()
    if not known.any():
        return out
    typical = float(np.median(baseline[known]))
    for _ in range(cells):
        if known.all():
            break
        grown, reached = _neighbour_max(np.where(known, out, -np.inf))
        fill = ~known & reached
        out[fill] = grown[fill]
        known |= fill
    out[~known] = typical
    return out


def _neighbour_max(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The maximum over each cell's 3 x 3 neighbourhood (``-inf`` marks no value), and where
    any neighbour had a value."""
    padded = np.pad(values, 1, constant_values=-np.inf)
    ny, nx = values.shape
    best = np.max(
        [padded[dy : dy + ny, dx : dx + nx] for dy in range(3) for dx in range(3)], axis=0
    )
    return best, np.isfinite(best)
