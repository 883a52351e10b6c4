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
pose on the robot) is the business of the layers above; ``visibility_from_depth`` turns any
of them into profiles.

How a profile is computed from depth (the project's decision on heights). For patch column c
(pixels [u0, u1]) and distance bin b (centre r metres, horizontal, from the camera's optical
centre): a few pixel columns u are sampled evenly inside the span; for each, the point at
horizontal distance r along u's bearing lies over some plan cell, and an object could stand on
any of that cell's support levels h (``SupportLevels.sample``). A sample point of the object,
at height h + f * object_height (f in 0.25, 0.5, 0.75), is *seen* from u if it projects inside
the image (through the pinhole, given the camera's height and tilt) and the depth along that
pixel's ray is at least the distance to the point minus a tolerance: the object's own
half-width plus half a cell (0.2 m by default), because when the object is there it is itself
what the depth hits. A NaN depth (nothing within range) hides nothing. The object is as visible
from u as the share of its sample points seen, on its best-seen level; the profile value is the
mean over the sampled pixel columns. An object half hidden behind the sofa's arm is half
visible: a detector sees half an object, and its silence there says less. So a column looking
at the back of the sofa sees the shelf above and behind it but not the floor or the seat behind
it, and the floor at the camera's feet, below the vertical field of view, is seen by no column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from twin.core.errors import InputError
from twin.core.geometry import CameraModel


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
class TallMap:
    """Plan cells (row 0 at ``y_min``, ``cell_size`` m) covered by something no camera on the
    robot sees over or through: walls, a wardrobe's door, a bookcase's sides, the fridge
    (``twin.sim.supports.tall_map``: one geom from 0.3 m to 1.5 m up).

    Why: the depth test lets a point stand up to its tolerance (0.2 m: half an object plus half
    a cell) behind the surface the pixel hits, because when the object is there it is itself
    that surface. A 0.1 m wall is thinner than that, so the living room's views saw the
    bedroom desk's edge through it and a look-alike gained there. Past a run of tall cells
    along a column, nothing is seen (``block_behind``); inside the run (a bookcase's own
    shelves) the depth test decides."""

    x_min: float
    y_min: float
    cell_size: float
    tall: np.ndarray  # (ny, nx) bool

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whether each point (x, y) (metres) lies in a tall cell (outside the map: no)."""
        row, col, inside = _cells_of(x, y, self.x_min, self.y_min, self.cell_size, self.tall.shape)
        out = np.zeros(row.shape, dtype=bool)
        out[inside] = self.tall[row[inside], col[inside]]
        return out


def _cells_of(
    x: np.ndarray, y: np.ndarray, x_min: float, y_min: float, cell: float, shape: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (row, col) of the plan cell under each point (metres) of a map whose row 0 is at
    ``y_min``, and whether it lies inside the map's ``shape[:2]``."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    col = np.floor((x - x_min) / cell).astype(int)
    row = np.floor((y - y_min) / cell).astype(int)
    inside = (col >= 0) & (col < shape[1]) & (row >= 0) & (row < shape[0])
    return row, col, inside


def block_behind(
    profiles: np.ndarray,
    step: float,
    origin: tuple[float, float],
    bearings: np.ndarray,
    tall: TallMap,
) -> np.ndarray:
    """``profiles`` (columns, bins) with every bin past a run of ``tall`` cells along its
    column's ``bearings`` (map frame, radians) set to 0 (``TallMap``)."""
    bins = profiles.shape[1]
    r = (np.arange(bins) + 0.5) * step
    bearings = np.asarray(bearings, dtype=float)
    x = origin[0] + np.cos(bearings)[:, None] * r
    y = origin[1] + np.sin(bearings)[:, None] * r
    inside = tall.sample(x, y)
    entered = np.maximum.accumulate(inside, axis=1)
    behind = np.maximum.accumulate(entered & ~inside, axis=1)
    return np.where(behind, 0.0, profiles)


# The kinds of surface an object may stand on, by the surface's height (metres, inclusive): the
# floor and what lies flat on it (a rug, tiles); seats, coffee, dining and bedside tables and
# desks; kitchen counters and cabinets of counter height; shelves between the 1.0 m camera and a
# reaching hand (not a bed's headboard, 1.1 m). A mission's ``stands_on`` and the twin's
# placements (``twin.sim.placement``) both name them.
SUPPORT_KINDS: dict[str, tuple[float, float]] = {
    "floor": (0.0, 0.05),
    "table": (0.3, 0.8),
    "counter": (0.8, 1.0),
    "shelf": (1.12, 1.65),
}


@dataclass(frozen=True)
class SupportLevels:
    """Where an object could stand: per cell of a plan grid, the heights (m above the floor) of
    the horizontal surfaces there (the floor, seats, table tops, shelves), NaN-padded.

    ``levels`` is (ny, nx, k), row 0 at ``y_min``; outside the grid only the floor (0 m) is a
    support. Visibility asks whether an object standing on some support of a cell would have been
    in view; without a model of the room, ``anywhere`` offers every height up to ``max_height``.
    ``surfaces`` says whether the levels are real surfaces (a model of the room) or that
    stand-in: only a real surface may say how high an object on it stands.
    """

    x_min: float
    y_min: float
    cell_size: float
    levels: np.ndarray
    surfaces: bool = True

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
        k = self.levels.shape[2]
        row, col, inside = _cells_of(
            x, y, self.x_min, self.y_min, self.cell_size, self.levels.shape
        )
        floor_only = np.full(k, np.nan)
        floor_only[0] = 0.0
        out = np.broadcast_to(floor_only, (*row.shape, k)).copy()
        out[inside] = self.levels[row[inside], col[inside]]
        return out

    def of_kinds(self, kinds: tuple[str, ...]) -> SupportLevels:
        """Only the surfaces of ``kinds`` (keys of ``SUPPORT_KINDS``): where an object that is
        known to stand on the floor, say, could be. A cell with none of them keeps none (NaN)."""
        unknown = [kind for kind in kinds if kind not in SUPPORT_KINDS]
        if unknown or not kinds:
            raise InputError(
                f"unknown kinds of support {unknown or list(kinds)}; use some of "
                f"{', '.join(SUPPORT_KINDS)}"
            )
        keep = np.zeros(self.levels.shape, dtype=bool)
        with np.errstate(invalid="ignore"):
            for kind in kinds:
                low, high = SUPPORT_KINDS[kind]
                keep |= (self.levels >= low - 1e-9) & (self.levels <= high + 1e-9)
        return SupportLevels(
            self.x_min, self.y_min, self.cell_size, np.where(keep, self.levels, np.nan),
            self.surfaces,
        )  # fmt: skip

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
        levels = np.broadcast_to(heights, (ny, nx, len(heights)))
        return cls(x_min, y_min, cell_size, levels, surfaces=False)


# Heights up an object (fractions of its height) whose views stand for it: a point near its base,
# its middle and near its top; seeing any one of them is seeing the object.
OBJECT_SAMPLE_FRACTIONS = (0.25, 0.5, 0.75)


def _check_finite(name: str, *values: float) -> None:
    for value in values:
        if not math.isfinite(value):
            raise InputError(f"visibility {name} must be finite, got {value!r}")


def visibility_from_depth(
    depth: np.ndarray,
    camera: CameraModel,
    column_spans: np.ndarray,
    *,
    origin: tuple[float, float],
    axis: float,
    tilt: float,
    camera_height: float,
    supports: SupportLevels,
    object_height: float,
    reach: float,
    step: float = 0.05,
    tolerance: float = 0.2,
    samples: int = 4,
    tall: TallMap | None = None,
) -> ColumnVisibility:
    """Per patch column, how visible an object of ``object_height`` metres would have been at
    each distance, from one view's depth (see the module docstring for the rule).

    ``depth`` is H x W metres along each pixel's ray (row 0 at the top, NaN: nothing within
    range) for ``camera``; ``column_spans`` the (n, 2) pixel spans of the patch columns;
    ``origin`` the camera's (x, y) in the map and ``camera_height`` its height (metres);
    ``axis`` the optical axis bearing in the map (base yaw + pan) and ``tilt`` its elevation
    (radians, positive up). Profiles cover ``reach`` metres in bins of ``step``; ``tolerance``
    (metres) is how far short of the point the depth may stop and still count as the object
    itself, ``samples`` the number of pixel columns sampled per patch column; with ``tall``
    nothing past a wall along a column is seen (``block_behind``).
    """
    depth = np.asarray(depth)
    if depth.shape != (camera.height, camera.width):
        raise InputError(
            f"depth image is {depth.shape} but the camera is {camera.height}x{camera.width} "
            "(rows x columns); pass the depth rendered for this camera"
        )
    spans = np.asarray(column_spans, dtype=float)
    if spans.ndim != 2 or spans.shape[1] != 2 or spans.shape[0] == 0:
        raise InputError(f"column_spans must be an (n, 2) array, got shape {spans.shape}")
    if not np.all(np.isfinite(spans)) or np.any(spans[:, 1] <= spans[:, 0]):
        raise InputError("column_spans must be finite pixel ranges [u0, u1] with u0 < u1")
    _check_finite("origin", *origin)
    _check_finite("axis, tilt and camera height", axis, tilt, camera_height)
    if not abs(tilt) < math.pi / 2:
        raise InputError(f"visibility tilt must be within +-90 degrees, got {tilt!r} rad")
    for name, value in (("object height", object_height), ("reach", reach), ("step", step)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"visibility {name} must be a positive length (m), not {value!r}")
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"visibility tolerance must be >= 0 m, got {tolerance!r}")
    if samples < 1:
        raise InputError(f"visibility needs >= 1 pixel column per patch column, got {samples}")

    bins = max(1, math.ceil(reach / step))
    r = (np.arange(bins) + 0.5) * step
    u = spans[:, :1] + (np.arange(samples) + 0.5) / samples * (spans[:, 1:] - spans[:, :1])
    bearing = np.asarray(camera.column_bearing(u), dtype=float)  # (n, S) radians off the axis
    heading = axis + bearing
    levels = supports.sample(
        origin[0] + np.cos(heading)[..., None] * r, origin[1] + np.sin(heading)[..., None] * r
    )  # (n, S, B, k) metres, NaN-padded
    seen = np.zeros((spans.shape[0], bins))
    _count_seen(
        levels,
        np.cos(bearing),
        np.sin(bearing),
        r,
        object_height * np.asarray(OBJECT_SAMPLE_FRACTIONS),
        camera_height,
        math.cos(tilt),
        math.sin(tilt),
        projection_of(camera),
        np.ascontiguousarray(depth, dtype=np.float32),
        tolerance,
        seen,
    )
    profiles = seen / samples
    if tall is not None:
        profiles = block_behind(profiles, step, origin, heading.mean(axis=1), tall)
    return ColumnVisibility(profiles, step)


def projection_of(camera: CameraModel) -> np.ndarray:
    """The camera's projection for the kernel: fx, fy, cx, cy (pixels, from the frame's edges),
    k1, k2, p1, p2, k3 (OpenCV's distortion), and the largest |x| and |y| of an undistorted ray
    that lands in the frame (normalized units; beyond them a distorting polynomial may fold a
    point from outside the field back into the frame)."""
    lens = camera.lens
    if lens is None:
        f = camera.focal_px
        half_w, half_h = camera.width / 2.0, camera.height / 2.0
        return np.array([f, f, half_w, half_h, 0, 0, 0, 0, 0, half_w / f, half_h / f], float)
    u = np.concatenate([np.linspace(0, camera.width, 65), np.full(49, 0.0)])
    v = np.concatenate([np.full(65, 0.0), np.linspace(0, camera.height, 49)])
    corners_u = np.concatenate([u, camera.width - u])
    corners_v = np.concatenate([v, camera.height - v])
    x, y = camera.normalized(corners_u, corners_v)
    return np.array(
        [lens.fx, lens.fy, lens.cx + 0.5, lens.cy + 0.5, lens.k1, lens.k2, lens.p1, lens.p2,
         lens.k3, 1.01 * np.abs(x).max(), 1.01 * np.abs(y).max()],
        float,
    )  # fmt: skip


@njit(cache=True)
def project(x: float, y: float, projection: np.ndarray) -> tuple[float, float]:
    """Pixel position (from the frame's edges) of the undistorted normalized point (x right,
    y down) through ``projection_of``'s camera; (-1, -1), outside every frame, for a point beyond
    the field, which a distorting polynomial could otherwise fold back into it."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3, x_max, y_max = projection
    if abs(x) > x_max or abs(y) > y_max:
        return -1.0, -1.0
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    col = cx + fx * (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x))
    row = cy + fy * (y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)
    return col, row


@njit(cache=True)
def _count_seen(
    levels, cos_b, sin_b, r, lifts, camera_height, cos_t, sin_t, projection, depth, tolerance, seen
):
    """Adds to ``seen[c, b]``, for each of column c's sampled pixel columns, the share of an
    object at distance bin b that would be seen from it (the rule in the module docstring). A
    loop, not arrays: it stops at the first wholly seen level, where arrays would compute every
    level and height of every point (measured, 20 columns x 160 bins: 10-28 ms as arrays,
    1-1.6 ms as this loop; benchmarks/bench_visibility.py)."""
    n, n_samples, n_bins, n_levels = levels.shape
    height, width = depth.shape
    for c in range(n):
        for s in range(n_samples):
            for b in range(n_bins):
                ahead_level = r[b] * cos_b[c, s]
                left = r[b] * sin_b[c, s]
                best = 0
                for k in range(n_levels):
                    level = levels[c, s, b, k]
                    if not math.isfinite(level):
                        continue
                    visible = 0
                    for lift in lifts:
                        dz = level + lift - camera_height
                        ahead = ahead_level * cos_t + dz * sin_t
                        if ahead <= 0.0:
                            continue
                        # normalized, right and down positive
                        col, row = project(
                            -left / ahead, -(dz * cos_t - ahead_level * sin_t) / ahead, projection
                        )
                        if not (0.0 <= col < width and 0.0 <= row < height):
                            continue
                        surface = depth[int(row), int(col)]
                        # NaN: nothing within range, so nothing in the way
                        if (
                            math.isnan(surface)
                            or surface >= math.sqrt(r[b] * r[b] + dz * dz) - tolerance
                        ):
                            visible += 1
                    best = max(best, visible)
                    if best == len(lifts):
                        break
                seen[c, b] += best / len(lifts)
