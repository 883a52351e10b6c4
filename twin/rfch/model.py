"""One object's RFCH model: training from masked images, model files, per-patch scores."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from twin.core.errors import FileFormatError, InputError, TwinError
from twin.core.store import load_arrays, save_arrays
from twin.rfch import kernels
from twin.rfch.calibration import ScoreCalibration
from twin.rfch.descriptor import check_image, check_mask, raw_descriptors, sample
from twin.rfch.params import RFCHParams
from twin.rfch.views import cluster_views

# The parameters that only decide how an object's views become histograms: free to differ
# between objects sharing one codebook (their codebook_key leaves them out).
VIEW_PARAMETERS = ("views", "view_similarity", "max_view_models")
MODEL_KIND = "rfch-model"
MODEL_VERSION = 1
# Standard deviations below this (in descriptor units: chromaticity, or log/relative intensity
# per px) are floored so that a flat-coloured training object does not blow up the z-scores.
_MIN_STD = 0.01


@dataclass
class RFCH:
    """A trained RFCH model of one object.

    ``offset`` and ``scale`` map the raw descriptor to the k-means space: z = (x - offset) ·
    scale (training mean, and colour weight / training std). ``centres`` (K×D) live in that
    space, ``radius`` (K) is α × each cluster's mean training distance (floored), and
    ``histograms`` (V×K×K) are normalized upper-triangular pair histograms: one per training
    view (``params.views == "per_view"``), one per cluster of similar views ("clustered";
    ``summary["view_models"]`` says which view went where) or a single merged one.
    ``calibration`` (optional) is the measured LLR of this model's column scores
    (``twin.rfch.calibration``), saved in the model file; files written before it existed load
    with none.
    """

    name: str
    params: RFCHParams
    offset: np.ndarray
    scale: np.ndarray
    centres: np.ndarray
    radius: np.ndarray
    histograms: np.ndarray
    summary: dict[str, Any] = field(default_factory=dict)
    calibration: ScoreCalibration | None = None

    def __post_init__(self) -> None:
        if not self.name or not isinstance(self.name, str):
            raise InputError(f"model name must be a non-empty string, got {self.name!r}")
        dims = self.params.n_dims
        k = self.centres.shape[0] if self.centres.ndim == 2 else -1
        expected = {
            "offset": (self.offset, (dims,)),
            "scale": (self.scale, (dims,)),
            "centres": (self.centres, (k, dims)),
            "radius": (self.radius, (k,)),
        }
        for what, (array, shape) in expected.items():
            if array.shape != shape or not np.all(np.isfinite(array)):
                raise InputError(
                    f"model {what} must be finite with shape {shape}, got {array.shape}"
                )
        hist = self.histograms
        if hist.ndim != 3 or hist.shape[1:] != (k, k) or hist.shape[0] < 1:
            raise InputError(f"model histograms must be (views, {k}, {k}), got {hist.shape}")
        if not np.all(np.isfinite(hist)) or np.any(hist < 0):
            raise InputError("model histograms must be finite and non-negative")
        self.offset = self.offset.astype(np.float32)
        self.scale = self.scale.astype(np.float32)
        self.centres = np.ascontiguousarray(self.centres, dtype=np.float32)
        self.radius = self.radius.astype(np.float32)
        self.histograms = np.ascontiguousarray(hist, dtype=np.float32)
        self._codebook_key: str | None = None

    # ---------------------------------------------------------------- training
    @classmethod
    def train(
        cls,
        name: str,
        images: Sequence[np.ndarray],
        masks: Sequence[np.ndarray],
        codebook: RFCH | None = None,
        **params: Any,
    ) -> RFCH:
        """Train on one or more views (H×W×3 uint8 images, H×W bool masks of the object).

        Keyword arguments are ``RFCHParams`` fields. Steps (spec §2): descriptors of the mask
        pixels, z-scoring with their statistics (colour weighted), seeded k-means, per-cluster
        mean distance, then the pair histogram of the masked training pixels built exactly as
        for a test patch (same labelling with rejection, same d_max and sample step).

        With ``codebook`` (another model), its codebook and parameters are reused and only this
        object's histogram is built, so a ``Detector`` labels and counts pairs once for both;
        only the view parameters (``VIEW_PARAMETERS``) may then be given.
        """
        if codebook is None:
            return cls.train_shared({name: (images, masks)}, **params)[0]
        if set(params) - set(VIEW_PARAMETERS):
            raise InputError(
                f"with a codebook only {', '.join(VIEW_PARAMETERS)} may be given, got "
                f"{sorted(params)}; the other parameters come from the codebook's model"
            )
        config = replace(codebook.params, **params)
        views = _checked_views(name, images, masks, config)
        histograms, per_view = _histograms(
            views, config, codebook.offset, codebook.scale, codebook.centres, codebook.radius
        )
        summary = {
            **_view_summary(views, per_view),
            "codebook": dict(codebook.summary.get("codebook", {}), reused_from=codebook.name),
        }
        return cls(
            name,
            config,
            codebook.offset,
            codebook.scale,
            codebook.centres,
            codebook.radius,
            histograms,
            summary,
        )

    @classmethod
    def train_shared(
        cls, objects: Mapping[str, tuple[Sequence[np.ndarray], Sequence[np.ndarray]]], **params: Any
    ) -> list[RFCH]:
        """Train several objects on ONE codebook: {name: (images, masks)} → one model each.

        The spec's remedy for cost linear in the number of objects: k-means runs on the pixels
        of all objects (each object contributing an equal share of ``max_training_pixels``), so
        a ``Detector`` labels each frame and counts its pairs once for all of them; each extra
        object then costs one histogram intersection per patch. The price is the per-object
        rejection: a pixel is background only if it is far from every object's colours.
        """
        config = RFCHParams.from_json(params)
        if not objects:
            raise InputError("training needs at least one object")
        views = {name: _checked_views(name, *data, config) for name, data in objects.items()}
        rng = np.random.default_rng(config.seed)
        share = max(config.max_training_pixels // len(views), 2)
        pixel_sets = []
        for object_views in views.values():
            pixels = np.concatenate([desc[mask] for desc, mask in object_views])
            if len(pixels) > share:
                pixels = pixels[np.sort(rng.choice(len(pixels), share, replace=False))]
            pixel_sets.append(pixels)
        pixels = np.concatenate(pixel_sets)
        mean = pixels.mean(axis=0, dtype=np.float64)
        std = np.maximum(pixels.std(axis=0, dtype=np.float64), _MIN_STD)
        scale = 1.0 / std
        scale[:2] *= config.colour_weight
        points = ((pixels - mean) * scale).astype(np.float32)
        centres = _kmeans(points, config.n_clusters, config.kmeans_iterations, rng)

        labels = nearest_centres(points, centres)
        distances = np.linalg.norm(points - centres[labels], axis=1)
        members = np.bincount(labels, minlength=len(centres))
        keep = members > 0  # k-means may leave a centre without members; it would match nothing
        mean_distance = np.bincount(labels, weights=distances, minlength=len(centres))[keep]
        mean_distance /= members[keep]
        centres = centres[keep]
        radius = config.alpha * np.maximum(mean_distance, config.min_cluster_radius)
        codebook = {
            "objects": list(views),
            "kmeans_pixels": len(points),
            "clusters": len(centres),
            "mean_cluster_distance": float(mean_distance.mean()),
        }
        models = []
        for name, object_views in views.items():
            histograms, per_view = _histograms(object_views, config, mean, scale, centres, radius)
            summary = {**_view_summary(object_views, per_view), "codebook": codebook}
            models.append(cls(name, config, mean, scale, centres, radius, histograms, summary))
        return models

    # ---------------------------------------------------------------- files
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the model atomically as ``.npz`` + JSON header (kind ``rfch-model``, v1); the
        calibration, if any, is a header entry (older readers ignore it)."""
        header = {"name": self.name, "params": self.params.to_json(), "summary": self.summary}
        if self.calibration is not None:
            header["calibration"] = self.calibration.to_json()
        save_arrays(
            path,
            MODEL_KIND,
            MODEL_VERSION,
            header,
            {
                "offset": self.offset,
                "scale": self.scale,
                "centres": self.centres,
                "radius": self.radius,
                "histograms": self.histograms,
            },
        )

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> RFCH:
        """Read a model file; a corrupt or mismatched file is a one-line ``FileFormatError``."""
        header, arrays = load_arrays(path, MODEL_KIND, MODEL_VERSION)
        try:
            params = RFCHParams.from_json(header["params"])
            calibration = header.get("calibration")
            return cls(
                name=header["name"],
                params=params,
                offset=arrays["offset"],
                scale=arrays["scale"],
                centres=arrays["centres"],
                radius=arrays["radius"],
                histograms=arrays["histograms"],
                summary=dict(header.get("summary", {})),
                calibration=None
                if calibration is None
                else ScoreCalibration.from_json(calibration),
            )
        except (KeyError, TypeError, AttributeError, TwinError) as exc:
            raise FileFormatError(
                f"{path}: inconsistent rfch-model file ({exc}); re-train it"
            ) from exc

    # ---------------------------------------------------------------- scoring
    @property
    def codebook_key(self) -> str:
        """Fingerprint of everything labelling and pair counting depend on: models with equal
        keys give the same labels and patch pair counts, so a ``Detector`` does that work once."""
        if self._codebook_key is None:
            digest = hashlib.sha1()
            for array in (self.offset, self.scale, self.centres, self.radius):
                digest.update(np.ascontiguousarray(array).tobytes())
            shared = {k: v for k, v in self.params.to_json().items() if k not in VIEW_PARAMETERS}
            digest.update(json.dumps(shared, sort_keys=True).encode())
            self._codebook_key = digest.hexdigest()
        return self._codebook_key

    @property
    def n_clusters(self) -> int:
        return int(self.centres.shape[0])

    def flat_histograms(self) -> np.ndarray:
        """(V, K·K) float32 histograms as the compiled patch kernel wants them."""
        return self.histograms.reshape(self.histograms.shape[0], -1)

    def label(self, descriptors: np.ndarray) -> np.ndarray:
        """Labels (-1 = background) of sampled raw descriptors (h×w×D)."""
        return _label(descriptors, self.offset, self.scale, self.centres, self.radius)

    def scores(self, image: np.ndarray) -> np.ndarray:
        """Degree of match in [0, 1] of every patch: (rows, cols) float32."""
        from twin.rfch.detector import Detector

        return Detector([self]).scores(image)[0]

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray:
        """(rows, cols, 4) patch boxes [x0, y0, x1, y1] in px for a frame of ``shape``."""
        return self.params.grid.boxes(shape)

    def column_spans(self, width: int) -> np.ndarray:
        """(cols, 2) pixel spans [u0, u1] of the patch columns, for ``CameraModel.wedges``."""
        return self.params.grid.column_spans(width)


