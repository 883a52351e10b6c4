"""The views a search may take, and what each could see: computed once per scene, then cached.

A candidate view is a place on a lattice of the free floor (``spacing`` metres, where the
robot's disc fits on the planning map) and one of ``headings`` directions the camera's optical
axis may face there. Its footprint (``twin.core.view_gain.Footprints``) holds, per patch column,
the share of every grid cell the column's wedge covers times how visible an object standing
there would be from that place (``twin.core.visibility``, from the room's model rendered at the
candidate's camera pose: the twin's own depth exists only for views already taken).

Only columns whose pixel spans do not overlap are kept (the detector's columns step by half a
patch): the view's expected information is then a sum over disjoint wedges.

Building them renders one depth image per candidate (about 7 ms each on the software renderer),
so the candidates of a scene are cached in ``run.cache``: the key holds the scene file's
content, the camera, the columns, the grid, the lattice and the visibility settings.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.core.coverage import add_coverage
from twin.core.devices import View
from twin.core.errors import FileFormatError, InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.grid import GridSpec
from twin.core.store import load_arrays, save_arrays
from twin.core.view_gain import Footprints

CANDIDATES_KIND = "twin-search-candidates"
CANDIDATES_VERSION = 1
FOOTPRINT_SUPERSAMPLE = 4  # sub-cells per side: a planner's estimate, not the grid's evidence
SHARE_FLOOR = 1e-3  # entries below this are dropped (a sliver of a cell, or a hidden one)


def disjoint_columns(spans: np.ndarray) -> np.ndarray:
    """Indices of patch columns whose pixel spans tile the frame without overlapping (greedy
    from the left): the detector's overlapping columns would count one cell twice."""
    keep, right = [], -math.inf
    for i, (u0, u1) in enumerate(np.asarray(spans, dtype=float)):
        if u0 >= right:
            keep.append(i)
            right = u1
    return np.array(keep, dtype=int)


@dataclass(frozen=True)
class DetectionRates:
    """A detector's column as a binary detector: it fires at score >= ``threshold``, with false-
    positive rate ``fpr`` and true-positive rate ``tpr`` per distance band (``ranges``: the
    K-1 band edges in metres, ``tpr``: K rates)."""

    threshold: float
    fpr: float
    tpr: tuple[float, ...]
    ranges: tuple[float, ...] = ()

    def tpr_at(self, distance: np.ndarray) -> np.ndarray:
        band = np.searchsorted(np.asarray(self.ranges), distance, side="right")
        return np.asarray(self.tpr)[band]

    @property
    def contrast(self) -> float:
        """The best TPR - FPR: the lift of a fully seen cell at the detector's best range."""
        return max(max(self.tpr) - self.fpr, 1e-6)


def detection_rates(calibration: Any) -> DetectionRates:
    """The rates of a ``twin.rfch.calibration.ScoreCalibration`` at the threshold that best
    separates on from off (Youden's J: TPR - FPR largest), per distance band when it has them."""
    edges = np.asarray(calibration.edges)
    on = np.asarray(calibration.on_counts, dtype=float)
    off = np.asarray(calibration.off_counts, dtype=float)
    tpr_all = np.cumsum(on[::-1])[::-1] / on.sum()  # P(score >= edges[k] | on), k = 0..B-1
    fpr_all = np.cumsum(off[::-1])[::-1] / off.sum()
    k = int(np.argmax(tpr_all - fpr_all))
    fpr = float(np.clip(fpr_all[k], 1e-4, 0.5))
    bands = [np.asarray(row, dtype=float) for row in calibration.range_on_counts]
    if bands and all(row.sum() > 0 for row in bands):
        tpr = tuple(float(row[k:].sum() / row.sum()) for row in bands)
        ranges = tuple(float(r) for r in calibration.ranges)
    else:
        tpr, ranges = (float(tpr_all[k]),), ()
    tpr = tuple(min(max(t, fpr), 0.999) for t in tpr)
    return DetectionRates(float(edges[k]), fpr, tpr, ranges)


@dataclass(frozen=True)
class Candidates:
    """Every view a search may take: ``places`` (P, 2) metres, ``headings`` (H,) radians (the
    optical axis, map frame); view v = place v // H facing heading v % H. ``footprints`` holds
    the shares (coverage x visibility); ``distance`` (nnz,) the metres from the view's place to
    each entry's cell centre, for a detector's rate at that range."""

    places: np.ndarray
    headings: np.ndarray
    footprints: Footprints
    distance: np.ndarray

    @property
    def n_views(self) -> int:
        return len(self.places) * len(self.headings)

    def place_of(self, view: int) -> int:
        return view // len(self.headings)

    def heading_of(self, view: int) -> float:
        return float(self.headings[view % len(self.headings)])

    def for_detector(self, rates: DetectionRates) -> Footprints:
        """The footprints with each entry's lift: share x (TPR at its distance - FPR)."""
        f = self.footprints
        lift = f.share * np.maximum(rates.tpr_at(self.distance) - rates.fpr, 0.0)
        return Footprints(f.indptr, f.cells, f.share, lift, f.row_view, f.n_views, f.n_cells)

    def nearest(self, x: float, y: float, heading: float) -> tuple[int, float, float]:
        """(view index, metres, radians) of the candidate nearest to a view taken at (x, y)
        facing ``heading``."""
        gaps = np.hypot(self.places[:, 0] - x, self.places[:, 1] - y)
        place = int(np.argmin(gaps))
        turns = np.abs((self.headings - heading + math.pi) % (2 * math.pi) - math.pi)
        h = int(np.argmin(turns))
        return place * len(self.headings) + h, float(gaps[place]), float(turns[h])


