"""An object's height from the rows its best patches were found in, across views.

The grid gives an object's place on the floor plan; the patch rows give the rest. In each view,
the column that looks toward the plan estimate has a best-matching bump of patch rows, and the
bump's centre is a ray at a known elevation (``CameraModel.pixel_rays``: through the tilt and
the lens). At the estimate's horizontal distance ``d`` from the camera, the ray is at height
``camera_height + d tan(e)``. One view's answer is coarse (patch rows are 16 px apart: 2.3
degrees, 0.12 m at 3 m) and a view that does not really see the object answers at random, so
the height is the weighted median over views, each weighted by how much its column stands out
from the rest of its frame (its match above the frame's median column), by what the camera
could see there (the visibility profile, when the mission has one) and by its nearness (a
row's error in height grows with the distance).

Angles in radians, lengths in metres; elevation is positive above the horizontal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from twin.core.errors import InputError
from twin.core.geometry import CameraModel
from twin.core.visibility import ColumnVisibility, SupportLevels

# A best patch's row gives its elevation to about this: rows are 2.3 degrees apart and the
# bump's centre is refined between them; the lens and the tilt add a little.
ELEVATION_SIGMA = math.radians(1.5)


def best_patch_elevations(
    scores: np.ndarray, boxes: np.ndarray, camera: CameraModel, tilt: float
) -> np.ndarray:
    """(objects, columns) elevation (radians) of each column's best patch, refined between rows.

    ``scores`` is the detector's (objects, rows, columns) patch scores of one frame and
    ``boxes`` its (rows, columns, 4) patch boxes [x0, y0, x1, y1] in pixels.
    """
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 3 or scores.shape[1:] != boxes.shape[:2]:
        raise InputError(
            f"scores {scores.shape} do not match the patch grid {boxes.shape[:2]} (rows, cols)"
        )
    n_rows = scores.shape[1]
    centre_u = 0.5 * (boxes[0, :, 0] + boxes[0, :, 2])  # (cols,)
    centre_v = 0.5 * (boxes[:, 0, 1] + boxes[:, 0, 3])  # (rows,)
    rows = _bump_centres(scores)
    # Row centres are evenly spaced except maybe the last (aligned with the frame's edge):
    # interpolate the pixel row through them.
    v = np.interp(rows, np.arange(n_rows), centre_v)
    u = np.broadcast_to(centre_u, v.shape)
    return camera.pixel_rays(u, v, tilt)[1]


def _bump_centres(scores: np.ndarray) -> np.ndarray:
    """(objects, columns) fractional row of the centre of each column's best bump: the rows
    next to the best one whose score stays above half-way between the column's median and its
    best, averaged with weights by how far above that level they are. An object taller than
    a patch lights several rows, and its centre lies between them, not in the best one."""
    n_objects, n_rows, n_cols = scores.shape
    best = scores.argmax(axis=1)
    peak = scores.max(axis=1)
    level = 0.5 * (peak + np.median(scores, axis=1))
    centres = best.astype(float)
    for k in range(n_objects):
        for c in range(n_cols):
            column, top, floor = scores[k, :, c], best[k, c], level[k, c]
            lo = top
            while lo > 0 and column[lo - 1] > floor:
                lo -= 1
            hi = top
            while hi < n_rows - 1 and column[hi + 1] > floor:
                hi += 1
            weights = column[lo : hi + 1] - floor
            if weights.sum() > 0.0:
                centres[k, c] = float(np.dot(np.arange(lo, hi + 1), weights) / weights.sum())
    return centres


@dataclass(frozen=True)
class HeightEstimate:
    """An object's height (m above the floor), the views that voted and the weighted median
    absolute deviation of their answers (m): how much they agreed. Once placed on a surface
    (``on_surface``), ``surface`` is that surface's height and ``measured`` what the rows
    said; both are None before."""

    z: float
    views: int
    spread: float
    surface: float | None = None
    measured: float | None = None

    def on_surface(
        self, levels: np.ndarray, object_height: float, tolerance: float = 0.1
    ) -> HeightEstimate:
        """The object standing on the surface of ``levels`` (m, NaN ignored) that fits the
        rows' height (``height_fits``) and whose standing object's centre, ``object_height``
        / 2 above it, is nearest it; unchanged when none fits.

        Why: the rows are biased toward what the object stands on. A patch that holds the
        object's lower half and the wooden desk under it matches better than one that holds
        its upper half and the wall behind it (measured: a rice box on a 0.755 m desk read
        0.71 m from four views, 0.2 m under its centre, and crates on the floor read 0.24-0.27
        m for their 0.13 m centre). The rows are still good to a surface: desks, seats and
        shelves lie further apart than that bias. A robot that knows the room's surfaces
        knows how high an object on one of them stands."""
        levels = np.asarray(levels, dtype=float).ravel()
        levels = np.unique(levels[np.isfinite(levels)])
        fitting = levels[_fits(np.full(len(levels), self.z), levels[:, None], object_height,
                               tolerance)]  # fmt: skip
        if len(fitting) == 0:
            return self
        centres = fitting + 0.5 * object_height
        best = int(np.argmin(np.abs(centres - self.z)))
        return replace(self, z=float(centres[best]), surface=float(fitting[best]), measured=self.z)


def height_fits(z: float, levels: np.ndarray, object_height: float, tolerance: float = 0.1) -> bool:
    """Whether an object whose centre is ``z`` m up could stand on one of ``levels`` (support
    heights in m, NaN ignored): its centre lies between a surface and ``object_height`` above
    it, give or take ``tolerance`` (what a height from patch rows is good to). A peak in front
    of a bookcase whose views put the object 1.3 m above a bare floor is a bearing crossing,
    not an object; ``levels`` from ``SupportLevels.anywhere`` accept every height."""
    levels = np.asarray(levels, dtype=float).ravel()
    return bool(_fits(np.asarray(z, dtype=float), levels, object_height, tolerance))


def _fits(
    z: np.ndarray, levels: np.ndarray, object_height: float, slack: float | np.ndarray
) -> np.ndarray:
    """Whether each height ``z`` (...) lies between one of its ``levels`` (..., k; NaN: none)
    and ``object_height`` above it, give or take ``slack`` (broadcast with ``z``)."""
    z, slack = z[..., None], np.asarray(slack)[..., None]
    with np.errstate(invalid="ignore"):
        return ((levels - slack <= z) & (z <= levels + object_height + slack)).any(axis=-1)


@dataclass(frozen=True)
class HeightCheck:
    """Where along a column an object could be that its best patch's row shows: a bearing is
    a wedge on the plan, but the row is an elevation, and an object stands on a surface. At
    distance ``d`` the row's ray is ``camera_height + d tan(e)`` up; a cell of the wedge counts
    in full only where that height fits one of its ``supports`` (``height_fits``: between a
    surface and ``object_height`` above it, with ``tolerance`` plus the row's uncertainty at
    that distance), and by ``outside`` elsewhere.

    Why: without it every cell of a wedge gains alike, so the bearings toward a look-alike on
    a bookcase's top shelf cross on the bare floor in front of it and make a peak there, and a
    crate on the floor, seen only from afar with the head level, is smeared along its wedge.
    ``outside`` > 0 keeps a wrong row (the best patch on something above the object in the
    same column) from erasing a view.
    """

    supports: SupportLevels
    object_height: float
    tolerance: float = 0.1
    outside: float = 0.1

    def weights(
        self,
        origin: tuple[float, float],
        wedges: np.ndarray,
        elevations: np.ndarray,
        camera_height: float,
        step: float,
        bins: int,
    ) -> np.ndarray:
        """(columns, bins) weights in [``outside``, 1] for distance bins of ``step`` m along
        each column's centre ray; a column without an elevation (NaN) keeps 1 everywhere."""
        wedges = np.asarray(wedges, dtype=float)
        elevation = np.asarray(elevations, dtype=float)
        centre = 0.5 * (wedges[:, 0] + wedges[:, 1])
        distance = (np.arange(bins) + 0.5) * step
        x = origin[0] + np.cos(centre)[:, None] * distance[None, :]
        y = origin[1] + np.sin(centre)[:, None] * distance[None, :]
        levels = self.supports.sample(x, y)  # (columns, bins, k)
        z = camera_height + distance[None, :] * np.tan(np.nan_to_num(elevation))[:, None]
        slack = self.tolerance + distance * math.tan(ELEVATION_SIGMA)
        out = np.where(_fits(z, levels, self.object_height, slack), 1.0, self.outside)
        out[~np.isfinite(elevation)] = 1.0
        return out

    def shape(
        self,
        seen: ColumnVisibility,
        origin: tuple[float, float],
        wedges: np.ndarray,
        elevations: np.ndarray,
        camera_height: float,
    ) -> ColumnVisibility:
        """``seen`` weighed by ``weights``: what a column could see and its row allows."""
        bins = seen.profiles.shape[1]
        weights = self.weights(origin, wedges, elevations, camera_height, seen.step, bins)
        return ColumnVisibility(seen.profiles * weights, seen.step)


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The value at which the weights' cumulative share first reaches one half."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def estimate_height(
    target: tuple[float, float],
    origins: np.ndarray,
    wedges: np.ndarray,
    values: np.ndarray,
    elevations: np.ndarray,
    camera_heights: np.ndarray,
    visibility: list[np.ndarray | None] | None = None,
    visibility_step: np.ndarray | None = None,
    max_range: float | None = None,
) -> HeightEstimate | None:
    """The height of an object standing at plan position ``target`` (module docstring).

    Per view i (n views, c columns): ``origins`` (n, 2) the camera's plan position, ``wedges``
    (n, c, 2) the columns' bearing intervals in the map, ``values`` (n, c) the object's column
    matches, ``elevations`` (n, c) its best patches' elevations (NaN: unknown), and
    ``camera_heights`` (n,). ``visibility[i]`` (c, bins) and ``visibility_step[i]`` (m), when
    given, weigh each view by what its camera could see at the target's distance. None when
    no view looks toward the target.
    """
    origins = np.asarray(origins, dtype=float).reshape(-1, 2)
    if len(origins) == 0:
        return None
    values = np.asarray(values, dtype=float)
    dx, dy = target[0] - origins[:, 0], target[1] - origins[:, 1]
    distance = np.hypot(dx, dy)
    bearing = np.arctan2(dy, dx)
    lo, hi = wedges[..., 0], wedges[..., 1]
    # the bearing wrapped into each wedge's turn: inside when it does not pass the far edge
    inside = lo + np.mod(bearing[:, None] - lo, 2.0 * math.pi) <= hi
    near = distance > 1e-6
    if max_range is not None:
        near &= distance <= max_range
    looking = inside.any(axis=1) & near
    column = np.argmax(np.where(inside, values, -np.inf), axis=1)
    rows = np.arange(len(origins))
    elevation = np.asarray(elevations, dtype=float)[rows, column]
    weight = values[rows, column] - np.median(values, axis=1)
    if visibility is not None and visibility_step is not None:
        for i in np.flatnonzero(looking):
            if visibility[i] is None or visibility_step[i] <= 0.0:
                continue
            profile = visibility[i][column[i]]
            b = int(distance[i] / visibility_step[i])
            weight[i] *= float(profile[b]) if b < len(profile) else 0.0
    # A row's error in height grows with the distance: nearer views say more.
    weight = weight / np.maximum(distance, 1e-6)
    voting = looking & np.isfinite(elevation) & (weight > 0.0)
    if not voting.any():
        return None
    heights = np.asarray(camera_heights, dtype=float)[voting] + distance[voting] * np.tan(
        elevation[voting]
    )
    weights = weight[voting]
    median = weighted_median(heights, weights)
    spread = weighted_median(np.abs(heights - median), weights)
    return HeightEstimate(median, len(heights), spread)
