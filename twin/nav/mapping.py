"""Building occupancy maps from laser scans: log-odds grid mapping, and a scan-matching builder.

``OccupancyGridMapper`` integrates scans taken at known poses into a log-odds grid with the
classic inverse sensor model (Thrun, Burgard and Fox, *Probabilistic Robotics*, ch. 9): along
each beam the cells up to the return gain the log-odds of "free", the cell of the return that of
"occupied"; a beam with no return clears cells up to ``no_return_free_m`` only, since a missing
echo (a dark or glancing surface) is weaker evidence than a long free beam. Within one scan every
cell is updated at most once and a cell some beam hit is not cleared by another beam grazing it,
so thin walls seen at shallow angles survive. Evidence is clamped so the map can still change.

``MapBuilder`` makes a map from a drive: each scan is matched against the map built so far
(``twin.nav.scan_matching``) around the pose odometry predicts, then integrated at the corrected
pose. ``map_agreement`` scores a built map against a reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numba import njit

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.nav.distance import distance_transform
from twin.nav.maps import UNKNOWN, OccupancyMap
from twin.nav.raycast import clip_to_grid, first_boundary, laser_pose
from twin.nav.scan_matching import CorrelativeScanMatcher, LikelihoodTable, MatchResult


def _log_odds(p: float) -> float:
    return math.log(p / (1.0 - p))


class OccupancyGridMapper:
    """A log-odds occupancy grid over a fixed extent, fed scans at known base poses.

    ``extent`` (x_min, y_min, x_max, y_max) metres and ``resolution`` metres per cell fix the
    grid (the origin is (x_min, y_min)); ``p_hit`` / ``p_miss`` are the inverse sensor model's
    occupancy for a cell with a return / one a beam crossed, ``p_min`` / ``p_max`` the clamps;
    ``no_return_free_m`` how far (m) a beam without a return clears. Points beyond the extent
    are dropped (their beams still clear the cells inside it).
    """

    def __init__(
        self,
        extent: tuple[float, float, float, float],
        resolution: float = 0.05,
        *,
        mount: LaserMount | None = None,
        p_hit: float = 0.7,
        p_miss: float = 0.4,
        p_min: float = 0.12,
        p_max: float = 0.97,
        no_return_free_m: float = 3.0,
    ) -> None:
        x_min, y_min, x_max, y_max = (float(v) for v in extent)
        if not (math.isfinite(resolution) and resolution > 0):
            raise InputError(f"map resolution must be positive, got {resolution!r} m")
        if not (x_max > x_min and y_max > y_min) or not all(
            math.isfinite(v) for v in (x_min, y_min, x_max, y_max)
        ):
            raise InputError(f"map extent must be (x_min, y_min, x_max, y_max), got {extent!r}")
        if not 0.0 < p_min < p_miss < 0.5 < p_hit < p_max < 1.0:
            raise InputError(
                "the sensor model needs 0 < p_min < p_miss < 0.5 < p_hit < p_max < 1, got "
                f"{p_min}, {p_miss}, {p_hit}, {p_max}"
            )
        if not no_return_free_m >= 0:
            raise InputError(f"no_return_free_m must be >= 0 m, got {no_return_free_m!r}")
        nx = math.ceil((x_max - x_min) / resolution - 1e-9)
        ny = math.ceil((y_max - y_min) / resolution - 1e-9)
        self.resolution = float(resolution)
        self.origin = (x_min, y_min)
        self.mount = mount or LaserMount()
        self.log_odds = np.zeros((ny, nx))
        self._hit_sum = np.zeros((ny, nx, 2))
        self._hit_count = np.zeros((ny, nx), dtype=np.int64)
        self.observed = np.zeros((ny, nx), dtype=bool)
        self._hit_stamp = np.full((ny, nx), -1, dtype=np.int64)
        self._free_stamp = np.full((ny, nx), -1, dtype=np.int64)
        self._scans = 0
        self._l_hit, self._l_miss = _log_odds(p_hit), _log_odds(p_miss)
        self._l_min, self._l_max = _log_odds(p_min), _log_odds(p_max)
        self.no_return_free_m = float(no_return_free_m)

    @property
    def shape(self) -> tuple[int, int]:
        return self.log_odds.shape  # type: ignore[return-value]

    @property
    def scans(self) -> int:
        """How many scans have been integrated."""
        return self._scans

    def integrate(self, pose: Pose2D, scan: Scan) -> None:
        """Add one scan taken with the base at ``pose`` (map frame)."""
        sensor = laser_pose(pose, self.mount)
        ranges = np.asarray(scan.ranges, dtype=float)
        angles = np.asarray(scan.angles, dtype=float)
        if ranges.shape != angles.shape or ranges.ndim != 1:
            raise InputError(
                f"a scan needs one range per angle, got {ranges.shape} / {angles.shape}"
            )
        hit = np.isfinite(ranges) & (ranges >= 0.0) & (ranges < scan.max_range)
        free_reach = min(self.no_return_free_m, scan.max_range)
        lengths = np.where(hit, ranges, free_reach)
        _integrate_scan(
            self.log_odds,
            self.observed,
            self._hit_sum,
            self._hit_count,
            self._hit_stamp,
            self._free_stamp,
            self._scans,
            self.origin[0],
            self.origin[1],
            self.resolution,
            sensor.x,
            sensor.y,
            angles + sensor.yaw,
            lengths,
            hit,
            self._l_hit,
            self._l_miss,
            self._l_min,
            self._l_max,
        )
        self._scans += 1

    def surface_points(self) -> np.ndarray:
        """(ny, nx, 2): where in each cell the returns fell on average (metres, map frame),
        NaN in cells without one: the surface within the cell, for the scan matcher."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self._hit_sum / self._hit_count[..., None]

    def to_map(self, occupied_thresh: float = 0.65, free_thresh: float = 0.196) -> OccupancyMap:
        """The grid as an ``OccupancyMap``: each observed cell's probability, never-observed
        cells ``UNKNOWN``."""
        probability = 1.0 / (1.0 + np.exp(-self.log_odds))
        grid = np.where(self.observed, probability, UNKNOWN)
        return OccupancyMap(
            grid, self.resolution, (*self.origin, 0.0), occupied_thresh, free_thresh
        )