def _kmeans(
    points: np.ndarray, n_clusters: int, iterations: int, rng: np.random.Generator
) -> np.ndarray:
    """Seeded k-means: k-means++ seeding from ``rng``, then OpenCV's Lloyd iterations.

    Seeding here (not in OpenCV) keeps all randomness in the numpy Generator, so a seed gives
    the same centres on every machine. Fewer distinct points than clusters lowers the count.
    """
    distinct = np.unique(points, axis=0)
    k = min(n_clusters, len(distinct))
    if k < 2:
        raise InputError(
            "the training pixels have fewer than 2 distinct descriptors; the object region "
            "must show some colour or texture"
        )
    seeds = [distinct[rng.integers(len(distinct))]]
    nearest = np.sum((distinct - seeds[0]) ** 2, axis=1)
    for _ in range(1, k):
        choice = rng.choice(len(distinct), p=nearest / nearest.sum())
        seeds.append(distinct[choice])
        nearest = np.minimum(nearest, np.sum((distinct - distinct[choice]) ** 2, axis=1))
    initial = nearest_centres(points, np.array(seeds, dtype=np.float32))[:, None]
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, iterations, 1e-4)
    _, _, centres = cv2.kmeans(points, k, initial, criteria, 1, cv2.KMEANS_USE_INITIAL_LABELS)
    return np.ascontiguousarray(centres, dtype=np.float32)


