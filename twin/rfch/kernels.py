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


@numba.njit(cache=True, nogil=True)
def sampled_responses(
    image: np.ndarray,  # (H, W, 3) uint8 RGB
    smooth: np.ndarray,  # (S, H, W) float32 Gaussian-smoothed intensity, one plane per sigma
    sigmas: np.ndarray,  # (S,) float64
    gradient: bool,
    laplacian: bool,
    step: int,
) -> np.ndarray:
    """(h, w, D) float32 raw descriptor at every ``step``-th pixel, in one pass.

    [r, g, then per sigma σ·|∇L| and/or σ²·∇²L]; derivatives are central differences with the
    border mirrored about the edge pixel (OpenCV's default BORDER_REFLECT_101, what the
    Sobel/Laplacian calls this replaces used), computed only where they are sampled.
    """
    height, width = image.shape[0], image.shape[1]
    h = (height + step - 1) // step
    w = (width + step - 1) // step
    n_responses = int(gradient) + int(laplacian)
    out = np.empty((h, w, 2 + n_responses * smooth.shape[0]), dtype=np.float32)
    third = np.float32(1.0 / 3.0)
    half = np.float32(0.5)
    for i in range(h):
        y = i * step
        up = y - 1 if y > 0 else min(1, height - 1)
        down = y + 1 if y < height - 1 else max(height - 2, 0)
        for j in range(w):
            x = j * step
            red = np.float32(image[y, x, 0])
            green = np.float32(image[y, x, 1])
            total = red + green + np.float32(image[y, x, 2])
            if total <= 0.0:  # black has no chromaticity: the neutral grey point
                out[i, j, 0] = third
                out[i, j, 1] = third
            else:
                inverse = np.float32(1.0) / total
                out[i, j, 0] = red * inverse
                out[i, j, 1] = green * inverse
            left = x - 1 if x > 0 else min(1, width - 1)
            right = x + 1 if x < width - 1 else max(width - 2, 0)
            d = 2
            for s in range(smooth.shape[0]):
                plane = smooth[s]
                sigma = np.float32(sigmas[s])
                centre = plane[y, x]
                if gradient:
                    gx = (plane[y, right] - plane[y, left]) * half
                    gy = (plane[down, x] - plane[up, x]) * half
                    out[i, j, d] = np.sqrt(gx * gx + gy * gy) * sigma
                    d += 1
                if laplacian:
                    lap = (
                        plane[up, x] + plane[y, left] + plane[y, right] + plane[down, x]
                    ) - np.float32(4.0) * centre
                    out[i, j, d] = lap * (sigma * sigma)
                    d += 1
    return out


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

    One sample row at a time, laid out dimension-major, and centre by centre: every inner loop
    runs over the row's samples, so it is SIMD over pixels (the squared distance summed over
    dimensions in the same order as ``nearest_centres``, strict ``<`` keeps the first minimum).
    1.6× faster than searching pixel by pixel with an early-out for background; same labels.
    """
    h, w, dims = descriptors.shape
    n_centres = centres.shape[0]
    labels = np.empty((h, w), dtype=np.int32)
    z = np.empty((dims, w), dtype=np.float32)
    dist = np.empty(w, dtype=np.float32)
    best = np.empty(w, dtype=np.float32)
    best_k = np.empty(w, dtype=np.int32)
    for y in range(h):
        for d in range(dims):
            o = offset[d]
            s = scale[d]
            for x in range(w):
                z[d, x] = (descriptors[y, x, d] - o) * s
        best[:] = np.inf
        best_k[:] = 0
        for k in range(n_centres):
            c = centres[k, 0]
            for x in range(w):
                t = z[0, x] - c
                dist[x] = t * t
            for d in range(1, dims):
                c = centres[k, d]
                for x in range(w):
                    t = z[d, x] - c
                    dist[x] += t * t
            for x in range(w):
                closer = dist[x] < best[x]
                best[x] = dist[x] if closer else best[x]
                best_k[x] = k if closer else best_k[x]
        for x in range(w):
            k = best_k[x]
            labels[y, x] = k if best[x] <= radius2[k] else -1
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
def _intersect(out, r, c, by_bin, owners, counts, touched, n_touched, total, sums):
    """out[owner, r, c] = best over the owner's histograms of Σ min(model, counts / total).

    ``by_bin`` is the models bin-major (K·K × T): one pass over the patch's touched bins serves
    every histogram (each bin's count read once, the models' values for it contiguous); each
    histogram's sum runs over the bins in the same order as a pass per histogram would.
    """
    inverse = 1.0 / total
    sums[:] = 0.0
    for t in range(n_touched):
        index = touched[t]
        share = counts[index] * inverse
        for v in range(by_bin.shape[1]):
            sums[v] += min(by_bin[index, v], share)
    for v in range(by_bin.shape[1]):
        owner = owners[v]
        out[owner, r, c] = max(out[owner, r, c], min(sums[v], 1.0))


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
    by_bin = np.ascontiguousarray(models.T)
    sums = np.zeros(models.shape[0], dtype=np.float64)
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
                _intersect(out, r, c, by_bin, owners, scratch, touched, n_touched, total, sums)
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
    # Phase 1: every pair once, into per-group sparse lists (CSR over groups). Partners are
    # walked over each row's list of labelled samples only (background costs nothing, and there
    # is no branch on it), and a new bin is recorded by always writing its slot and advancing
    # the list only if it was empty (that branch was unpredictable on a cluttered frame).
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
    n_slots = n_bins
    # Per row, the labelled samples in order (column, label, slot offset of the column's cell),
    # and for each column the index of the first labelled sample at or after it.
    row_start = np.zeros(h + 1, dtype=np.int64)
    for y in range(h):
        count = 0
        for x in range(w):
            if labels[y, x] >= 0:
                count += 1
        row_start[y + 1] = row_start[y] + count
    lab_x = np.empty(max(row_start[h], 1), dtype=np.int64)
    lab_v = np.empty(max(row_start[h], 1), dtype=np.int64)
    lab_cell = np.empty(max(row_start[h], 1), dtype=np.int64)
    next_at = np.empty((h, w + 1), dtype=np.int64)
    for y in range(h):
        k = row_start[y]
        for x in range(w):
            next_at[y, x] = k
            if labels[y, x] >= 0:
                lab_x[k] = x
                lab_v[k] = labels[y, x]
                lab_cell[k] = (x // cell) * n_slots
                k += 1
        next_at[y, w] = k
    scratch = np.zeros(n_rel * n_slots, dtype=np.int32)
    touched = np.empty(n_rel * n_slots + 1, dtype=np.int64)
    per_group = np.zeros(n_rel + 1, dtype=np.int64)
    fill = np.zeros(n_rel, dtype=np.int64)
    position = 0
    for cy in range(ny):
        for cx in range(nx):
            n_touched = 0
            for y in range(cy * cell, min((cy + 1) * cell, h)):
                x_end = min((cx + 1) * cell, w)
                for i in range(next_at[y, cx * cell], next_at[y, x_end]):
                    x = lab_x[i]
                    a = lab_v[i]
                    for dy in range(reach + 1):
                        yy = y + dy
                        if yy >= h:
                            break
                        row_slot = ((yy // cell - cy) * side + rc - cx) * n_slots
                        half = widths[dy]
                        lo = x + 1 if dy == 0 else max(0, x - half)
                        hi = min(w, x + half + 1)
                        for j in range(next_at[yy, lo], next_at[yy, hi]):
                            b = lab_v[j]
                            small = min(a, b)
                            slot = row_slot + lab_cell[j] + small * n_labels + (a + b - small)
                            touched[n_touched] = slot
                            n_touched += scratch[slot] == 0
                            scratch[slot] += 1
            # Write the cell's groups out in group order (a counting sort of the touched slots).
            per_group[:] = 0
            for t in range(n_touched):
                per_group[touched[t] // n_slots + 1] += 1
            first_group = (cy * nx + cx) * n_rel
            for rel in range(n_rel):
                per_group[rel + 1] += per_group[rel]  # now: where each group's entries start
                group_start[first_group + rel] = position + per_group[rel]
                fill[rel] = position + per_group[rel]
            for t in range(n_touched):
                slot = touched[t]
                rel = slot // n_slots
                entry_bin[fill[rel]] = slot - rel * n_slots
                entry_count[fill[rel]] = scratch[slot]
                fill[rel] += 1
                scratch[slot] = 0
            position += per_group[n_rel]
    group_start[ny * nx * n_rel] = position

    # Phase 2: each patch sums the groups inside it, then intersects with the model.
    patch = np.zeros(n_bins, dtype=np.int64)
    patch_touched = np.empty(n_bins + 1, dtype=np.int64)
    by_bin = np.ascontiguousarray(models.T)
    sums = np.zeros(models.shape[0], dtype=np.float64)
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
                                patch_touched[count_touched] = index  # kept only if new
                                count_touched += patch[index] == 0
                                patch[index] += entry_count[e]
                                total += entry_count[e]
            if total > 0:
                _intersect(
                    out, r, c, by_bin, owners, patch, patch_touched, count_touched, total, sums
                )
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