@njit(cache=True)
def _integrate_scan(
    log_odds,
    observed,
    hit_sum,
    hit_count,
    hit_stamp,
    free_stamp,
    stamp,
    x0,
    y0,
    res,
    sx,
    sy,
    bearings,
    lengths,
    hit,
    l_hit,
    l_miss,
    l_min,
    l_max,
):
    ny, nx = log_odds.shape
    gx, gy = (sx - x0) / res, (sy - y0) / res
    # Pass 1: the cells of the returns. The end point is pushed a micrometre along the beam so
    # that a return exactly on a cell boundary (a wall face on the grid) counts in the far cell.
    for k in range(bearings.shape[0]):
        if not hit[k]:
            continue
        reach = (lengths[k] + 1e-6) / res
        ix = math.floor(gx + reach * math.cos(bearings[k]))
        iy = math.floor(gy + reach * math.sin(bearings[k]))
        if not (0 <= ix < nx and 0 <= iy < ny):
            continue
        hit_sum[iy, ix, 0] += sx + lengths[k] * math.cos(bearings[k])
        hit_sum[iy, ix, 1] += sy + lengths[k] * math.sin(bearings[k])
        hit_count[iy, ix] += 1
        if hit_stamp[iy, ix] != stamp:
            hit_stamp[iy, ix] = stamp
            log_odds[iy, ix] = min(log_odds[iy, ix] + l_hit, l_max)
            observed[iy, ix] = True
    # Pass 2: the cells each beam crossed before its end, once per scan, unless hit in it.
    for k in range(bearings.shape[0]):
        dx, dy = math.cos(bearings[k]), math.sin(bearings[k])
        t_end = (lengths[k] + 1e-6) / res
        t0, t1 = clip_to_grid(gx, gy, dx, dy, nx, ny, t_end)
        if t0 > t1:
            continue
        ix = min(max(math.floor(gx + t0 * dx), 0), nx - 1)
        iy = min(max(math.floor(gy + t0 * dy), 0), ny - 1)
        tx, step_tx, step_x = first_boundary(gx + t0 * dx, dx, ix)
        ty, step_ty, step_y = first_boundary(gy + t0 * dy, dy, iy)
        tx += t0
        ty += t0
        while True:
            leaving = min(tx, ty)
            last = leaving >= t_end  # the beam ends in this cell
            if last and hit[k]:
                break
            if hit_stamp[iy, ix] != stamp and free_stamp[iy, ix] != stamp:
                free_stamp[iy, ix] = stamp
                log_odds[iy, ix] = max(log_odds[iy, ix] + l_miss, l_min)
                observed[iy, ix] = True
            if last or leaving > t1:
                break
            if tx < ty:
                ix += step_x
                tx += step_tx
            else:
                iy += step_y
                ty += step_ty
            if ix < 0 or ix >= nx or iy < 0 or iy >= ny:
                break