def _checked_views(
    name: str, images: Sequence[np.ndarray], masks: Sequence[np.ndarray], config: RFCHParams
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(full-resolution raw descriptor, mask) per checked training view of one object."""
    images, masks = list(images), list(masks)
    if not images:
        raise InputError(f"training {name!r} needs at least one image with its mask")
    if len(images) != len(masks):
        raise InputError(f"{name!r}: got {len(images)} training images but {len(masks)} masks")
    views = []
    for index, (image, mask) in enumerate(zip(images, masks, strict=True)):
        image = check_image(image, f"training image {index} of {name!r}")
        mask = check_mask(mask, image.shape, f"training mask {index} of {name!r}")
        views.append((raw_descriptors(image, config), mask))
    return views


def _histograms(
    views: list[tuple[np.ndarray, np.ndarray]],
    config: RFCHParams,
    offset: np.ndarray,
    scale: np.ndarray,
    centres: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, dict[str, list[int]]]:
    """Normalized model histograms (merged: 1, per view: V, clustered: a few) and, per view,
    its pair count and the index of the histogram (model) it went into."""
    widths = kernels.half_widths(config.d_max, config.sample_step)
    per_view = []
    for index, (desc, mask) in enumerate(views):
        labels = _label(sample(desc, config.sample_step), offset, scale, centres, radius)
        labels[~sample(mask, config.sample_step)] = -1
        counts = kernels.pair_counts(
            labels, widths, len(centres), 0, labels.shape[0], 0, labels.shape[1]
        ).astype(np.float64)
        if counts.sum() == 0:
            raise InputError(
                f"training mask {index} yields no pixel pair within d_max={config.d_max} px "
                "after rejection; give a larger object region or lower sample_step"
            )
        per_view.append(counts)
    if config.views == "merged":
        merged = np.sum(per_view, axis=0)
        histograms = (merged / merged.sum())[None]
    elif config.views == "clustered":
        clusters, models = cluster_views(per_view, config.view_similarity, config.max_view_models)
        histograms = np.stack([c / c.sum() for c in clusters])
    else:
        histograms = np.stack([c / c.sum() for c in per_view])
    if config.views == "merged":
        models = [0] * len(per_view)
    elif config.views == "per_view":
        models = list(range(len(per_view)))
    return histograms, {"pairs_per_view": [int(c.sum()) for c in per_view], "view_models": models}


def _view_summary(
    views: list[tuple[np.ndarray, np.ndarray]], per_view: dict[str, list[int]]
) -> dict[str, Any]:
    return {
        "views": len(views),
        "object_pixels": int(sum(int(mask.sum()) for _, mask in views)),
        **per_view,
    }


def nearest_centres(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(n,) int32 index of the nearest centre of each point (both already in k-means space)."""
    return kernels.nearest_centres(
        np.ascontiguousarray(points, dtype=np.float32),
        np.ascontiguousarray(centres, dtype=np.float32),
    )


def _label(
    descriptors: np.ndarray,
    offset: np.ndarray,
    scale: np.ndarray,
    centres: np.ndarray,
    radius: np.ndarray,
) -> np.ndarray:
    """Labels with rejection (-1 = background) of sampled raw descriptors (h×w×D)."""
    return kernels.label_samples(
        descriptors,
        offset.astype(np.float32),
        scale.astype(np.float32),
        np.ascontiguousarray(centres, np.float32),
        radius.astype(np.float32) ** 2,
    )
