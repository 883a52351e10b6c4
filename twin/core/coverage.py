"""Supersampled wedge coverage: how much of each grid cell a bearing wedge covers.

The paper (Section 1.3) rasterizes each sensor wedge at 10x the grid's resolution so that a cell
gains in proportion to how well the wedge covers it. Here every cell holds s x s sample points
at the centres of its sub-cells; a cell's coverage by a wedge is the fraction of its points whose
bearing from the origin lies in the wedge's half-open interval [a0, a1) (and, optionally, whose
distance is at most ``max_range``). Adjacent wedges that share an edge therefore never count a
point twice, and a full circle covers every point once.

Rather than testing all (n s)^2 points per wedge, each row of sample points is cut by the
wedge's two rays: on a row above the origin the bearing falls monotonically with x, below it
rises, so the points inside a wedge form one run per row and piece of the wedge, found from the
rays' cotangents. Runs are added to cells in whole blocks of s points. A view of 32 columns on a
50 x 50 grid at s = 10 thus costs ~500 rows x 32 runs instead of 250 000 x 32 point tests.

The kernels are compiled by numba (``cache=True``: compiled once per machine, then loaded).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi
# Stand-in for the cotangent of 0 (and of pi from above): dy * _HUGE overflows nothing for any
# |dy| the grid can see, and is clipped to the grid right after.
_HUGE = 1e300
# What the kernel needs to weigh a cell by its visibility to a wedge: profiles (p, n_wedges,
# n_bins) over distance from the origin in bins of ``step`` metres, shared by every weight row
# (p = 1) or one per row (p = k); no bins: every cell fully visible. Also the origin, and the
# grid's corner and cell size.
_Seeing = namedtuple("_Seeing", "profiles step ox oy x0 y0 cell")
NO_VISIBILITY = np.zeros((1, 0, 0))


@njit(cache=True, inline="always")
def _cot(angle: float) -> float:
    return math.cos(angle) / math.sin(angle)


@njit(cache=True)
def wedge_pieces(a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """Split each wedge [a0, a1) into its parts in the upper and lower half-planes.

    Returns an (n, 4, 2) array of cotangents: rows 0-1 are up to two pieces with bearings in
    (0, pi) (for sample rows above the origin), rows 2-3 up to two pieces in (pi, 2 pi) (rows
    below). Each piece is stored as (cot of its start, cot of its end); an empty piece is
    (nan, nan). Wedges must satisfy 0 <= a1 - a0 <= 2 pi.
    """
    n = a0.shape[0]
    out = np.full((n, 4, 2), np.nan)
    for w in range(n):
        start = a0[w] % TWO_PI
        end = start + (a1[w] - a0[w])
        slot = 0
        # Upper half-plane bearings are (0, pi) and, for wedges reaching past 2 pi, (2pi, 3pi).
        for shift in (0.0, TWO_PI):
            lo = max(start - shift, 0.0)
            hi = min(end - shift, math.pi)
            if hi > lo:
                out[w, slot, 0] = _HUGE if lo <= 0.0 else _cot(lo)
                out[w, slot, 1] = -_HUGE if hi >= math.pi else _cot(hi)
                slot += 1
        slot = 2
        for shift in (0.0, TWO_PI):
            lo = max(start - shift, math.pi)
            hi = min(end - shift, TWO_PI)
            if hi > lo:
                out[w, slot, 0] = _HUGE if lo <= math.pi else _cot(lo)
                out[w, slot, 1] = -_HUGE if hi >= TWO_PI else _cot(hi)
                slot += 1
    return out


@njit(cache=True, inline="always")
def _contains_angle(a0: float, a1: float, angle: float) -> bool:
    """Whether ``angle`` (in [0, 2 pi)) lies in the half-open wedge [a0, a1)."""
    offset = (angle - a0) % TWO_PI
    return offset < (a1 - a0)


@njit(cache=True, inline="always")
def _first_index_at_or_after(x: float, x0: float, step: float, count: int) -> int:
    """Smallest sample index i with x0 + (i + 0.5) step >= x, clipped to [0, count]."""
    t = (x - x0) / step - 0.5
    if t <= 0.0:
        return 0
    if t >= count:
        return count
    return math.ceil(t)


@njit(cache=True, inline="always")
def _first_index_after(x: float, x0: float, step: float, count: int) -> int:
    """Smallest sample index i with x0 + (i + 0.5) step > x, clipped to [0, count]."""
    t = (x - x0) / step - 0.5
    if t < 0.0:
        return 0
    if t >= count:
        return count
    return math.floor(t) + 1


@njit(cache=True, inline="always")
def _add_run(out, row: int, i_lo: int, i_hi: int, s: int, weights, w: int, scale: float):
    """Add weights[:, w] * (points in [i_lo, i_hi) of each cell) * scale to ``out[:, row]``."""
    if i_hi <= i_lo:
        return
    k = weights.shape[0]
    c_lo = i_lo // s
    c_hi = (i_hi - 1) // s
    if c_lo == c_hi:
        count = (i_hi - i_lo) * scale
        for q in range(k):
            out[q, row, c_lo] += weights[q, w] * count
        return
    head = (s * (c_lo + 1) - i_lo) * scale
    tail = (i_hi - s * c_hi) * scale
    full = s * scale
    for q in range(k):
        value = weights[q, w]
        if value == 0.0:
            continue
        out[q, row, c_lo] += value * head
        for c in range(c_lo + 1, c_hi):
            out[q, row, c] += value * full
        out[q, row, c_hi] += value * tail


@njit(cache=True)
def _add_seen_run(out, row: int, i_lo: int, i_hi: int, s: int, weights, w: int, scale, see):
    """``_add_run`` with each cell's share scaled by its profile value for wedge ``w`` (one
    profile for every weight row, or one per row)."""
    if i_hi <= i_lo:
        return
    k = weights.shape[0]
    per_row = see.profiles.shape[0] > 1
    for c in range(i_lo // s, (i_hi - 1) // s + 1):
        b = _distance_bin(see, row, c)
        if b >= see.profiles.shape[2]:
            continue  # beyond the profiles: not seen
        count = (min(i_hi, s * (c + 1)) - max(i_lo, s * c)) * scale
        if per_row:
            for q in range(k):
                out[q, row, c] += weights[q, w] * count * see.profiles[q, w, b]
        else:
            count *= see.profiles[0, w, b]
            if count == 0.0:
                continue
            for q in range(k):
                out[q, row, c] += weights[q, w] * count


@njit(cache=True, inline="always")
def _run(out, row, i_lo, i_hi, s, weights, w, scale, see, seeing: bool) -> None:
    if seeing:
        _add_seen_run(out, row, i_lo, i_hi, s, weights, w, scale, see)
    else:
        _add_run(out, row, i_lo, i_hi, s, weights, w, scale)


@njit(cache=True, inline="always")
def _distance_bin(see, row: int, col: int) -> int:
    """The profile bin of cell (row, col): its centre's distance from the origin over the
    profiles' step."""
    dx = see.x0 + (col + 0.5) * see.cell - see.ox
    dy = see.y0 + (row + 0.5) * see.cell - see.oy
    return int(math.sqrt(dx * dx + dy * dy) / see.step)