class MapBuilder:
    """Builds a map from a drive: (odometry pose, scan) pairs in, corrected poses and a map out.

    The first scan is integrated at its odometry pose, which fixes the map frame. For each later
    one, the odometry increment since the previous scan is applied to the previous *corrected*
    pose; the scan is matched against the map built so far in a window around that prediction
    (``matcher``, by default a ``CorrelativeScanMatcher`` for the laser on ``mount``); the scan
    is then integrated at the matched pose. A scan with fewer than ``min_points`` returns is
    integrated at the prediction unmatched. ``extent`` (metres) bounds the map, as
    ``OccupancyGridMapper``'s; ``sigma_m`` blurs the matcher's table of the map built so far.
    """

    def __init__(
        self,
        extent: tuple[float, float, float, float],
        resolution: float = 0.05,
        *,
        mount: LaserMount | None = None,
        matcher: CorrelativeScanMatcher | None = None,
        sigma_m: float = 0.05,
        coarse_cells: int = 4,
        min_points: int = 20,
        no_return_free_m: float = 3.0,
    ) -> None:
        if matcher is None:
            matcher = CorrelativeScanMatcher(mount=mount)
        elif mount is not None and mount != matcher.mount:
            raise InputError(
                f"the laser mount {mount} differs from the matcher's {matcher.mount}; give one"
            )
        self.matcher = matcher
        self.mapper = OccupancyGridMapper(
            extent, resolution, mount=self.matcher.mount, no_return_free_m=no_return_free_m
        )
        self.sigma_m = float(sigma_m)
        self.coarse_cells = coarse_cells
        self.min_points = int(min_points)
        self._trajectory: list[Pose2D] = []
        self._odometry: list[Pose2D] = []
        self._matches: list[MatchResult | None] = []

    @property
    def trajectory(self) -> list[Pose2D]:
        """The corrected base poses, one per scan added (map frame)."""
        return list(self._trajectory)

    @property
    def odometry(self) -> list[Pose2D]:
        """The odometry poses as they were given, one per scan."""
        return list(self._odometry)

    @property
    def matches(self) -> list[MatchResult | None]:
        """Each scan's match (None for the first scan and for scans too sparse to match)."""
        return list(self._matches)

    def predict(self, odometry: Pose2D) -> Pose2D:
        """Where odometry says the base is now: its increment since the last scan applied to
        the last corrected pose (the odometry pose itself before the first scan)."""
        if not self._trajectory:
            return odometry
        return self._trajectory[-1].compose(self._odometry[-1].relative(odometry))

    def add(self, odometry: Pose2D, scan: Scan) -> Pose2D:
        """Match and integrate one scan taken at odometry pose ``odometry``; returns the
        corrected pose."""
        predicted = self.predict(odometry)
        match: MatchResult | None = None
        if self._trajectory and int(np.isfinite(scan.ranges).sum()) >= self.min_points:
            table = LikelihoodTable(
                self.mapper.to_map(),
                sigma_m=self.sigma_m,
                coarse_cells=self.coarse_cells,
                surface_points=self.mapper.surface_points(),
            )
            match = self.matcher.match(table, scan, predicted)
        corrected = predicted if match is None else match.pose
        self.mapper.integrate(corrected, scan)
        self._trajectory.append(corrected)
        self._odometry.append(odometry)
        self._matches.append(match)
        return corrected

    def to_map(self) -> OccupancyMap:
        """The map built so far."""
        return self.mapper.to_map()


