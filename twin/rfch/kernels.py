"""The compiled hot loops of RFCH: labelling, pair counting and histogram intersection.

Semantics (exactly those of ``twin.rfch.reference``, which is plain NumPy and slow):

- Pixels are taken on a grid with ``sample_step`` s (pixel (s·i, s·j) is sample (i, j)).
  s = 1 is the spec verbatim. s = 2 labels a quarter of the pixels and counts a sixteenth of
  the pairs; because the descriptor is already smoothed over σ ≥ 2 px, neighbouring pixels carry
  nearly the same label and the normalized histograms change little (measured in
  ``tests/test_rfch_exact.py``, reported by ``benchmarks/bench_rfch.py``). Pair distances are
  always true pixel distances, so d_max keeps its meaning.
- A patch's histogram counts unordered pairs of distinct labelled samples that are BOTH inside
  the patch and at most d_max apart: pairs straddling the patch border are not counted. Each
  pair is found once through the "forward" half of the disc of offsets (dy > 0, or dy = 0 and
  dx > 0; see ``half_widths``) and stored in the upper triangle (i ≤ j) of a K×K count matrix.
- Histogram intersection is Σ min(model, patch / total) over the upper triangle; a patch with
  no labelled pair scores 0 (it shows nothing of the object).

Why it is fast: each patch is counted into one K×K scratch matrix that stays in L1 cache, only
bins touched by the patch are intersected and then reset, and background samples cost one load.
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


@numba.njit(cache=True, fastmath=True, nogil=True)
def label_samples(
    descriptors: np.ndarray,  # (h, w, D) float32 raw descriptor
    offset: np.ndarray,  # (D,) float32: subtracted first (training mean)
    scale: np.ndarray,  # (D,) float32: then multiplied (weight / training std)
    centres: np.ndarray,  # (K, D) float32 in the scaled space
    radius2: np.ndarray,  # (K,) float32 squared rejection radius per cluster
    reject: bool,
    colour_table: np.ndarray,  # (B, B) bool: can an (r, g) bin be accepted at all?
) -> np.ndarray:
    """(h, w) int32 nearest-centre labels; -1 where the nearest centre is beyond its radius.

    With ``reject``, samples whose (r, g) bin of ``colour_table`` is False are background at
    once: the table is built (``colour_table``) so that no point of such a bin lies within any
    centre's radius even counting colour alone, so the shortcut never changes a label.
    """
    h, w, dims = descriptors.shape
    n_centres = centres.shape[0]
    n_bins = colour_table.shape[0]
    # Dimension-major centres let the distance loop run over contiguous centres (SIMD).
    by_dim = np.ascontiguousarray(centres.T)
    labels = np.empty((h, w), dtype=np.int32)
    dist = np.empty(n_centres, dtype=np.float32)
    for y in range(h):
        for x in range(w):
            if reject:
                rb = min(max(int(descriptors[y, x, 0] * n_bins), 0), n_bins - 1)
                gb = min(max(int(descriptors[y, x, 1] * n_bins), 0), n_bins - 1)
                if not colour_table[rb, gb]:
                    labels[y, x] = -1
                    continue
            for k in range(n_centres):
                dist[k] = 0.0
            for d in range(dims):
                zd = (descriptors[y, x, d] - offset[d]) * scale[d]
                for k in range(n_centres):
                    t = zd - by_dim[d, k]
                    dist[k] += t * t
            best = dist[0]
            best_k = 0
            for k in range(1, n_centres):
                if dist[k] < best:
                    best = dist[k]
                    best_k = k
            if reject and best > radius2[best_k]:
                labels[y, x] = -1
            else:
                labels[y, x] = best_k
    return labels


def colour_table(
    offset: np.ndarray, scale: np.ndarray, centres: np.ndarray, radius: np.ndarray, bins: int = 64
) -> np.ndarray:
    """(bins, bins) bool over (r, g) ∈ [0, 1]²: True where some centre might accept a pixel.

    Distance in the colour dimensions alone is a lower bound of the full distance, so a bin whose
    nearest point is farther than every centre's radius (in r, g only) can hold no accepted pixel
    whatever its other dimensions are. Exact, conservative, and cheap to look up.
    """
    edges = np.linspace(0.0, 1.0, bins + 1)
    lo, hi = edges[:-1], edges[1:]
    raw = centres[:, :2].astype(np.float64) / scale[:2] + offset[:2]  # centres' r, g
    table = np.zeros((bins, bins), dtype=bool)
    for (cr, cg), reach in zip(raw, radius.astype(np.float64) * 1.0001, strict=True):
        dr = np.maximum(np.maximum(lo - cr, cr - hi), 0.0) * scale[0]
        dg = np.maximum(np.maximum(lo - cg, cg - hi), 0.0) * scale[1]
        table |= dr[:, None] ** 2 + dg[None, :] ** 2 <= reach**2
    return table


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


@numba.njit(cache=True, nogil=True)
def patch_scores(
    labels: np.ndarray,  # (h, w) int32 sample labels, -1 = background
    widths: np.ndarray,  # (reach + 1,) int64 half-disc widths, see half_widths
    row_bounds: np.ndarray,  # (R, 2) int64 half-open sample ranges of the patch rows
    col_bounds: np.ndarray,  # (C, 2) int64 half-open sample ranges of the patch columns
    models: np.ndarray,  # (V, K*K) float32 normalized upper-triangular model histograms
) -> np.ndarray:
    """(R, C) float32 best histogram intersection over the V model histograms, per patch."""
    n_views, n_bins = models.shape
    n_labels = int(np.sqrt(n_bins) + 0.5)
    scratch = np.zeros(n_bins, dtype=np.int64)
    touched = np.empty(n_bins, dtype=np.int64)
    out = np.zeros((row_bounds.shape[0], col_bounds.shape[0]), dtype=np.float32)
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
                inverse = 1.0 / total
                best = 0.0
                for v in range(n_views):
                    score = 0.0
                    for t in range(n_touched):
                        index = touched[t]
                        score += min(models[v, index], scratch[index] * inverse)
                    best = max(best, score)
                out[r, c] = min(best, 1.0)
            for t in range(n_touched):
                scratch[touched[t]] = 0
    return out