@njit(cache=True)
def add_coverage(
    out: np.ndarray,
    ox: float,
    oy: float,
    a0: np.ndarray,
    a1: np.ndarray,
    weights: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    supersample: int,
    max_range: float,
    visibility: np.ndarray = NO_VISIBILITY,
    visibility_step: float = 1.0,
) -> None:
    """Add, for every wedge w and weight row q, ``weights[q, w] * coverage_w`` to ``out[q]``.

    ``out`` is (k, ny, nx), row 0 at y0; the grid's lower-left corner is (x0, y0) and its cells
    are ``cell`` metres. Coverage is the fraction (0..1) of a cell's supersample points in the
    wedge. ``max_range <= 0`` means unlimited range. Wedges are given by a0 < a1 in radians.

    ``visibility`` (p, n_wedges, n_bins), when it has bins, scales each cell's coverage by the
    wedge's profile at the distance of the cell's centre from the origin, in bins of
    ``visibility_step`` metres (0 beyond the last bin): with p = 1 one profile for every weight
    row (how visible the cell was: a cell the camera could not have seen an object in gains
    nothing, and loses nothing), with p = k one per row (a rule whose weight varies with
    distance, e.g. a detector that weakens with range).
    """
    see = _Seeing(visibility, visibility_step, ox, oy, x0, y0, cell)
    seeing = visibility.shape[2] > 0
    ny = out.shape[1]
    nx = out.shape[2]
    s = supersample
    step = cell / s
    n_cols = nx * s
    scale = 1.0 / (s * s)
    pieces = wedge_pieces(a0, a1)
    n_wedges = a0.shape[0]
    limited = max_range > 0.0
    for j in range(ny * s):
        dy = y0 + (j + 0.5) * step - oy
        row = j // s
        r_lo = 0
        r_hi = n_cols
        if limited:
            if abs(dy) > max_range:
                continue
            half = math.sqrt(max_range * max_range - dy * dy)
            r_lo = _first_index_at_or_after(ox - half, x0, step, n_cols)
            r_hi = _first_index_after(ox + half, x0, step, n_cols)
        if dy == 0.0:
            # The row through the origin: bearing 0 to the right, pi to the left.
            i_origin_lo = _first_index_at_or_after(ox, x0, step, n_cols)
            i_origin_hi = _first_index_after(ox, x0, step, n_cols)
            for w in range(n_wedges):
                if _contains_angle(a0[w], a1[w], 0.0):
                    _run(out, row, max(i_origin_hi, r_lo), r_hi, s, weights, w, scale, see, seeing)
                if _contains_angle(a0[w], a1[w], math.pi):
                    _run(out, row, r_lo, min(i_origin_lo, r_hi), s, weights, w, scale, see, seeing)
            continue
        first_slot = 0 if dy > 0.0 else 2
        for w in range(n_wedges):
            for slot in range(first_slot, first_slot + 2):
                cot_start = pieces[w, slot, 0]
                if math.isnan(cot_start):
                    continue
                cot_end = pieces[w, slot, 1]
                if dy > 0.0:
                    # Bearing falls with x: the piece [b0, b1) is x in (x(b1), x(b0)].
                    i_lo = _first_index_after(ox + dy * cot_end, x0, step, n_cols)
                    i_hi = _first_index_after(ox + dy * cot_start, x0, step, n_cols)
                else:
                    # Bearing rises with x: the piece [b0, b1) is x in [x(b0), x(b1)).
                    i_lo = _first_index_at_or_after(ox + dy * cot_start, x0, step, n_cols)
                    i_hi = _first_index_at_or_after(ox + dy * cot_end, x0, step, n_cols)
                _run(out, row, max(i_lo, r_lo), min(i_hi, r_hi), s, weights, w, scale, see, seeing)
