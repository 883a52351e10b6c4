"""RFCH quality on real photographs: objects cut out of scikit-image's colour photographs, pasted
at known places (scaled ±20 %, rotated, darker and brighter) into other photographs.

Reports, per object and pooled, the per-column ROC AUC (``twin.rfch.roc``: a column is positive
when one of its patches is ≥ 25 % object, negative when it holds no object pixel) and how often
the frame's best column is a positive one. Several variants are compared (descriptor choices,
sample step, multi-view strategies) and a colour back-projection baseline. Seeded: the same
command prints the same numbers.

    /tmp/venv/bin/python benchmarks/rfch_quality.py            # ~1 min on one core
    /tmp/venv/bin/python benchmarks/rfch_quality.py --frames 20 --variants default
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
import skimage.data

from twin.rfch import RFCH, Detector
from twin.rfch.params import PatchGrid
from twin.rfch.roc import column_truth, roc_curve
from twin.rfch.synthetic import paste

FRAME_W, FRAME_H = 320, 240
OBJECT_SIDE = 44  # px: nominal larger side of a pasted object (±20 %), under 3 patch columns
DISTRACTORS = 2  # other objects pasted into every frame, so that specificity matters
NOISE = 3.0  # grey levels of Gaussian pixel noise over every test frame


@dataclass
class CutOut:
    name: str
    source: str  # photograph it comes from: never used as a background for it
    views: list[tuple[np.ndarray, np.ndarray]]  # (image, bool mask) per training view


def _ellipse_mask(shape, centre, axes) -> np.ndarray:
    mask = np.zeros(shape[:2], np.uint8)
    cv2.ellipse(mask, centre, axes, 0, 0, 360, 1, -1)
    return mask.astype(bool)


def _polygon_mask(shape, points) -> np.ndarray:
    mask = np.zeros(shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.array(points, np.int32)], 1)
    return mask.astype(bool)


def _cut(image: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Crop to the mask's bounding box and resize so the larger side is OBJECT_SIDE px."""
    ys, xs = np.nonzero(mask)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    crop, crop_mask = image[y0:y1, x0:x1], mask[y0:y1, x0:x1]
    factor = OBJECT_SIDE / max(crop.shape[:2])
    size = (max(round(crop.shape[1] * factor), 2), max(round(crop.shape[0] * factor), 2))
    small = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
    small_mask = cv2.resize(crop_mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
    return small, small_mask.astype(bool)


def cut_outs() -> list[CutOut]:
    coffee, astronaut, chelsea = (
        skimage.data.coffee(),
        skimage.data.astronaut(),
        skimage.data.chelsea(),
    )
    left, right, _ = skimage.data.stereo_motorcycle()
    tank_left = [(330, 170), (500, 150), (505, 240), (420, 250), (330, 250)]
    tank_right = [(x - 62, y) for x, y in tank_left]  # the stereo disparity at the tank
    front = [(330, 150), (560, 110), (600, 290), (480, 310), (330, 250)]
    rear = [(90, 160), (330, 160), (330, 250), (240, 265), (90, 235)]
    return [
        CutOut(
            "cup", "coffee", [_cut(coffee, _ellipse_mask(coffee.shape, (292, 140), (118, 125)))]
        ),
        CutOut(
            "patch",
            "astronaut",
            [_cut(astronaut, _ellipse_mask(astronaut.shape, (170, 385), (37, 37)))],
        ),
        CutOut(
            "cat", "chelsea", [_cut(chelsea, _ellipse_mask(chelsea.shape, (245, 160), (120, 110)))]
        ),
        # Two real views of the same part (a stereo pair: nearly the same appearance) ...
        CutOut(
            "tank",
            "motorcycle",
            [
                _cut(left, _polygon_mask(left.shape, tank_left)),
                _cut(right, _polygon_mask(right.shape, tank_right)),
            ],
        ),
        # ... and two faces of one object that look different (front: tank, lamp, fork;
        # rear: seat, fender, tail), as views from the front and from behind would.
        CutOut(
            "motorbike",
            "motorcycle",
            [
                _cut(left, _polygon_mask(left.shape, front)),
                _cut(left, _polygon_mask(left.shape, rear)),
            ],
        ),
    ]


def photographs() -> dict[str, np.ndarray]:
    return {
        "astronaut": skimage.data.astronaut(),
        "chelsea": skimage.data.chelsea(),
        "coffee": skimage.data.coffee(),
        "rocket": skimage.data.rocket(),
        "immunohistochemistry": skimage.data.immunohistochemistry(),
        "retina": skimage.data.retina(),
        "motorcycle": skimage.data.stereo_motorcycle()[0],
    }


def background(rng: np.random.Generator, photo: np.ndarray) -> np.ndarray:
    """A random 4:3 crop (50–100 % of the photo's short side) resized to 320×240."""
    h, w = photo.shape[:2]
    crop_h = int(min(h, w * 3 / 4) * rng.uniform(0.5, 1.0))
    crop_w = int(crop_h * 4 / 3)
    y0 = rng.integers(0, h - crop_h + 1)
    x0 = rng.integers(0, w - crop_w + 1)
    return cv2.resize(
        photo[y0 : y0 + crop_h, x0 : x0 + crop_w], (FRAME_W, FRAME_H), interpolation=cv2.INTER_AREA
    )


def _random_paste(rng, frame, view, avoid=None):
    image, mask = view
    scale = rng.uniform(0.8, 1.2)
    reach = 0.5 * np.hypot(*image.shape[:2]) * scale
    for _ in range(50):  # distractors must not cover the target
        centre = (rng.uniform(reach, FRAME_W - reach), rng.uniform(reach, FRAME_H - reach))
        if avoid is None or abs(centre[0] - avoid[0]) > reach + avoid[1]:
            break
    pasted, cover = paste(
        frame, image, mask, centre, scale, rng.uniform(-180, 180), rng.uniform(0.7, 1.3)
    )
    return pasted, cover, (centre[0], reach)


def test_frames(
    cut: CutOut, others: list[CutOut], photos: dict[str, np.ndarray], n: int, seed: int
):
    """(frame, mask) pairs: a random view of ``cut`` pasted with random scale, angle and
    brightness into another photograph, plus DISTRACTORS views of other objects beside it, then
    a random white-balance cast (±10 % per channel) and NOISE over the whole frame."""
    rng = np.random.default_rng(seed)
    names = [name for name in photos if name != cut.source]
    frames = []
    for _ in range(n):
        frame = background(rng, photos[names[rng.integers(len(names))]])
        frame, mask, place = _random_paste(rng, frame, cut.views[rng.integers(len(cut.views))])
        for _ in range(DISTRACTORS):
            other = others[rng.integers(len(others))]
            view = other.views[rng.integers(len(other.views))]
            frame, cover, _ = _random_paste(rng, frame, view, avoid=place)
            mask &= ~cover
        # The camera's own variation: a white-balance cast over the whole frame, and noise.
        cast = rng.uniform(0.9, 1.1, size=3).astype(np.float32)
        noisy = frame * cast + rng.normal(0.0, NOISE, frame.shape).astype(np.float32)
        frames.append((np.clip(noisy + 0.5, 0, 255).astype(np.uint8), mask))
    return frames


def evaluate(score_columns: Callable[[np.ndarray], np.ndarray], frames, grid: PatchGrid):
    """(AUC, best-column hit rate, mean seconds per frame) of a column scorer."""
    scores, truths, hits = [], [], []
    start = time.perf_counter()
    for frame, mask in frames:
        columns = score_columns(frame)
        truth = column_truth(mask, grid)
        scores.append(columns)
        truths.append(truth)
        hits.append(truth[int(np.argmax(columns))] == 1)
    seconds = (time.perf_counter() - start) / len(frames)
    return (
        roc_curve(np.concatenate(scores), np.concatenate(truths)).auc,
        float(np.mean(hits)),
        seconds,
    )


def rfch_variant(**params):
    def build(cut: CutOut):
        images, masks = zip(*cut.views, strict=True)
        model = RFCH.train(cut.name, images, masks, **params)
        return lambda frame: model.scores(frame).max(axis=0)

    return build


def separate_models(**params):
    """One independent model (own codebook) per view; a column scores its best model."""

    def build(cut: CutOut):
        detector = Detector([RFCH.train(cut.name, [im], [m], **params) for im, m in cut.views])
        return lambda frame: detector.scores(frame).max(axis=(0, 1))

    return build


def shared_codebook(**params):
    """All objects of the benchmark on one codebook (``RFCH.train_shared``)."""
    cache: dict[str, RFCH] = {}

    def build(cut: CutOut):
        if cut.name not in cache:
            objects = {c.name: tuple(zip(*c.views, strict=True)) for c in cut_outs()}
            cache.update({m.name: m for m in RFCH.train_shared(objects, **params)})
        model = cache[cut.name]
        return lambda frame: model.scores(frame).max(axis=0)

    return build


def backprojection(bins: int = 32):
    """Baseline: the object's (r, g) histogram back-projected, averaged over each patch."""

    def chroma(image: np.ndarray) -> np.ndarray:
        rgb = image.astype(np.float32) + 1.0
        return (rgb[..., :2] / rgb.sum(axis=2, keepdims=True)).astype(np.float32)

    def build(cut: CutOut):
        samples = np.concatenate([chroma(im)[m] for im, m in cut.views])
        hist = cv2.calcHist([samples[None]], [0, 1], None, [bins, bins], [0, 1, 0, 1])
        hist /= hist.max()
        grid = PatchGrid()

        def score(frame: np.ndarray) -> np.ndarray:
            prob = cv2.calcBackProject([chroma(frame)], [0, 1], hist, [0, 1, 0, 1], 1.0)
            boxes = grid.boxes(frame.shape)
            integral = cv2.integral(prob)
            x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
            sums = integral[y1, x1] - integral[y0, x1] - integral[y1, x0] + integral[y0, x0]
            return sums.max(axis=0)

        return score

    return build


VARIANTS = {
    "default": rfch_variant(),
    "linear-intensity": rfch_variant(log_intensity=False),
    "colour-weight-2": rfch_variant(colour_weight=2.0),
    "gradient-only": rfch_variant(responses=("gradient",)),
    "colour-only": rfch_variant(responses=()),
    "alpha-2.5": rfch_variant(alpha=2.5),
    "sample-step-1": rfch_variant(sample_step=1),
    "per-view-histograms": rfch_variant(views="per_view"),
    "clustered-views": rfch_variant(views="clustered"),
    "separate-models": separate_models(),
    "shared-codebook": shared_codebook(),
    "shared-codebook-160": shared_codebook(n_clusters=160),
    "backprojection": backprojection(),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=40, help="test frames per object (40)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated names")
    args = parser.parse_args()
    cuts = cut_outs()
    photos = photographs()
    frames = {
        cut.name: test_frames(
            cut, [c for c in cuts if c is not cut], photos, args.frames, args.seed
        )
        for cut in cuts
    }
    grid = PatchGrid()
    names = [cut.name for cut in cuts]
    print(
        f"{args.frames} frames of 320×240 per object ({OBJECT_SIDE} px ±20 %, "
        f"{DISTRACTORS} other objects as distractors); AUC / best-column hit rate"
    )
    print(
        f"{'variant':22s}"
        + "".join(f"{n:>14s}" for n in names)
        + f"{'pooled AUC':>12s}{'hits':>7s}{'ms':>7s}"
    )
    for variant in args.variants.split(","):
        build = VARIANTS[variant]
        cells, aucs, hit_rates, times = [], [], [], []
        for cut in cuts:
            auc, hits, seconds = evaluate(build(cut), frames[cut.name], grid)
            cells.append(f"{auc:7.3f} /{hits:4.0%}")
            aucs.append(auc)
            hit_rates.append(hits)
            times.append(seconds)
        print(
            f"{variant:22s}"
            + "".join(f"{c:>14s}" for c in cells)
            + f"{np.mean(aucs):12.3f}{np.mean(hit_rates):7.0%}{1000 * np.mean(times):7.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
