"""RFCH parameters (every number of the spec, with its default) and the patch grid.

The defaults follow ``specs/rfch.md``: N = 80 clusters, rejection α = 1.5, pairs within
d_max = 10 px, Gaussian-derivative responses (gradient magnitude and Laplacian) at σ = 2 and
4 px. The others were measured with ``benchmarks/rfch_quality.py`` (real photographs, pooled
column AUC / best-column hit rate; see docs/rfch.md):
- ``log_intensity``: log and linear intensity score alike (AUC 0.936 vs 0.937, hits 94 % both);
  log is kept because it makes the derivative responses brightness invariant, as r, g are.
- ``colour_weight`` 1: weighting colour ×2 did not help (0.931 / 92 %); colour alone is far
  worse (0.832 / 74 %), so the texture responses earn their place.
- ``sample_step`` 2: the verbatim step 1 is better (0.957 / 97 %) but ~3× slower; step 2 keeps
  one object well inside 10 ms per 320×240 frame.
- ``views`` "merged": on the two-view objects merged, per-view and separate models are within
  noise of each other (150 frames each: 0.959 / 0.958 / 0.964 and 0.910 / 0.913 / 0.911 AUC),
  and merged is the cheapest with the best hit rate. On rendered head-camera frames of the
  training stage's four objects (``benchmarks/rfch_rendered.py --views-table``) "clustered"
  lowers the column AUC (rice box 0.923 → 0.876, the others by 0–0.005) without finding the
  object's column more often.
- ``view_similarity`` 0.35, ``max_view_models`` 4 ("clustered"): views 45 degrees apart at one
  range match each other at 0.32-0.50 (median per object), so views at least as alike share a
  model (``twin.rfch.views``).
- ``patch_size`` 32, ``stride`` 16: a 320×240 frame gets 19 columns × 14 rows that tile it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from twin.core.errors import InputError

RESPONSES = ("gradient", "laplacian")
VIEW_MODES = ("merged", "per_view", "clustered")


@dataclass(frozen=True)
class PatchGrid:
    """A regular grid of square patches over a frame; each column of patches is one bearing slice.

    Patches are ``size`` × ``size`` pixels, ``stride`` pixels apart. When the stride does not
    tile the frame exactly, one extra patch is aligned with the right (bottom) edge so that every
    pixel column belongs to some patch column. Boxes are half-open pixel ranges.
    """

    size: int = 32
    stride: int = 16

    def __post_init__(self) -> None:
        if int(self.size) != self.size or self.size < 2:
            raise InputError(f"patch size must be an integer >= 2 px, got {self.size!r}")
        if int(self.stride) != self.stride or not 1 <= self.stride <= self.size:
            raise InputError(
                f"patch stride must be an integer in [1, patch size={self.size}] px, "
                f"got {self.stride!r}"
            )

    def starts(self, length: int) -> np.ndarray:
        """First pixel of each patch along an axis of ``length`` pixels."""
        if length < self.size:
            raise InputError(
                f"frame side of {length} px is smaller than the patch size {self.size} px; "
                "use a larger frame or a smaller --patch-size"
            )
        starts = np.arange(0, length - self.size + 1, self.stride)
        if starts[-1] + self.size < length:
            starts = np.append(starts, length - self.size)
        return starts.astype(np.int64)

    def shape(self, frame_shape: tuple[int, ...]) -> tuple[int, int]:
        """(rows, columns) of patches for a frame of shape (height, width, ...)."""
        return len(self.starts(frame_shape[0])), len(self.starts(frame_shape[1]))

    def column_spans(self, width: int) -> np.ndarray:
        """(columns, 2) float array of [u0, u1] pixel spans, ready for ``CameraModel.wedges``."""
        starts = self.starts(width).astype(float)
        return np.stack([starts, starts + self.size], axis=1)

    def boxes(self, frame_shape: tuple[int, ...]) -> np.ndarray:
        """(rows, columns, 4) int array of patch boxes [x0, y0, x1, y1] in pixels, half-open."""
        ys = self.starts(frame_shape[0])
        xs = self.starts(frame_shape[1])
        boxes = np.empty((len(ys), len(xs), 4), dtype=np.int64)
        boxes[..., 0] = xs[None, :]
        boxes[..., 1] = ys[:, None]
        boxes[..., 2] = xs[None, :] + self.size
        boxes[..., 3] = ys[:, None] + self.size
        return boxes


@dataclass(frozen=True)
class RFCHParams:
    """Every parameter of the method. Lengths in pixels of the full-resolution frame.

    Descriptor (shared by all objects with the same values, see ``descriptor_key``):
      ``sigmas`` Gaussian scales (px) of the derivative responses; ``responses`` which
      rotation-invariant responses to use per scale ("gradient" magnitude, "laplacian");
      ``log_intensity`` takes the derivatives of log(I + ``intensity_offset``) (I in 0…255) so
      that a global brightness change leaves them unchanged, as r, g already are.
    Codebook: ``n_clusters`` k-means centres; ``colour_weight`` multiplies the z-scored r, g
      before k-means; ``max_training_pixels`` caps the pixels fed to k-means; ``seed`` makes it
      reproducible; ``kmeans_iterations`` bounds Lloyd's iterations.
    Matching: a pixel farther than ``alpha`` × (its nearest cluster's mean training distance,
      floored at ``min_cluster_radius`` z-units) is background; pairs of labelled pixels at
      most ``d_max`` px apart are counted; ``sample_step`` labels every n-th pixel in each
      direction (pairs keep their true pixel distance) — see ``twin.rfch.kernels``.
    Grid: ``patch_size`` and ``stride`` in px. Views: ``views`` = "merged" (one histogram over
      all training views), "per_view" (one per view; a patch scores its best view) or
      "clustered" (paper §4: similar views merged into a few models, a patch scores its best
      model): agglomerative, the two clusters whose merged histograms intersect most are merged
      while that intersection is at least ``view_similarity``, or while there are more than
      ``max_view_models`` clusters (``twin.rfch.views``).
    """

    n_clusters: int = 80
    alpha: float = 1.5
    d_max: float = 10.0
    sigmas: tuple[float, ...] = (2.0, 4.0)
    responses: tuple[str, ...] = RESPONSES
    log_intensity: bool = True
    intensity_offset: float = 8.0
    colour_weight: float = 1.0
    max_training_pixels: int = 20000
    kmeans_iterations: int = 30
    seed: int = 0
    min_cluster_radius: float = 0.05
    sample_step: int = 2
    patch_size: int = 32
    stride: int = 16
    views: str = "merged"
    view_similarity: float = 0.35
    max_view_models: int = 4

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigmas", tuple(float(s) for s in self.sigmas))
        object.__setattr__(self, "responses", tuple(str(r) for r in self.responses))
        _require_int("n_clusters", self.n_clusters, 2)
        _require_int("max_training_pixels", self.max_training_pixels, 2)
        _require_int("kmeans_iterations", self.kmeans_iterations, 1)
        _require_int("sample_step", self.sample_step, 1)
        _require_int("seed", self.seed, 0)
        _require_int("max_view_models", self.max_view_models, 1)
        if not (
            isinstance(self.view_similarity, int | float)
            and not isinstance(self.view_similarity, bool)
            and 0.0 <= self.view_similarity <= 1.0
        ):
            raise InputError(f"view_similarity must be in [0, 1], got {self.view_similarity!r}")
        _require_positive("alpha", self.alpha)
        _require_positive("d_max", self.d_max)
        _require_positive("colour_weight", self.colour_weight)
        _require_positive("intensity_offset", self.intensity_offset)
        _require_positive("min_cluster_radius", self.min_cluster_radius)
        for sigma in self.sigmas:
            _require_positive("each sigma", sigma)
        unknown = [r for r in self.responses if r not in RESPONSES]
        if unknown or len(set(self.responses)) != len(self.responses):
            raise InputError(
                f"responses must be distinct names among {RESPONSES}, got {self.responses}"
            )
        if self.responses and not self.sigmas:
            raise InputError("responses need at least one sigma; give sigmas or responses=()")
        if self.views not in VIEW_MODES:
            raise InputError(f"views must be one of {VIEW_MODES}, got {self.views!r}")
        if self.d_max < self.sample_step:
            raise InputError(
                f"d_max={self.d_max} px is smaller than sample_step={self.sample_step} px, so "
                "no pair could ever be counted; raise d_max or lower sample_step"
            )
        self.grid  # validates patch size and stride  # noqa: B018

    @property
    def grid(self) -> PatchGrid:
        return PatchGrid(self.patch_size, self.stride)

    @property
    def descriptor_key(self) -> tuple[Any, ...]:
        """The values that decide the raw descriptor; models sharing it share one pass."""
        return (self.sigmas, self.responses, self.log_intensity, self.intensity_offset)

    @property
    def n_dims(self) -> int:
        """Descriptor length: r, g and one value per (sigma, response)."""
        return 2 + len(self.sigmas) * len(self.responses)

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["sigmas"] = list(self.sigmas)
        data["responses"] = list(self.responses)
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RFCHParams:
        names = {f.name for f in fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise InputError(f"unknown RFCH parameters {sorted(unknown)}; known: {sorted(names)}")
        values = dict(data)
        for key in ("sigmas", "responses"):
            if key in values:
                values[key] = tuple(values[key])
        return cls(**values)


def _require_int(name: str, value: Any, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")


def _require_positive(name: str, value: Any) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float | np.number)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise InputError(f"{name} must be a finite number > 0, got {value!r}")
