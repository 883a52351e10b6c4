"""The compiled hot loops of RFCH: labelling, pair counting and histogram intersection.

Semantics (exactly those of ``twin.rfch.reference``, which is plain NumPy and slow):

- Pixels are taken on a grid with ``sample_step`` s (pixel (s·i, s·j) is sample (i, j)).
  s = 1 is the spec verbatim. s = 2 labels a quarter of the pixels and counts a sixteenth of
  the pairs; because the descriptor is already smoothed over σ ≥ 2 px, neighbouring pixels carry
  nearly the same label and the normalized histograms change little (measured in
  ``tests/test_rfch_exact.py`` and ``benchmarks/rfch_quality.py``). Pair distances are
  always true pixel distances, so d_max keeps its meaning.
- A patch's histogram counts unordered pairs of distinct labelled samples that are BOTH inside
  the patch and at most d_max apart: pairs straddling the patch border are not counted. Each
  pair is found once through the "forward" half of the disc of offsets (dy > 0, or dy = 0 and
  dx > 0; see ``half_widths``) and stored in the upper triangle (i ≤ j) of a K×K count matrix.
- Histogram intersection is Σ min(model, patch / total) over the upper triangle; a patch with
  no labelled pair scores 0 (it shows nothing of the object).

Why it is fast: labelling settles most (background) samples with one vectorized pass over
"distance − radius²"; ``cell_patch_scores`` counts every pair once into a sparse histogram of its
cell group and sums the groups per patch, instead of recounting the pairs that overlapping
patches share; scratch histograms are reset only where touched; only touched bins are
intersected; and background samples cost one load. Sample step 2 is the one approximation
(measured in ``tests/test_rfch_exact.py`` and docs/rfch.md).
"""

from __future__ import annotations

import numba
import numpy as np


