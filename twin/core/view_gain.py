"""What a prospective view is worth: expected information, detection probability or coverage.

A view the robot could take is described by its **footprint**: for each of its patch columns
(rows of a sparse matrix) the cells its wedge reaches and, per cell, the *lift*: how much more
likely the column is to fire when the object stands in that cell than when it does not,

    lift(r, c) = P(hit_r | object at c) - P(hit_r | object elsewhere)
               = coverage(r, c) * visibility(r, c) * (TPR(d) - FPR),

with the column's coverage of the cell (the supersampled wedge share), the visibility of an
object there (``twin.core.visibility``) and the detector's true- and false-positive rates at
the cell's distance d (from its score calibration). Columns are treated as separate binary
detectors ("hit" when the column's score clears the calibration's threshold).

Given the posterior p over cells (``twin.core.confidence.posterior``; its "absent" mass lies in
no cell), each column's expected information about the object's cell is the mutual information
between its hit and the cell,

    I_r = h(FPR + sum_c p_c lift_rc) - sum_c p_c h(FPR + lift_rc) - (1 - sum_c p_c) h(FPR),

h the binary entropy in nats; a view's gain is the sum over its columns (an upper bound on the
joint information when columns overlap, exact when their wedges are disjoint, as patch columns
are). ``detection_probability`` is Ye & Tsotsos's (1999) objective instead: the probability
that the view detects the object, sum_c p_c lift_rc / (TPR - FPR) summed over columns, and
``unseen_coverage`` the greedy-coverage baseline's: each cell's visible share weighed by how
little it has been seen so far, exp(-observed).

The footprints of every candidate view are computed once per scene; what changes per decision
is the posterior, so each decision is a few sparse products (compiled by numba).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from twin.core.errors import InputError


@dataclass(frozen=True)
class Footprints:
    """The sparse footprints of ``n_views`` candidate views over a grid of ``n_cells`` cells.

    Row r (a patch column of view ``row_view[r]``) holds cells ``cells[indptr[r]:indptr[r+1]]``
    (flat indices, row-major over the grid) with their ``share`` (coverage x visibility, in
    [0, 1]) and ``lift`` (share x (TPR - FPR) at that distance, in [0, 1]). Rows of one view are
    contiguous and ``row_view`` is non-decreasing.
    """

    indptr: np.ndarray
    cells: np.ndarray
    share: np.ndarray
    lift: np.ndarray
    row_view: np.ndarray
    n_views: int
    n_cells: int

    def __post_init__(self) -> None:
        indptr = np.ascontiguousarray(self.indptr, dtype=np.int64)
        cells = np.ascontiguousarray(self.cells, dtype=np.int64)
        share = np.ascontiguousarray(self.share, dtype=float)
        lift = np.ascontiguousarray(self.lift, dtype=float)
        row_view = np.ascontiguousarray(self.row_view, dtype=np.int64)
        rows = len(row_view)
        if indptr.shape != (rows + 1,) or indptr[0] != 0 or np.any(np.diff(indptr) < 0):
            raise InputError(
                f"footprints: indptr must be ({rows + 1},) non-decreasing from 0, "
                f"got shape {indptr.shape}"
            )
        nnz = int(indptr[-1])
        if cells.shape != (nnz,) or share.shape != (nnz,) or lift.shape != (nnz,):
            raise InputError(
                f"footprints: cells, share and lift must each hold indptr[-1] = {nnz} entries"
            )
        if nnz and (cells.min() < 0 or cells.max() >= self.n_cells):
            raise InputError(f"footprints: cell indices must lie in [0, {self.n_cells})")
        bad = ~np.isfinite(share) | (share < 0) | (share > 1 + 1e-9)
        bad |= ~np.isfinite(lift) | (lift < 0) | (lift > 1 + 1e-9)
        if bad.any():
            raise InputError("footprints: share and lift must be finite values in [0, 1]")
        if rows and (
            row_view.min() < 0 or row_view.max() >= self.n_views or np.any(np.diff(row_view) < 0)
        ):
            raise InputError(
                f"footprints: row_view must be non-decreasing view indices in [0, {self.n_views})"
            )
        for name, value in (("indptr", indptr), ("cells", cells), ("share", share),
                            ("lift", lift), ("row_view", row_view)):  # fmt: skip
            object.__setattr__(self, name, value)

    @property
    def rows(self) -> int:
        return len(self.row_view)

    def entries_of(self, view: int) -> slice:
        """The entries of one view's rows (they are contiguous): its cells and their shares."""
        first, last = np.searchsorted(self.row_view, [view, view + 1])
        return slice(int(self.indptr[first]), int(self.indptr[last]))

    @classmethod
    def from_dense(
        cls, views: list[np.ndarray], lift_of: list[np.ndarray] | None = None, floor: float = 1e-6
    ) -> Footprints:
        """Footprints from dense per-view arrays: ``views[k]`` (columns, ny, nx) shares, and
        ``lift_of[k]`` the same shape of lifts (default: the shares, a perfect detector).
        Entries below ``floor`` are dropped."""
        if not views:
            raise InputError("footprints need at least one view")
        n_cells = int(np.prod(views[0].shape[1:]))
        indptr, cells, shares, lifts, row_view = [0], [], [], [], []
        for k, dense in enumerate(views):
            flat = np.asarray(dense, dtype=float).reshape(dense.shape[0], -1)
            if flat.shape[1] != n_cells:
                raise InputError("footprints: every view must cover the same grid")
            lifted = flat if lift_of is None else np.asarray(lift_of[k], float).reshape(flat.shape)
            for r in range(flat.shape[0]):
                keep = np.flatnonzero(flat[r] > floor)
                cells.append(keep)
                shares.append(flat[r, keep])
                lifts.append(lifted[r, keep])
                indptr.append(indptr[-1] + len(keep))
                row_view.append(k)
        return cls(
            np.array(indptr),
            np.concatenate(cells),
            np.clip(np.concatenate(shares), 0.0, 1.0),
            np.clip(np.concatenate(lifts), 0.0, 1.0),
            np.array(row_view),
            len(views),
            n_cells,
        )


