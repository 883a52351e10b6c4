"""Clustering an object's training views into a few models (paper §4: "different views").

One merged histogram blurs views that look different (a box's printed front and its plain
side; its top seen from above, hidden from below); one histogram per view makes a patch's best
match a maximum over dozens of models, which also lets clutter match some view by chance.
Between the two: views are clustered on their pair histograms, and each cluster's merged
histogram is one model of the object.

Rule: average-linkage agglomerative clustering with the detector's own degree of match as the
similarity (histogram intersection of two views' normalized histograms, so 1 − intersection is
the distance). Two clusters are merged while their views match each other, on average, at least
``similarity``; if that leaves more than ``max_models`` clusters the tree is cut at
``max_models`` instead (a cap on the per-patch cost). Average linkage, not the intersection of
merged histograms: a merged histogram spreads over more bins with every view it takes in, so it
intersects everything better and one cluster swallows all views (measured on the training
stage's objects: 119 of 128 views in one cluster, the rest single far views).
"""

from __future__ import annotations

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage
from scipy.spatial.distance import squareform


def view_similarities(counts: list[np.ndarray]) -> np.ndarray:
    """(V, V) histogram intersections of the views' normalized pair histograms."""
    normalized = np.stack([np.asarray(c, np.float64).ravel() / np.sum(c) for c in counts])
    sim = np.ones((len(counts), len(counts)))
    for i in range(len(counts) - 1):
        sim[i, i + 1 :] = np.minimum(normalized[i], normalized[i + 1 :]).sum(axis=1)
        sim[i + 1 :, i] = sim[i, i + 1 :]
    return sim


def cluster_views(
    counts: list[np.ndarray], similarity: float, max_models: int
) -> tuple[list[np.ndarray], list[int]]:
    """(summed pair counts per cluster, cluster index of each view); clusters are numbered in
    the order of their first view. ``counts`` are the views' raw pair-count matrices."""
    if len(counts) == 1:
        return [np.asarray(counts[0], np.float64)], [0]
    distance = np.clip(1.0 - view_similarities(counts), 0.0, None)
    np.fill_diagonal(distance, 0.0)
    tree = linkage(squareform(distance, checks=False), method="average")
    labels = fcluster(tree, t=1.0 - similarity, criterion="distance")
    if labels.max() > max_models:
        labels = fcluster(tree, t=max_models, criterion="maxclust")
    order = {label: index for index, label in enumerate(dict.fromkeys(labels.tolist()))}
    views = [order[label] for label in labels.tolist()]
    sums = [
        np.sum([np.asarray(counts[v], np.float64) for v in range(len(counts)) if views[v] == k], 0)
        for k in range(len(order))
    ]
    return sums, views