def lattice_places(blocked: np.ndarray, origin: tuple[float, float], resolution: float,
                   spacing: float) -> np.ndarray:  # fmt: skip
    """(P, 2) points of a square lattice of ``spacing`` metres over a planning map whose cells
    are not ``blocked`` (the robot's disc fits there), aligned to the map's origin."""
    ny, nx = blocked.shape
    x0, y0 = origin
    xs = x0 + np.arange(spacing / 2, nx * resolution, spacing)
    ys = y0 + np.arange(spacing / 2, ny * resolution, spacing)
    gx, gy = np.meshgrid(xs, ys)
    cols = np.floor((gx - x0) / resolution).astype(int)
    rows = np.floor((gy - y0) / resolution).astype(int)
    free = ~blocked[np.clip(rows, 0, ny - 1), np.clip(cols, 0, nx - 1)]
    return np.stack([gx[free], gy[free]], axis=1)


def build_candidates(
    places: np.ndarray,
    headings: int,
    spec: GridSpec,
    camera: CameraModel,
    spans: np.ndarray,
    visibility: Any | None,
    reach: float,
    tilt: float = 0.0,
) -> Candidates:
    """The footprints of every place x heading. ``visibility`` is a
    ``twin.app.mission.VisibilityModel`` that can render any pose (a "model" or "map" source),
    or None: every cell in a wedge is seen (the paper's assumption)."""
    if len(places) == 0:
        raise InputError(
            "no place on the map where the robot fits: check the map, or a smaller search.spacing_m"
        )
    spans = np.asarray(spans, dtype=float)[disjoint_columns(spans)]
    angles = np.arange(headings) * (2 * math.pi / headings)
    n_cols = len(spans)
    xs, ys = spec.cell_centers()
    image = np.zeros((camera.height, camera.width, 3), dtype=np.uint8)
    indptr, cells, shares, distances = [0], [], [], []
    eye = np.eye(n_cols)
    dense = np.zeros((n_cols, *spec.shape))
    for x, y in places:
        far = np.hypot(xs - x, ys - y).ravel()
        for axis in angles:
            pose = Pose2D(float(x), float(y), float(axis))
            wedges = camera.wedges(pose, 0.0, spans)
            profiles, step = np.zeros((1, 0, 0)), 1.0
            if visibility is not None:
                seen = visibility.profiles(View(image, pose, 0.0, tilt, 0.0), camera, spans)
                profiles, step = seen.profiles[None], seen.step
            dense[:] = 0.0
            add_coverage(
                dense, float(x), float(y), np.ascontiguousarray(wedges[:, 0]),
                np.ascontiguousarray(wedges[:, 1]), eye, spec.x_min, spec.y_min,
                spec.cell_size, FOOTPRINT_SUPERSAMPLE, reach, profiles, step,
            )  # fmt: skip
            flat = dense.reshape(n_cols, -1)
            for r in range(n_cols):
                keep = np.flatnonzero(flat[r] > SHARE_FLOOR)
                cells.append(keep)
                shares.append(flat[r, keep])
                distances.append(far[keep])
                indptr.append(indptr[-1] + len(keep))
    n_views = len(places) * headings
    cell_index = np.concatenate(cells)
    share = np.clip(np.concatenate(shares), 0.0, 1.0)
    footprints = Footprints(
        np.array(indptr), cell_index, share, share.copy(),
        np.repeat(np.arange(n_views), n_cols), n_views, spec.nx * spec.ny,
    )  # fmt: skip
    return Candidates(np.asarray(places, float), angles, footprints, np.concatenate(distances))


def candidates_key(scene: Path, **settings: Any) -> str:
    """A cache key: the scene file's content and every setting the footprints depend on."""
    digest = hashlib.sha256(Path(scene).read_bytes())
    digest.update(json.dumps(settings, sort_keys=True, default=_plain).encode())
    return digest.hexdigest()[:20]


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.round(9).tolist()
    return repr(value)


def save_candidates(path: Path, candidates: Candidates, key: str) -> None:
    f = candidates.footprints
    save_arrays(
        path,
        CANDIDATES_KIND,
        CANDIDATES_VERSION,
        {"key": key, "n_cells": f.n_cells},
        {
            "places": candidates.places,
            "headings": candidates.headings,
            "indptr": f.indptr,
            "cells": f.cells.astype(np.int32),
            "share": f.share.astype(np.float32),
            "row_view": f.row_view.astype(np.int32),
            "distance": candidates.distance.astype(np.float32),
        },
    )


def load_candidates(path: Path, key: str) -> Candidates | None:
    """The cached candidates for ``key``, or None if there are none (or they are stale or
    unreadable: they are rebuilt, nothing is lost)."""
    if not path.is_file():
        return None
    try:
        header, a = load_arrays(path, CANDIDATES_KIND, CANDIDATES_VERSION)
        if header.get("key") != key:
            return None
        share = a["share"].astype(float)
        places, headings = a["places"], a["headings"]
        footprints = Footprints(
            a["indptr"], a["cells"].astype(np.int64), share, share.copy(),
            a["row_view"].astype(np.int64), len(places) * len(headings), int(header["n_cells"]),
        )  # fmt: skip
        return Candidates(places, headings, footprints, a["distance"].astype(float))
    except (FileFormatError, KeyError, InputError, ValueError):
        return None