@njit(cache=True, inline="always")
def _entropy(p: float) -> float:
    if p <= 0.0 or p >= 1.0:
        return 0.0
    return -p * math.log(p) - (1.0 - p) * math.log(1.0 - p)


@njit(cache=True)
def _information(p, indptr, cells, lift, row_view, n_views, fpr):
    out = np.zeros(n_views)
    base = _entropy(fpr)
    for r in range(len(row_view)):
        mass = 0.0
        fired = 0.0
        conditional = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            pc = p[cells[k]]
            mass += pc
            fired += pc * lift[k]
            conditional += pc * _entropy(fpr + lift[k])
        gain = _entropy(fpr + fired) - conditional - (1.0 - mass) * base
        out[row_view[r]] += max(gain, 0.0)
    return out


@njit(cache=True)
def _weighted(p, indptr, cells, weight, row_view, n_views):
    out = np.zeros(n_views)
    for r in range(len(row_view)):
        total = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            total += p[cells[k]] * weight[k]
        out[row_view[r]] += total
    return out


def _check_cells(footprints: Footprints, values: np.ndarray, what: str) -> np.ndarray:
    flat = np.ascontiguousarray(np.asarray(values, dtype=float).ravel())
    if flat.size != footprints.n_cells:
        raise InputError(
            f"{what} has {flat.size} cells but the footprints cover {footprints.n_cells}; "
            "give the grid the footprints were built for"
        )
    if not np.all(np.isfinite(flat)):
        raise InputError(f"{what} holds NaN or infinite values")
    return flat


def _check_rate(name: str, value: float) -> float:
    if not (math.isfinite(value) and 0.0 <= value < 1.0):
        raise InputError(f"{name} must be a probability in [0, 1), got {value!r}")
    return float(value)


def _lift(footprints: Footprints, novelty: np.ndarray | None) -> np.ndarray:
    if novelty is None:
        return footprints.lift
    novelty = np.asarray(novelty, dtype=float)
    if novelty.shape != footprints.lift.shape:
        raise InputError(
            f"novelty must give one factor per footprint entry ({footprints.lift.size}), "
            f"got shape {novelty.shape}"
        )
    return footprints.lift * np.clip(novelty, 0.0, 1.0)


def information_gain(
    footprints: Footprints,
    cell_probs: np.ndarray,
    fpr: float,
    novelty: np.ndarray | None = None,
) -> np.ndarray:
    """(n_views,) expected information (nats) each view's columns give about the object's cell,
    given the posterior ``cell_probs`` (any shape with ``n_cells`` entries, summing to at most
    1: the rest is "absent") and the detector's false-positive rate ``fpr``.

    ``novelty`` (one factor in [0, 1] per footprint entry) scales each entry's lift: how much
    of what the view would show there is news. Views of a cell from where it was seen before
    mostly repeat what those showed (the same background, the same distractor), which the
    belief's independent views do not know; a planner says so here."""
    p = _check_cells(footprints, cell_probs, "the posterior")
    f = footprints
    fpr = _check_rate("fpr", fpr)
    lift = np.minimum(_lift(f, novelty), 1.0 - fpr)
    return _information(p, f.indptr, f.cells, lift, f.row_view, f.n_views, fpr)


def detection_probability(
    footprints: Footprints,
    cell_probs: np.ndarray,
    contrast: float = 1.0,
    novelty: np.ndarray | None = None,
) -> np.ndarray:
    """(n_views,) probability that each view's columns detect the object (Ye & Tsotsos): the
    posterior mass each sees, weighed by the lift (and ``novelty``, as ``information_gain``),
    divided by ``contrast`` (TPR - FPR at its best, the lift of a fully seen, near cell), so a
    perfect view of all the mass scores 1."""
    p = _check_cells(footprints, cell_probs, "the posterior")
    if not (math.isfinite(contrast) and contrast > 0.0):
        raise InputError(f"contrast must be TPR - FPR > 0, got {contrast!r}")
    f = footprints
    return _weighted(p, f.indptr, f.cells, _lift(f, novelty), f.row_view, f.n_views) / contrast


def unseen_coverage(footprints: Footprints, observed: np.ndarray) -> np.ndarray:
    """(n_views,) the cells each view would see, each weighed by exp(-observed): how little it
    has been seen (``observed``: the grid's seen count per cell, in views)."""
    seen = _check_cells(footprints, observed, "the observed counts")
    f = footprints
    return _weighted(np.exp(-np.maximum(seen, 0.0)), f.indptr, f.cells, f.share, f.row_view,
                     f.n_views)  # fmt: skip