@dataclass(frozen=True)
class MapAgreement:
    """How well a built map's obstacles agree with a reference's, within a tolerance.

    ``precision``: the share of the built map's occupied cells within the tolerance of a
    reference occupied cell; ``recall``: the share of the reference's occupied cells that the
    built map observed (a known cell there) lying within the tolerance of a built occupied cell;
    ``f1`` their harmonic mean; the counts are the denominators."""

    precision: float
    recall: float
    f1: float
    built_occupied: int
    reference_observed: int


def map_agreement(
    built: OccupancyMap, reference: OccupancyMap, tolerance_m: float = 0.05
) -> MapAgreement:
    """Occupied-cell agreement of ``built`` with ``reference`` (maps of any grids): distances are
    between cell centres, read on the grid of the map the distance is measured to, so a cell
    offset by one cell of 5 cm is 0.05 m away; cells outside the other map are unmatched."""
    if not (math.isfinite(tolerance_m) and tolerance_m >= 0):
        raise InputError(f"tolerance_m must be a finite number of metres >= 0, got {tolerance_m!r}")
    built_rows, built_cols = np.nonzero(built.occupied)
    bx, by = built.center_of(built_rows, built_cols)
    near_reference = _distance_at(reference, bx, by) <= tolerance_m + 1e-9
    ref_rows, ref_cols = np.nonzero(reference.occupied)
    rx, ry = reference.center_of(ref_rows, ref_cols)
    row, col = built.cell_of(rx, ry)
    ny, nx = built.shape
    inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
    observed = np.zeros(rx.shape, dtype=bool)
    observed[inside] = built.occupancy[row[inside], col[inside]] != UNKNOWN
    near_built = _distance_at(built, rx[observed], ry[observed]) <= tolerance_m + 1e-9
    precision = float(near_reference.mean()) if near_reference.size else 0.0
    recall = float(near_built.mean()) if near_built.size else 0.0
    f1 = 2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return MapAgreement(precision, recall, f1, int(near_reference.size), int(near_built.size))


def _distance_at(occupancy_map: OccupancyMap, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance (m) from the cells holding points (x, y) to the nearest occupied cell of the
    map, centre to centre; infinite off the map."""
    field = distance_transform(occupancy_map.occupied, occupancy_map.resolution)
    row, col = occupancy_map.cell_of(x, y)
    ny, nx = occupancy_map.shape
    inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
    out = np.full(np.shape(x), np.inf)
    out[inside] = field[row[inside], col[inside]]
    return out


def wheel_odometry(
    truth: list[Pose2D],
    wheel_base: float = 0.34,
    left_scale: float = 1.0,
    right_scale: float = 1.01,
) -> list[Pose2D]:
    """The odometry a differential drive with miscalibrated wheels reports along a true path.

    Each step's true motion is split into the wheels' travel (``wheel_base`` metres apart, the
    Peoplebot's 0.34 m), each wheel's travel is scaled (a wheel 1 % larger than its encoder
    believes travels 1 % further: ``right_scale=1.01``) and the steps are integrated again at
    their mid-heading, starting from the first true pose: what a map builder is fed to test
    how it corrects drift.
    """
    if not truth:
        return []
    if not (math.isfinite(wheel_base) and wheel_base > 0):
        raise InputError(f"wheel_base must be a positive number of metres, got {wheel_base!r}")
    odometry = [truth[0]]
    for before, after in pairwise(truth):
        step = before.relative(after)
        left = (step.x - 0.5 * wheel_base * step.yaw) * left_scale
        right = (step.x + 0.5 * wheel_base * step.yaw) * right_scale
        travel, turn = 0.5 * (left + right), (right - left) / wheel_base
        odometry.append(
            odometry[-1].compose(
                Pose2D(travel * math.cos(0.5 * turn), travel * math.sin(0.5 * turn), turn)
            )
        )
    return odometry
