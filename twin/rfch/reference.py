"""A slow, literal NumPy transcription of the RFCH scoring, to check the compiled kernels against.

Nothing here is clever: labels by a full distance matrix, pairs by all pairwise distances of the
labelled samples of each patch. It shares only the descriptor function with the fast path, so a
mistake in labelling, pair enumeration, bounds or normalization shows up as a difference.
Used by the tests and ``benchmarks/bench_rfch.py``; a 320×240 frame takes seconds.
"""

from __future__ import annotations

import numpy as np

from twin.rfch.descriptor import check_image, raw_descriptors
from twin.rfch.model import RFCH


def reference_labels(model: RFCH, image: np.ndarray) -> np.ndarray:
    """(h, w) labels of the sampled pixels: nearest centre, -1 beyond α × mean distance."""
    params = model.params
    desc = raw_descriptors(check_image(image), params, params.sample_step)
    z = (desc.astype(np.float64) - model.offset) * model.scale
    d2 = ((z[:, :, None, :] - model.centres.astype(np.float64)) ** 2).sum(axis=3)
    labels = np.argmin(d2, axis=2)
    nearest = np.take_along_axis(d2, labels[..., None], axis=2)[..., 0]
    labels[nearest > model.radius.astype(np.float64)[labels] ** 2] = -1
    return labels


def reference_pair_counts(
    labels: np.ndarray, n_labels: int, step: int, d_max: float, box: tuple[int, int, int, int]
) -> np.ndarray:
    """(K, K) upper-triangular counts of unordered labelled pairs ≤ d_max px apart in ``box``.

    ``box`` is (y0, y1, x0, x1) in sample indices, half-open; sample (i, j) is pixel (s·i, s·j).
    """
    y0, y1, x0, x1 = box
    ys, xs = np.nonzero(labels[y0:y1, x0:x1] >= 0)
    values = labels[y0:y1, x0:x1][ys, xs]
    points = np.stack([ys, xs], axis=1).astype(np.float64) * step
    counts = np.zeros((n_labels, n_labels), dtype=np.int64)
    if len(points) < 2:
        return counts
    dist2 = ((points[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    first, second = np.nonzero(np.triu(dist2 <= d_max**2, k=1))
    a, b = values[first], values[second]
    np.add.at(counts, (np.minimum(a, b), np.maximum(a, b)), 1)
    return counts


def intersection(model_hist: np.ndarray, counts: np.ndarray) -> float:
    """Σ min(model, counts / total); 0 for a region without any pair."""
    total = counts.sum()
    if total == 0:
        return 0.0
    return float(np.minimum(model_hist, counts / total).sum())


def reference_scores(model: RFCH, image: np.ndarray) -> np.ndarray:
    """(rows, cols) scores computed literally; equals ``model.scores(image)`` up to rounding."""
    params = model.params
    step = params.sample_step
    labels = reference_labels(model, image)
    grid = params.grid
    out = np.zeros(grid.shape(image.shape))
    for r, y in enumerate(grid.starts(image.shape[0])):
        for c, x in enumerate(grid.starts(image.shape[1])):
            box = (
                -(-y // step),
                -(-(y + grid.size) // step),
                -(-x // step),
                -(-(x + grid.size) // step),
            )
            counts = reference_pair_counts(labels, model.n_clusters, step, params.d_max, box)
            out[r, c] = max(intersection(hist, counts) for hist in model.histograms)
    return out
