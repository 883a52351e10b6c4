"""Correlative scan matching after Olson, "Real-Time Correlative Scan Matching" (ICRA 2009).

Where is the base, given a scan, a map, and a rough prior (odometry)? The map is rasterised once
into a lookup table of the log-likelihood of a laser return falling in each cell: the log of a
Gaussian of the distance to the nearest surface, blurred by the sensor's uncertainty ``sigma_m``
and floored at ``max_distance_m`` so one stray return cannot veto a pose (Olson's table). The
surface is the outline of the occupied cells (a return deep inside a solid cross-section fits no
better than one in free space): anywhere within an outline cell, or at the mean of the returns
that fell in it when the map's builder kept those (``LikelihoodTable``). A pose's score is the
sum of the table over the scan's returns placed at that pose (independent beams). The search is
exhaustive over a window around the prior: x and y in steps of the table's cells, yaw in
``yaw_step``.

Multi-resolution makes it fast, as in the paper: a coarse table holds, in each cell, the maximum
of the fine table over the block of D x D cells that starts there, so a pose's coarse score bounds
the fine score of every pose within D cells of translation from it. Coarse scores of all blocks
are computed first, and fine poses are scored block by block in descending order of the bound,
until the next bound is below the best fine score: the answer is the exhaustive search's.

The covariance comes from the score distribution, as in the paper: each voxel (pose) has
probability ∝ exp(score), and Σ = K/s − u uᵀ/s² with s = Σp, u = Σp x and K = Σp x xᵀ. Voxels
the bound proves to lie more than ``covariance_margin`` below the best (probability < e^-margin of
the peak's) are not scored; the search keeps going until the bound falls below that margin, so
every voxel that matters is in the sum. The voxels' own size adds step²/12 to each variance.
An optional Gaussian prior on the offset from the odometry pose (``prior_sigma``) is added to
every score (the paper's motion model term), bounded per block likewise.

Beyond the paper, the best voxel is refined below the lattice (``refine``): a pattern search
from it, within one voxel, on the same likelihood evaluated at the returns' exact positions
instead of their cells. Cells of 5 cm otherwise limit a match to a few centimetres, and a map
built from such matches drifts by that much per scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.nav.maps import OccupancyMap
from twin.nav.raycast import scan_points_in_base


def surface_cells(occupied: np.ndarray) -> np.ndarray:
    """The occupied cells with a side on a cell that is not occupied (or on the map's edge):
    where a beam can end. A return deep inside a solid cross-section is as unlikely as one in
    free space, so a thick obstacle scores a pose by its outline, not its area."""
    occupied = np.asarray(occupied, dtype=bool)
    inner = np.zeros_like(occupied)
    inner[1:-1, 1:-1] = (
        occupied[1:-1, 1:-1]
        & occupied[:-2, 1:-1]
        & occupied[2:, 1:-1]
        & occupied[1:-1, :-2]
        & occupied[1:-1, 2:]
    )
    return occupied & ~inner


class LikelihoodTable:
    """Olson's lookup table of a map: per cell, the log-likelihood of a return there.

    The surface is in the occupied cells on an obstacle's outline (``surface_cells``):
    somewhere in the cell, as far as the map knows (a point in such a cell is at distance 0),
    or exactly where the returns in it fell on average when the map's builder knows that
    (``surface_points``, (ny, nx, 2) metres, NaN where unknown), which keeps what the laser saw
    finer than the cells. ``fine[row, col]`` = -min(d, ``max_distance_m``)² / (2 ``sigma_m``²)
    with d the distance (m) from the cell's centre to the nearest surface; ``floor`` is its
    least value (also used off the map); ``coarse`` holds block maxima of ``coarse_cells`` x
    ``coarse_cells`` fine cells (see the module's docstring), offset by ``coarse_cells - 1``.
    ``surface`` (ny, nx) marks the outline cells, ``anchors`` (ny, nx, 2) their known points.
    """

    def __init__(
        self,
        occupancy_map: OccupancyMap,
        sigma_m: float = 0.05,
        max_distance_m: float | None = None,
        coarse_cells: int = 4,
        surface_points: np.ndarray | None = None,
    ) -> None:
        if not (math.isfinite(sigma_m) and sigma_m > 0):
            raise InputError(f"sigma_m must be a positive number of metres, got {sigma_m!r}")
        if max_distance_m is None:
            max_distance_m = 3.0 * sigma_m
        if not (math.isfinite(max_distance_m) and max_distance_m > 0):
            raise InputError(f"max_distance_m must be positive, got {max_distance_m!r}")
        if not (isinstance(coarse_cells, int) and coarse_cells >= 1):
            raise InputError(f"coarse_cells must be a whole number >= 1, got {coarse_cells!r}")
        self.resolution = res = occupancy_map.resolution
        self.origin = (float(occupancy_map.origin[0]), float(occupancy_map.origin[1]))
        self.sigma_m = float(sigma_m)
        self.coarse_cells = coarse_cells
        self.floor = -(max_distance_m**2) / (2.0 * sigma_m**2)
        self.surface = surface_cells(occupancy_map.occupied)
        anchors = np.full((*occupancy_map.shape, 2), np.nan)
        if surface_points is not None:
            points = np.asarray(surface_points, dtype=float)
            if points.shape != anchors.shape:
                raise InputError(
                    f"surface_points must be (ny, nx, 2) = {anchors.shape}, got {points.shape}"
                )
            known = self.surface & np.isfinite(points).all(axis=2)
            anchors[known] = points[known]
        self.anchors = anchors
        reach = math.ceil(max_distance_m / res) + 1
        self.fine = _surface_table(
            self.surface, anchors, *self.origin, res, 1.0 / (2.0 * sigma_m**2), self.floor, reach
        )
        self.coarse = _block_max(self.fine, coarse_cells)


@njit(cache=True, inline="always")
def _surface_distance2(px, py, row, col, surface, anchors, x0, y0, res):
    """Squared distance (m²) from (px, py) to the surface in cell (row, col): to its known
    point, else to the cell's square; infinite if the cell holds no surface."""
    if not surface[row, col]:
        return np.inf
    ax = anchors[row, col, 0]
    if np.isfinite(ax):
        dx, dy = px - ax, py - anchors[row, col, 1]
        return dx * dx + dy * dy
    dx = max(abs(px - (x0 + (col + 0.5) * res)) - 0.5 * res, 0.0)
    dy = max(abs(py - (y0 + (row + 0.5) * res)) - 0.5 * res, 0.0)
    return dx * dx + dy * dy


@njit(cache=True)
def _surface_table(surface, anchors, x0, y0, res, inv_two_var, floor, reach):
    """Per cell: -d² / (2 sigma²) at its centre for the nearest surface within ``reach`` cells,
    at least ``floor``."""
    ny, nx = surface.shape
    table = np.full((ny, nx), floor)
    for r in range(ny):
        for c in range(nx):
            if not surface[r, c]:
                continue
            for rr in range(max(r - reach, 0), min(r + reach + 1, ny)):
                cy = y0 + (rr + 0.5) * res
                for cc in range(max(c - reach, 0), min(c + reach + 1, nx)):
                    cx = x0 + (cc + 0.5) * res
                    d2 = _surface_distance2(cx, cy, r, c, surface, anchors, x0, y0, res)
                    table[rr, cc] = max(table[rr, cc], -d2 * inv_two_var)
    return table


@njit(cache=True)
def _block_max(fine, d):
    """out[a, b] = max fine[a-d+1 .. a, b-d+1 .. b] clipped to the grid: the maximum over the
    d x d block starting at fine cell (a - d + 1, b - d + 1)."""
    ny, nx = fine.shape
    rows = np.empty((ny, nx + d - 1))
    for r in range(ny):
        for b in range(nx + d - 1):
            best = -np.inf
            for c in range(max(b - d + 1, 0), min(b, nx - 1) + 1):
                best = max(best, fine[r, c])
            rows[r, b] = best
    out = np.empty((ny + d - 1, nx + d - 1))
    for a in range(ny + d - 1):
        for b in range(nx + d - 1):
            best = -np.inf
            for r in range(max(a - d + 1, 0), min(a, ny - 1) + 1):
                best = max(best, rows[r, b])
            out[a, b] = best
    return out


@dataclass(frozen=True)
class MatchResult:
    """A scan match: the base ``pose`` with the best score, its ``covariance`` (3x3 over x, y
    in metres and yaw in radians, map frame), the best ``score`` (sum of the returns'
    log-likelihoods), the ``points`` matched, and how many poses were scored (``evaluated``)
    out of the window's ``candidates``."""

    pose: Pose2D
    covariance: np.ndarray
    score: float
    points: int
    evaluated: int
    candidates: int

    @property
    def mean_log_likelihood(self) -> float:
        """The best score per return: 0 when every return lies on an occupied cell."""
        return self.score / max(self.points, 1)


class CorrelativeScanMatcher:
    """Olson's correlative matcher: an exhaustive, multi-resolution search of a pose window.

    ``window_m`` (m) and ``window_yaw`` (rad) are the half-widths of the window around the
    prior; x and y are searched in steps of the table's resolution, yaw in ``yaw_step`` (rad).
    ``mount`` places the scanner on the base, so poses in and out are the base's.
    ``prior_sigma`` = (metres, radians) adds a Gaussian prior on the offset from the prior pose;
    ``covariance_margin`` (log-likelihood units) bounds the voxels left out of the covariance.
    """

    def __init__(
        self,
        window_m: float = 0.3,
        window_yaw: float = math.radians(15.0),
        yaw_step: float = math.radians(1.0),
        *,
        mount: LaserMount | None = None,
        prior_sigma: tuple[float, float] | None = None,
        covariance_margin: float = 9.0,
        refine: bool = True,
    ) -> None:
        for name, value in (("window_m", window_m), ("window_yaw", window_yaw)):
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (math.isfinite(yaw_step) and yaw_step > 0):
            raise InputError(f"yaw_step must be a positive number of radians, got {yaw_step!r}")
        if prior_sigma is not None and not all(math.isfinite(s) and s > 0 for s in prior_sigma):
            raise InputError(f"prior_sigma must be two positive numbers, got {prior_sigma!r}")
        if not (math.isfinite(covariance_margin) and covariance_margin >= 0):
            raise InputError(f"covariance_margin must be >= 0, got {covariance_margin!r}")
        self.window_m = float(window_m)
        self.window_yaw = float(window_yaw)
        self.yaw_step = float(yaw_step)
        self.mount = mount or LaserMount()
        self.prior_sigma = prior_sigma
        self.covariance_margin = float(covariance_margin)
        self.refine = bool(refine)

    def match(self, table: LikelihoodTable, scan: Scan, prior: Pose2D) -> MatchResult:
        """The best base pose for ``scan`` in ``table``'s map within the window around
        ``prior``; a scan without returns cannot be matched (``InputError``)."""
        points = scan_points_in_base(scan, self.mount)
        if points.shape[0] == 0:
            raise InputError("the scan has no returns to match; check the laser")
        res = table.resolution
        half_cells = round(self.window_m / res)
        half_yaws = round(self.window_yaw / self.yaw_step)
        yaw_offsets = np.arange(-half_yaws, half_yaws + 1) * self.yaw_step
        cells = _point_cells(
            points, prior.x, prior.y, prior.yaw, yaw_offsets, table.origin[0], table.origin[1], res
        )
        if self.prior_sigma is None:
            w_xy = w_yaw = 0.0
        else:
            w_xy = 1.0 / self.prior_sigma[0] ** 2
            w_yaw = 1.0 / self.prior_sigma[1] ** 2
        records = _search(
            table.fine,
            table.coarse,
            table.floor,
            table.coarse_cells,
            cells,
            half_cells,
            yaw_offsets,
            res,
            w_xy,
            w_yaw,
            self.covariance_margin,
        )
        scores = records[:, 3]
        best = int(np.argmax(scores))
        k, i, j = (int(v) for v in records[best, :3])
        offsets = np.stack(
            [records[:, 1] * res, records[:, 2] * res, yaw_offsets[records[:, 0].astype(int)]],
            axis=1,
        )
        weight = np.exp(scores - scores[best])
        total = weight.sum()
        mean = weight @ offsets / total
        covariance = (offsets * weight[:, None]).T @ offsets / total - np.outer(mean, mean)
        covariance += np.diag([res**2 / 12.0, res**2 / 12.0, self.yaw_step**2 / 12.0])
        x, y, yaw = prior.x + i * res, prior.y + j * res, prior.yaw + float(yaw_offsets[k])
        if self.refine:
            x, y, yaw = _refine(
                table.surface,
                table.anchors,
                points,
                np.array([x, y, yaw]),
                np.array([prior.x, prior.y, prior.yaw]),
                table.origin[0],
                table.origin[1],
                res,
                self.yaw_step,
                1.0 / (2.0 * table.sigma_m**2),
                w_xy,
                w_yaw,
            )
        pose = Pose2D(x, y, math.atan2(math.sin(yaw), math.cos(yaw)))
        side = 2 * half_cells + 1
        return MatchResult(
            pose=pose,
            covariance=0.5 * (covariance + covariance.T),
            score=float(scores[best]),
            points=int(points.shape[0]),
            evaluated=int(records.shape[0]),
            candidates=side * side * yaw_offsets.shape[0],
        )


@njit(cache=True)
def _point_cells(points, px, py, pyaw, yaw_offsets, x0, y0, res):
    """(n_yaw, n_points, 2) cells (col, row) of the points placed at the prior's x, y and each
    yaw of the window."""
    n_yaw, n = yaw_offsets.shape[0], points.shape[0]
    out = np.empty((n_yaw, n, 2), dtype=np.int64)
    for k in range(n_yaw):
        c, s = math.cos(pyaw + yaw_offsets[k]), math.sin(pyaw + yaw_offsets[k])
        for p in range(n):
            x = px + c * points[p, 0] - s * points[p, 1]
            y = py + s * points[p, 0] + c * points[p, 1]
            out[k, p, 0] = math.floor((x - x0) / res)
            out[k, p, 1] = math.floor((y - y0) / res)
    return out


@njit(cache=True, inline="always")
def _table_sum(table, floor, cells_k, di, dj, shift):
    ny, nx = table.shape
    total = 0.0
    for p in range(cells_k.shape[0]):
        col = cells_k[p, 0] + di + shift
        row = cells_k[p, 1] + dj + shift
        if 0 <= row < ny and 0 <= col < nx:
            total += table[row, col]
        else:
            total += floor
    return total


@njit(cache=True, inline="always")
def _min_square(lo, hi):
    """The least i² for integer i in [lo, hi]."""
    if lo <= 0 <= hi:
        return 0.0
    return float(min(lo * lo, hi * hi))


@njit(cache=True)
def _search(fine, coarse, floor, d, cells, half, yaw_offsets, res, w_xy, w_yaw, margin):
    """Branch and bound over (yaw, x, y) voxels; returns (k, i, j, score) of every fine voxel
    scored: all voxels within ``margin`` of the best, and the best itself."""
    n_yaw = yaw_offsets.shape[0]
    blocks = (2 * half + d) // d
    bounds = np.empty(n_yaw * blocks * blocks)
    for k in range(n_yaw):
        prior_yaw = -0.5 * w_yaw * yaw_offsets[k] * yaw_offsets[k]
        for bi in range(blocks):
            i0 = -half + bi * d
            i1 = min(i0 + d - 1, half)
            for bj in range(blocks):
                j0 = -half + bj * d
                j1 = min(j0 + d - 1, half)
                prior = prior_yaw - 0.5 * w_xy * res * res * (
                    _min_square(i0, i1) + _min_square(j0, j1)
                )
                # coarse[a, b] is the block max starting at fine (a - d + 1, b - d + 1)
                bounds[(k * blocks + bi) * blocks + bj] = prior + _table_sum(
                    coarse, floor, cells[k], i0, j0, d - 1
                )
    order = np.argsort(-bounds)
    side = 2 * half + 1
    records = np.empty((n_yaw * side * side, 4))
    count = 0
    best = -np.inf
    for idx in order:
        if bounds[idx] < best - margin:
            break
        k = idx // (blocks * blocks)
        bi = (idx // blocks) % blocks
        bj = idx % blocks
        prior_yaw = -0.5 * w_yaw * yaw_offsets[k] * yaw_offsets[k]
        i0 = -half + bi * d
        j0 = -half + bj * d
        for i in range(i0, min(i0 + d - 1, half) + 1):
            for j in range(j0, min(j0 + d - 1, half) + 1):
                score = _table_sum(fine, floor, cells[k], i, j, 0)
                score += prior_yaw - 0.5 * w_xy * res * res * (i * i + j * j)
                records[count, 0] = k
                records[count, 1] = i
                records[count, 2] = j
                records[count, 3] = score
                count += 1
                best = max(best, score)
    return records[:count]


@njit(cache=True)
def _surface_score(surface, anchors, points, x, y, yaw, x0, y0, res, inv_two_var, reach):
    """The score of a continuous pose: each return scores -d² / (2 sigma²) for the distance d
    to the nearest surface within ``reach`` cells of it (at least that of ``reach`` cells), so
    the refinement sees where within their cells the surfaces are."""
    ny, nx = surface.shape
    c, s = math.cos(yaw), math.sin(yaw)
    limit = (reach * res) ** 2
    total = 0.0
    for p in range(points.shape[0]):
        px = x + c * points[p, 0] - s * points[p, 1]
        py = y + s * points[p, 0] + c * points[p, 1]
        col, row = math.floor((px - x0) / res), math.floor((py - y0) / res)
        best = limit
        for rr in range(max(row - reach, 0), min(row + reach + 1, ny)):
            for cc in range(max(col - reach, 0), min(col + reach + 1, nx)):
                d2 = _surface_distance2(px, py, rr, cc, surface, anchors, x0, y0, res)
                best = min(best, d2)
        total -= best * inv_two_var
    return total


@njit(cache=True)
def _refine(
    surface, anchors, points, start, prior, x0, y0, res, yaw_step, inv_two_var, w_xy, w_yaw
):
    """Sub-voxel pose: a pattern search on ``_surface_score`` from the best voxel, moving by half
    a voxel, then a quarter, ... down to 1/64, and never beyond one voxel from it."""
    pose = start.copy()
    steps = np.array([res, res, yaw_step])

    def objective(q):
        d = q - prior
        penalty = 0.5 * (w_xy * (d[0] * d[0] + d[1] * d[1]) + w_yaw * d[2] * d[2])
        score = _surface_score(
            surface, anchors, points, q[0], q[1], q[2], x0, y0, res, inv_two_var, 2
        )
        return score - penalty

    best = objective(pose)
    scale = 0.5
    while scale >= 1.0 / 64.0:
        improved = True
        while improved:
            improved = False
            for axis in range(3):
                for sign in (-1.0, 1.0):
                    trial = pose.copy()
                    trial[axis] += sign * scale * steps[axis]
                    if abs(trial[axis] - start[axis]) > steps[axis]:
                        continue
                    value = objective(trial)
                    if value > best:
                        best, pose, improved = value, trial, True
        scale *= 0.5
    return pose[0], pose[1], pose[2]
