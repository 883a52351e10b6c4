"""Column-level ground truth, ROC curves and the threshold that turns scores into detections.

What a positive is (the grid's view of a frame): one patch COLUMN of one frame. Its score is the
maximum over the column's patches (what the grid update uses). It is positive when some patch of
the column has at least ``min_cover`` of its area on the object mask, negative when no pixel of
the column's pixel span is on the mask, and left out of the ROC otherwise (a sliver of the object
at the column's edge is neither a fair hit nor a fair miss). Rates: P_fp = false positives /
negatives, P_fn = misses / positives, at "detected when score ≥ threshold".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError
from twin.rfch.params import PatchGrid


def column_truth(mask: np.ndarray, grid: PatchGrid, min_cover: float = 0.25) -> np.ndarray:
    """(cols,) int8 per patch column: 1 positive, 0 negative, -1 ambiguous (left out)."""
    if not 0.0 < min_cover <= 1.0:
        raise InputError(f"min_cover must be in (0, 1], got {min_cover}")
    boxes = grid.boxes(mask.shape)
    integral = np.pad(mask.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    covered = integral[y1, x1] - integral[y0, x1] - integral[y1, x0] + integral[y0, x0]
    positive = (covered / float(grid.size * grid.size) >= min_cover).any(axis=0)
    touched = np.array([mask[:, a:b].any() for a, b in zip(x0[0], x1[0], strict=True)])
    return np.where(positive, 1, np.where(touched, -1, 0)).astype(np.int8)


@dataclass(frozen=True)
class ROC:
    """Rates at each distinct threshold, from "everything detected" to "nothing detected"."""

    thresholds: np.ndarray
    p_fp: np.ndarray
    p_fn: np.ndarray
    positives: int
    negatives: int

    @property
    def auc(self) -> float:
        """Area under TPR(FPR): the chance a random positive outscores a random negative."""
        tpr = 1.0 - self.p_fn
        order = np.lexsort((tpr, self.p_fp))
        return float(np.trapezoid(tpr[order], self.p_fp[order]))

    def choose(self, max_fp: float | None = None) -> tuple[float, float, float]:
        """(threshold, P_fp, P_fn): least P_fp + P_fn, or least P_fn with P_fp ≤ ``max_fp``."""
        if max_fp is None:
            best = int(np.argmin(self.p_fp + self.p_fn))
        else:
            allowed = np.nonzero(self.p_fp <= max_fp)[0]
            best = int(allowed[np.argmin(self.p_fn[allowed])])
        return float(self.thresholds[best]), float(self.p_fp[best]), float(self.p_fn[best])


def roc_curve(scores: np.ndarray, truth: np.ndarray) -> ROC:
    """ROC of column ``scores`` against ``truth`` (1/0; entries of -1 are ignored)."""
    scores = np.asarray(scores, dtype=float).ravel()
    truth = np.asarray(truth).ravel()
    keep = truth >= 0
    scores, truth = scores[keep], truth[keep].astype(bool)
    positives, negatives = int(truth.sum()), int((~truth).sum())
    if positives == 0 or negatives == 0:
        raise InputError(
            f"an ROC needs positive and negative columns, got {positives} positive and "
            f"{negatives} negative; give frames where the object covers some columns only"
        )
    # Thresholds: every distinct score, plus one above the maximum (nothing detected).
    thresholds = np.append(np.unique(scores), np.inf)
    pos_sorted = np.sort(scores[truth])
    neg_sorted = np.sort(scores[~truth])
    detected_pos = positives - np.searchsorted(pos_sorted, thresholds, side="left")
    detected_neg = negatives - np.searchsorted(neg_sorted, thresholds, side="left")
    return ROC(
        thresholds=thresholds,
        p_fp=detected_neg / negatives,
        p_fn=1.0 - detected_pos / positives,
        positives=positives,
        negatives=negatives,
    )