def half_widths(d_max: float, step: int) -> np.ndarray:
    """int64 ``w[dy]``: the largest sample offset dx with (dy·step)² + (dx·step)² ≤ d_max².

    The forward half-disc is then: dy = 0 with 1 ≤ dx ≤ w[0], and each dy ≥ 1 with |dx| ≤ w[dy];
    looping over it row by row lets the inner loop run over a clipped contiguous range.
    """
    reach = int(d_max // step)
    return np.array(
        [
            int(np.floor(np.sqrt(max(d_max**2 - (dy * step) ** 2, 0.0)) / step + 1e-9))
            for dy in range(reach + 1)
        ],
        dtype=np.int64,
    )


@numba.njit(cache=True, fastmath=True, nogil=True, inline="always")
def _distances(z, by_dim, dist):
    """Squared distances from ``z`` to every centre (by_dim: D×K centres) into ``dist``."""
    dims, n_centres = by_dim.shape
    zd = z[0]
    for k in range(n_centres):  # contiguous over centres, so the loops run as SIMD
        t = zd - by_dim[0, k]
        dist[k] = t * t
    for d in range(1, dims):
        zd = z[d]
        for k in range(n_centres):
            t = zd - by_dim[d, k]
            dist[k] += t * t


@numba.njit(cache=True, fastmath=True, nogil=True, inline="always")
def _first_minimum(dist):
    """(index, value) of the first smallest entry, found with a vectorizable min first."""
    best = dist[0]
    for k in range(1, dist.shape[0]):
        best = min(best, dist[k])
    for k in range(dist.shape[0]):
        if dist[k] == best:
            return k, best
    return 0, best


@numba.njit(cache=True, fastmath=True, nogil=True)
def nearest_centres(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(n,) int32 index of the nearest centre of each point (both in k-means space)."""
    by_dim = np.ascontiguousarray(centres.T)
    dist = np.empty(centres.shape[0], dtype=np.float32)
    labels = np.empty(points.shape[0], dtype=np.int32)
    for i in range(points.shape[0]):
        _distances(points[i], by_dim, dist)
        labels[i] = _first_minimum(dist)[0]
    return labels


@numba.njit(cache=True, fastmath=True, nogil=True)
def label_samples(
    descriptors: np.ndarray,  # (h, w, D) float32 raw descriptor
    offset: np.ndarray,  # (D,) float32: subtracted first (training mean)
    scale: np.ndarray,  # (D,) float32: then multiplied (weight / training std)
    centres: np.ndarray,  # (K, D) float32 in the scaled space
    radius2: np.ndarray,  # (K,) float32 squared rejection radius per cluster
) -> np.ndarray:
    """(h, w) int32 nearest-centre labels, -1 where the nearest centre is beyond its radius.

    Most pixels of a frame are background for any one object. If every centre is farther than
    its own radius, so is the nearest one: one vectorized pass over (distance - radius²) settles
    those pixels without the (scalar) search for the nearest centre. Same labels, ~2× faster.
    """
    h, w, dims = descriptors.shape
    n_centres = centres.shape[0]
    by_dim = np.ascontiguousarray(centres.T)
    dist = np.empty(n_centres, dtype=np.float32)
    z = np.empty(dims, dtype=np.float32)
    labels = np.full((h, w), -1, dtype=np.int32)
    for y in range(h):
        for x in range(w):
            for d in range(dims):
                z[d] = (descriptors[y, x, d] - offset[d]) * scale[d]
            _distances(z, by_dim, dist)
            margin = dist[0] - radius2[0]
            for k in range(1, n_centres):
                margin = min(margin, dist[k] - radius2[k])
            if margin > 0.0:
                continue  # no centre accepts it: background whichever is nearest
            best_k, best = _first_minimum(dist)
            if best <= radius2[best_k]:
                labels[y, x] = best_k
    return labels


@numba.njit(cache=True, nogil=True, inline="always")
def _count_patch(labels, widths, y0, y1, x0, x1, n_labels, scratch, touched):
    """Add the patch's pairs to ``scratch`` (flat K·K); return (pairs, touched bin count)."""
    total = 0
    n_touched = 0
    for y in range(y0, y1):
        for x in range(x0, x1):
            a = labels[y, x]
            if a < 0:
                continue
            for dy in range(widths.shape[0]):
                yy = y + dy
                if yy >= y1:
                    break
                w = widths[dy]
                lo = x + 1 if dy == 0 else max(x0, x - w)
                hi = min(x1, x + w + 1)
                for xx in range(lo, hi):
                    b = labels[yy, xx]
                    if b < 0:
                        continue
                    index = a * n_labels + b if a <= b else b * n_labels + a
                    if scratch[index] == 0:
                        touched[n_touched] = index
                        n_touched += 1
                    scratch[index] += 1
                    total += 1
    return total, n_touched


@numba.njit(cache=True, nogil=True)
def pair_counts(
    labels: np.ndarray, widths: np.ndarray, n_labels: int, y0: int, y1: int, x0: int, x1: int
) -> np.ndarray:
    """(K, K) int64 upper-triangular pair counts of the samples in [y0, y1) × [x0, x1)."""
    scratch = np.zeros(n_labels * n_labels, dtype=np.int64)
    touched = np.empty(n_labels * n_labels, dtype=np.int64)
    _count_patch(labels, widths, y0, y1, x0, x1, n_labels, scratch, touched)
    return scratch.reshape(n_labels, n_labels)


@numba.njit(cache=True, nogil=True, inline="always")
def _intersect(out, r, c, models, owners, counts, touched, n_touched, total):
    """out[owner, r, c] = best over the owner's histograms of Σ min(model, counts / total)."""
    inverse = 1.0 / total
    for v in range(models.shape[0]):
        score = 0.0
        for t in range(n_touched):
            index = touched[t]
            score += min(models[v, index], counts[index] * inverse)
        owner = owners[v]
        out[owner, r, c] = max(out[owner, r, c], min(score, 1.0))


@numba.njit(cache=True, nogil=True)
def patch_scores(
    labels: np.ndarray,  # (h, w) int32 sample labels, -1 = background
    widths: np.ndarray,  # (reach + 1,) int64 half-disc widths, see half_widths
    row_bounds: np.ndarray,  # (R, 2) int64 half-open sample ranges of the patch rows
    col_bounds: np.ndarray,  # (C, 2) int64 half-open sample ranges of the patch columns
    models: np.ndarray,  # (T, K*K) float32 normalized upper-triangular histograms
    owners: np.ndarray,  # (T,) int64: the object each histogram belongs to (0 … M-1)
    n_objects: int,
) -> np.ndarray:
    """(M, R, C) float32: per object, its best histogram intersection, per patch.

    Several histograms may belong to one object (training views kept apart), and several objects
    may share one codebook: the patch's pairs are then counted once for all of them.
    """
    n_bins = models.shape[1]
    n_labels = int(np.sqrt(n_bins) + 0.5)
    scratch = np.zeros(n_bins, dtype=np.int64)
    touched = np.empty(n_bins, dtype=np.int64)
    out = np.zeros((n_objects, row_bounds.shape[0], col_bounds.shape[0]), dtype=np.float32)
    for r in range(row_bounds.shape[0]):
        for c in range(col_bounds.shape[0]):
            total, n_touched = _count_patch(
                labels,
                widths,
                row_bounds[r, 0],
                row_bounds[r, 1],
                col_bounds[c, 0],
                col_bounds[c, 1],
                n_labels,
                scratch,
                touched,
            )
            if total > 0:
                _intersect(out, r, c, models, owners, scratch, touched, n_touched, total)
            for t in range(n_touched):
                scratch[touched[t]] = 0
    return out


@numba.njit(cache=True, nogil=True)
def cell_patch_scores(
    labels: np.ndarray,  # (h, w) int32 sample labels, -1 = background
    widths: np.ndarray,  # (reach + 1,) int64 half-disc widths, see half_widths
    cell: int,  # cell side in samples; every patch is exactly span × span cells
    span: int,
    row_cells: np.ndarray,  # (R,) int64 first cell row of each patch row
    col_cells: np.ndarray,  # (C,) int64 first cell column of each patch column
    models: np.ndarray,  # (T, K*K) float32 normalized upper-triangular histograms
    owners: np.ndarray,  # (T,) int64: the object each histogram belongs to (0 … M-1)
    n_objects: int,
) -> np.ndarray:
    """Same result as ``patch_scores``, counting every pair once instead of once per patch.

    Overlapping patches (stride < size) share most of their pairs. Here the frame is cut into
    cells such that every patch is a block of whole cells; each pair (p, q) is counted once into
    the sparse histogram of its (cell of p, relative cell of q) group, and a patch's histogram is
    the sum of the groups whose two cells both lie inside it — exactly its pairs, since a pair
    belongs to a patch iff both of its pixels do. Cost: one pass over the pairs plus a merge of
    short sparse lists per patch, instead of (size / stride)² passes over the pairs.
    """
    h, w = labels.shape
    n_bins = models.shape[1]
    n_labels = int(np.sqrt(n_bins) + 0.5)
    reach = widths.shape[0] - 1
    rc = (reach + cell - 1) // cell  # how many cells away a partner can be
    side = 2 * rc + 1
    n_rel = (rc + 1) * side
    ny = (h + cell - 1) // cell
    nx = (w + cell - 1) // cell
    cell_of_x = np.empty(w, dtype=np.int64)
    for x in range(w):
        cell_of_x[x] = x // cell

    # Phase 1: every pair once, into per-group sparse lists (CSR over groups).
    n_labelled = 0
    for y in range(h):
        for x in range(w):
            if labels[y, x] >= 0:
                n_labelled += 1
    n_offsets = 0
    for dy in range(reach + 1):
        n_offsets += widths[dy] if dy == 0 else 2 * widths[dy] + 1
    capacity = max(n_labelled * n_offsets, 1)
    group_start = np.zeros(ny * nx * n_rel + 1, dtype=np.int64)
    entry_bin = np.empty(capacity, dtype=np.int32)
    entry_count = np.empty(capacity, dtype=np.int32)
    scratch = np.zeros(n_rel * n_bins, dtype=np.int32)
    touched = np.empty((n_rel, n_bins), dtype=np.int32)
    n_touched = np.zeros(n_rel, dtype=np.int64)
    position = 0
    for cy in range(ny):
        for cx in range(nx):
            for y in range(cy * cell, min((cy + 1) * cell, h)):
                for x in range(cx * cell, min((cx + 1) * cell, w)):
                    a = labels[y, x]
                    if a < 0:
                        continue
                    for dy in range(reach + 1):
                        yy = y + dy
                        if yy >= h:
                            break
                        row_rel = (yy // cell - cy) * side + rc - cx
                        half = widths[dy]
                        lo = x + 1 if dy == 0 else max(0, x - half)
                        hi = min(w, x + half + 1)
                        for xx in range(lo, hi):
                            b = labels[yy, xx]
                            if b < 0:
                                continue
                            index = a * n_labels + b if a <= b else b * n_labels + a
                            rel = row_rel + cell_of_x[xx]
                            slot = rel * n_bins + index
                            if scratch[slot] == 0:
                                touched[rel, n_touched[rel]] = index
                                n_touched[rel] += 1
                            scratch[slot] += 1
            first_group = (cy * nx + cx) * n_rel
            for rel in range(n_rel):
                group_start[first_group + rel] = position
                for t in range(n_touched[rel]):
                    slot = rel * n_bins + touched[rel, t]
                    entry_bin[position] = touched[rel, t]
                    entry_count[position] = scratch[slot]
                    scratch[slot] = 0
                    position += 1
                n_touched[rel] = 0
    group_start[ny * nx * n_rel] = position

    # Phase 2: each patch sums the groups inside it, then intersects with the model.
    patch = np.zeros(n_bins, dtype=np.int64)
    patch_touched = np.empty(n_bins, dtype=np.int64)
    out = np.zeros((n_objects, row_cells.shape[0], col_cells.shape[0]), dtype=np.float32)
    for r in range(row_cells.shape[0]):
        cy0 = row_cells[r]
        for c in range(col_cells.shape[0]):
            cx0 = col_cells[c]
            total = 0
            count_touched = 0
            for cy in range(cy0, min(cy0 + span, ny)):
                for cx in range(cx0, min(cx0 + span, nx)):
                    for dcy in range(min(rc, cy0 + span - 1 - cy) + 1):
                        for dcx in range(max(-rc, cx0 - cx), min(rc, cx0 + span - 1 - cx) + 1):
                            group = (cy * nx + cx) * n_rel + dcy * side + dcx + rc
                            for e in range(group_start[group], group_start[group + 1]):
                                index = entry_bin[e]
                                if patch[index] == 0:
                                    patch_touched[count_touched] = index
                                    count_touched += 1
                                patch[index] += entry_count[e]
                                total += entry_count[e]
            if total > 0:
                _intersect(out, r, c, models, owners, patch, patch_touched, count_touched, total)
            for t in range(count_touched):
                patch[patch_touched[t]] = 0
    return out


def cell_layout(
    row_bounds: np.ndarray, col_bounds: np.ndarray, reach: int
) -> tuple[int, int, np.ndarray, np.ndarray] | None:
    """(cell, span, first cell rows, first cell columns) if every patch is span × span whole
    cells of side ``cell`` samples, and partners are at most 2 cells away; else None."""
    bounds = np.concatenate([row_bounds, col_bounds])
    sizes = bounds[:, 1] - bounds[:, 0]
    if np.any(sizes != sizes[0]):
        return None
    cell = int(np.gcd.reduce(np.append(bounds[:, 0], sizes[0])))
    if cell < 1 or reach > 2 * cell:
        return None
    return cell, int(sizes[0] // cell), row_bounds[:, 0] // cell, col_bounds[:, 0] // cell
