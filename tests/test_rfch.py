"""RFCH: known answers on hand-made label images, invariance, files, Detector, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.core.errors import FileFormatError, InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.store import save_arrays
from twin.rfch import RFCH, Detector, PatchGrid, RFCHParams, kernels
from twin.rfch.reference import intersection, reference_pair_counts
from twin.rfch.roc import column_truth, roc_curve
from twin.rfch.synthetic import cloudy_background, paste, striped_object

SMALL = {"n_clusters": 16}


def scene(seed: int, centre=(90, 40), **pose) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    obj, mask = striped_object(40)
    return paste(cloudy_background(rng, 96, 128), obj, mask, centre, **pose)


@pytest.fixture(scope="module")
def model() -> RFCH:
    frame, mask = scene(0, centre=(60, 50))
    return RFCH.train("rings", [frame], [mask], **SMALL)


def box_containing(model: RFCH, shape, xy) -> set[tuple[int, int]]:
    """Patches whose box holds the pixel ``xy``."""
    boxes = model.patch_boxes(shape)
    x, y = xy
    inside = (boxes[..., 0] <= x) & (x < boxes[..., 2]) & (boxes[..., 1] <= y) & (y < boxes[..., 3])
    return {tuple(int(v) for v in rc) for rc in np.argwhere(inside)}


# ------------------------------------------------------------------ known answers


@pytest.mark.parametrize("count", [kernels.pair_counts, "reference"])
def test_pair_counts_on_a_tiny_label_image(count) -> None:
    labels = np.array([[0, 1, 0], [-1, 2, 1]], dtype=np.int32)

    def counts(d_max: float) -> np.ndarray:
        if count == "reference":
            return reference_pair_counts(labels, 3, 1, d_max, (0, 2, 0, 3))
        return count(labels, kernels.half_widths(d_max, 1), 3, 0, 2, 0, 3)

    # d_max = 1: horizontal and vertical neighbours only; the background pixel joins no pair.
    expected = np.zeros((3, 3), dtype=np.int64)
    expected[0, 1] = 2  # (0,0)-(0,1) and (0,1)-(0,2)
    expected[1, 2] = 2  # (0,1)-(1,1) and (1,1)-(1,2)
    expected[0, 1] += 1  # (0,2)-(1,2)
    np.testing.assert_array_equal(counts(1.0), expected)
    # d_max = 1.5 adds the diagonals: (0,0)-(1,1) 0-2, (0,2)-(1,1) 0-2, (0,1)-(1,2) 1-1.
    expected[0, 2] += 2
    expected[1, 1] += 1
    np.testing.assert_array_equal(counts(1.5), expected)
    # d_max = 2 adds the two pixels two apart: (0,0)-(0,2) 0-0; (1,0) is background.
    expected[0, 0] += 1
    np.testing.assert_array_equal(counts(2.0), expected)


def test_pair_counts_use_true_pixel_distance_with_a_sample_step() -> None:
    labels = np.zeros((1, 4), dtype=np.int32)  # samples at pixels 0, 2, 4, 6
    widths = kernels.half_widths(3.0, 2)
    assert kernels.pair_counts(labels, widths, 1, 0, 1, 0, 4)[0, 0] == 3  # only neighbours
    widths = kernels.half_widths(4.0, 2)
    assert kernels.pair_counts(labels, widths, 1, 0, 1, 0, 4)[0, 0] == 5  # 2 and 4 px apart


def test_pairs_straddling_the_patch_border_are_not_counted() -> None:
    labels = np.zeros((1, 4), dtype=np.int32)
    widths = kernels.half_widths(1.0, 1)
    assert kernels.pair_counts(labels, widths, 1, 0, 1, 0, 2)[0, 0] == 1
    assert kernels.pair_counts(labels, widths, 1, 0, 1, 1, 4)[0, 0] == 2


def test_intersection_of_identical_histograms_is_one_and_of_disjoint_ones_zero() -> None:
    rng = np.random.default_rng(3)
    labels = rng.integers(0, 2, size=(8, 8)).astype(np.int32)  # labels 0 and 1 only
    widths = kernels.half_widths(2.0, 1)
    counts = kernels.pair_counts(labels, widths, 4, 0, 8, 0, 8).astype(np.float64)
    model = (counts / counts.sum()).astype(np.float32).reshape(1, -1)
    whole = np.array([[0, 8]])
    owner = np.zeros(1, dtype=np.int64)
    same = kernels.patch_scores(labels, widths, whole, whole, model, owner, 1)
    assert same[0, 0, 0] == pytest.approx(1.0, abs=1e-6)
    assert intersection(model.reshape(4, 4), counts) == pytest.approx(1.0, abs=1e-6)
    other = (labels + 2).astype(np.int32)  # labels 2 and 3: no bin in common
    assert kernels.patch_scores(other, widths, whole, whole, model, owner, 1)[0, 0, 0] == 0.0
    empty = np.full((8, 8), -1, dtype=np.int32)
    assert kernels.patch_scores(empty, widths, whole, whole, model, owner, 1)[0, 0, 0] == 0.0


# ------------------------------------------------------------------ detection


def test_the_object_patch_scores_highest(model: RFCH) -> None:
    frame, _ = scene(1, centre=(90, 40))
    scores = model.scores(frame)
    assert scores.shape == model.params.grid.shape(frame.shape)
    assert scores.dtype == np.float32 and scores.min() >= 0.0 and scores.max() <= 1.0
    best = np.unravel_index(np.argmax(scores), scores.shape)
    assert tuple(int(v) for v in best) in box_containing(model, frame.shape, (90, 40))
    assert scores.max() > 2.0 * np.median(scores)


@pytest.mark.parametrize(
    "pose", [{"gain": 0.7}, {"gain": 1.2}, {"angle_deg": 90.0}, {"scale": 0.8}, {"scale": 1.2}]
)
def test_right_patch_still_scores_highest_under_pose_and_lighting(model: RFCH, pose) -> None:
    frame, _ = scene(2, centre=(40, 56), **pose)
    scores = model.scores(frame)
    best = tuple(int(v) for v in np.unravel_index(np.argmax(scores), scores.shape))
    assert best in box_containing(model, frame.shape, (40, 56))


def test_rotating_or_darkening_the_whole_frame_keeps_the_best_patch(model: RFCH) -> None:
    frame, _ = scene(2, centre=(40, 56))
    rotated = np.ascontiguousarray(np.rot90(frame))  # 128×96: pixel (x, y) → (y, 127 - x)
    scores = model.scores(rotated)
    best = tuple(int(v) for v in np.unravel_index(np.argmax(scores), scores.shape))
    assert best in box_containing(model, rotated.shape, (56, 127 - 40))
    darker = (frame.astype(np.float32) * 0.7).astype(np.uint8)
    scores = model.scores(darker)
    best = tuple(int(v) for v in np.unravel_index(np.argmax(scores), scores.shape))
    assert best in box_containing(model, frame.shape, (40, 56))


def test_detector_with_several_models_equals_each_model_alone(model: RFCH) -> None:
    frame, mask = scene(7, centre=(70, 60))
    other = RFCH.train("clouds", [frame], [~mask], n_clusters=12, seed=4)
    third = RFCH.train("coarse", [frame], [mask], n_clusters=8, sigmas=(3.0,), sample_step=1)
    test_frame, _ = scene(8)
    together = Detector([model, other, third]).scores(test_frame)
    assert together.shape[0] == 3
    for index, alone in enumerate([model, other, third]):
        np.testing.assert_array_equal(together[index], alone.scores(test_frame))


def test_training_is_reproducible_with_a_seed() -> None:
    frame, mask = scene(9)
    first = RFCH.train("a", [frame], [mask], n_clusters=12, seed=5)
    again = RFCH.train("a", [frame], [mask], n_clusters=12, seed=5)
    other = RFCH.train("a", [frame], [mask], n_clusters=12, seed=6)
    np.testing.assert_array_equal(first.centres, again.centres)
    np.testing.assert_array_equal(first.histograms, again.histograms)
    assert not np.array_equal(first.centres, other.centres)


def test_views_merged_or_per_view() -> None:
    views = [scene(s, centre=(60, 50), angle_deg=a) for s, a in ((10, 0.0), (11, 45.0))]
    images, masks = zip(*views, strict=True)
    merged = RFCH.train("m", images, masks, **SMALL)
    per_view = RFCH.train("p", images, masks, views="per_view", **SMALL)
    assert merged.histograms.shape == (1, 16, 16)
    assert per_view.histograms.shape == (2, 16, 16)
    np.testing.assert_allclose(per_view.histograms.sum(axis=(1, 2)), 1.0, atol=1e-5)
    np.testing.assert_allclose(merged.histograms.sum(), 1.0, atol=1e-5)
    # A per-view model scores each patch by its best view, so never below view 0 alone.
    frame, _ = scene(12)
    view0 = RFCH(
        "v0",
        per_view.params,
        per_view.offset,
        per_view.scale,
        per_view.centres,
        per_view.radius,
        per_view.histograms[:1],
    )
    assert np.all(per_view.scores(frame) >= view0.scores(frame))


# ------------------------------------------------------------------ patch grid


def test_default_grid_gives_a_320_px_frame_16_to_32_columns_that_cover_it() -> None:
    grid = RFCHParams().grid
    spans = grid.column_spans(320)
    assert 16 <= len(spans) <= 32
    assert spans[0, 0] == 0 and spans[-1, 1] == 320
    assert np.all(np.diff(spans[:, 0]) > 0)
    wedges = CameraModel().wedges(Pose2D(1.0, 2.0, 0.0), 0.0, spans)
    assert wedges.shape == (len(spans), 2)
    assert wedges[0, 1] == pytest.approx(math.radians(22.5))


def test_a_grid_that_does_not_tile_adds_an_edge_aligned_patch() -> None:
    grid = PatchGrid(size=30, stride=20)
    assert list(grid.starts(100)) == [0, 20, 40, 60, 70]
    boxes = grid.boxes((50, 100))
    assert boxes.shape == (2, 5, 4)
    assert boxes[-1, -1].tolist() == [70, 20, 100, 50]


# ------------------------------------------------------------------ files


def test_save_load_round_trip(model: RFCH, tmp_path) -> None:
    path = tmp_path / "rings.rfch.npz"
    model.save(path)
    loaded = RFCH.load(path)
    assert loaded.name == model.name and loaded.params == model.params
    assert loaded.summary == model.summary
    frame, _ = scene(4)
    np.testing.assert_array_equal(loaded.scores(frame), model.scores(frame))


def test_corrupt_or_foreign_model_files_are_clear_errors(model: RFCH, tmp_path) -> None:
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file")
    with pytest.raises(FileFormatError, match="not a readable rfch-model"):
        RFCH.load(garbage)
    foreign = tmp_path / "grid.npz"
    save_arrays(foreign, "grid", 1, {}, {"cells": np.zeros(3)})
    with pytest.raises(FileFormatError, match="not a 'rfch-model' file"):
        RFCH.load(foreign)
    truncated = tmp_path / "truncated.npz"
    save_arrays(truncated, "rfch-model", 1, {"name": "x", "params": {}}, {"offset": np.zeros(6)})
    with pytest.raises(FileFormatError, match="re-train"):
        RFCH.load(truncated)
    wrong = tmp_path / "wrong.npz"
    save_arrays(
        wrong,
        "rfch-model",
        1,
        {"name": "x", "params": model.params.to_json()},
        {
            "offset": model.offset,
            "scale": model.scale,
            "centres": model.centres[:, :3],
            "radius": model.radius,
            "histograms": model.histograms,
        },
    )
    with pytest.raises(FileFormatError, match="centres"):
        RFCH.load(wrong)
    with pytest.raises(FileFormatError, match="no such file"):
        RFCH.load(tmp_path / "missing.npz")


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (np.zeros((96, 128), np.uint8), "H×W×3"),
        (np.zeros((96, 128, 4), np.uint8), "H×W×3"),
        (np.ones((96, 128, 3), np.float64), "uint8"),
        (np.full((96, 128, 3), np.nan), "NaN"),
        (np.full((96, 128, 3), 77, np.uint8), "constant"),
        (np.arange(20 * 20 * 3, dtype=np.uint8).reshape(20, 20, 3), "smaller than the patch"),
        ([[1, 2, 3]], "numpy array"),
    ],
)
def test_bad_frames_are_clear_errors(model: RFCH, frame, message) -> None:
    with pytest.raises(InputError, match=message):
        model.scores(frame)


def test_bad_training_input_is_a_clear_error() -> None:
    frame, mask = scene(0)
    with pytest.raises(InputError, match="empty"):
        RFCH.train("x", [frame], [np.zeros_like(mask)])
    with pytest.raises(InputError, match="dtype bool"):
        RFCH.train("x", [frame], [mask.astype(np.uint8)])
    with pytest.raises(InputError, match="match their images"):
        RFCH.train("x", [frame], [mask[:50]])
    with pytest.raises(InputError, match="2 training images but 1 masks"):
        RFCH.train("x", [frame, frame], [mask])
    with pytest.raises(InputError, match="at least one image"):
        RFCH.train("x", [], [])
    with pytest.raises(InputError, match="name"):
        RFCH.train("", [frame], [mask], **SMALL)
    one_pixel = np.zeros_like(mask)
    one_pixel[40, 40] = True
    with pytest.raises(InputError, match="distinct descriptors"):
        RFCH.train("x", [frame], [one_pixel])
    with pytest.raises(InputError, match="unknown RFCH parameters"):
        RFCH.train("x", [frame], [mask], clusters=3)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"n_clusters": 1}, "n_clusters"),
        ({"alpha": 0.0}, "alpha"),
        ({"d_max": float("nan")}, "d_max"),
        ({"sigmas": (2.0, -1.0)}, "sigma"),
        ({"responses": ("curvature",)}, "responses"),
        ({"views": "best"}, "views"),
        ({"patch_size": 16, "stride": 20}, "stride"),
        ({"sample_step": 4, "d_max": 3.0}, "no pair"),
        ({"colour_weight": True}, "colour_weight"),
    ],
)
def test_bad_parameters_are_clear_errors(params, message) -> None:
    with pytest.raises(InputError, match=message):
        RFCHParams(**params)


def test_detector_refuses_models_with_different_grids(model: RFCH) -> None:
    frame, mask = scene(0)
    coarse = RFCH.train("x", [frame], [mask], n_clusters=8, patch_size=48, stride=24)
    with pytest.raises(InputError, match="same patch size"):
        Detector([model, coarse])
    with pytest.raises(InputError, match="at least one"):
        Detector([])


# ------------------------------------------------------------------ ROC


def test_column_truth_and_roc() -> None:
    grid = PatchGrid(size=20, stride=10)
    mask = np.zeros((40, 100), dtype=bool)
    mask[5:25, 30:52] = True  # covers columns starting at 30, 40 fully; 20 and 50 partly
    truth = column_truth(mask, grid, min_cover=0.25)
    assert list(grid.starts(100)) == [0, 10, 20, 30, 40, 50, 60, 70, 80]
    assert truth.tolist() == [0, 0, 1, 1, 1, -1, 0, 0, 0]
    scores = np.array([0.1, 0.2, 0.7, 0.9, 0.8, 0.95, 0.3, 0.6, 0.1])
    roc = roc_curve(scores, truth)
    assert (roc.positives, roc.negatives) == (3, 5)
    assert roc.auc == pytest.approx(1.0)
    threshold, p_fp, p_fn = roc.choose()
    assert (p_fp, p_fn) == (0.0, 0.0) and 0.6 < threshold <= 0.7
    swapped = roc_curve(1.0 - scores, truth)
    assert swapped.auc == pytest.approx(0.0)
    with pytest.raises(InputError, match="positive and negative"):
        roc_curve(scores, np.zeros(9))


# ------------------------------------------------------------------ shared codebook


def test_objects_on_a_shared_codebook_are_scored_together_and_alone_alike(model: RFCH) -> None:
    rings_frame, rings_mask = scene(13, centre=(40, 40))
    rng = np.random.default_rng(14)
    square = cloudy_background(rng, 96, 128)
    square[50:80, 80:110] = [250, 120, 200]  # a pink square with a dark stripe
    square[60:64, 80:110] = [40, 20, 30]
    square_mask = np.zeros(square.shape[:2], dtype=bool)
    square_mask[50:80, 80:110] = True
    rings, pink = RFCH.train_shared(
        {"rings": ([rings_frame], [rings_mask]), "pink": ([square], [square_mask])}, **SMALL
    )
    assert rings.codebook_key == pink.codebook_key != model.codebook_key
    np.testing.assert_array_equal(rings.centres, pink.centres)
    assert rings.summary["codebook"]["objects"] == ["rings", "pink"]
    late = RFCH.train("late", [rings_frame], [rings_mask], codebook=rings, views="per_view")
    assert late.codebook_key == rings.codebook_key

    frame, _ = scene(15, centre=(90, 40))
    frame[10:40, 10:40] = square[50:80, 80:110]  # the pink square, top left
    together = Detector([rings, model, pink, late]).scores(frame)
    for index, alone in enumerate([rings, model, pink, late]):
        np.testing.assert_array_equal(together[index], alone.scores(frame))
    # Each object is still found where it is, on the shared codebook.
    for layer, xy in ((together[0], (90, 40)), (together[2], (25, 25))):
        best = tuple(int(v) for v in np.unravel_index(np.argmax(layer), layer.shape))
        assert best in box_containing(rings, frame.shape, xy)


def test_a_reused_codebook_takes_only_views(model: RFCH) -> None:
    frame, mask = scene(0)
    with pytest.raises(InputError, match="only views, view_similarity"):
        RFCH.train("x", [frame], [mask], codebook=model, n_clusters=4)
    with pytest.raises(InputError, match="at least one object"):
        RFCH.train_shared({})


# ------------------------------------------------------------------ the public shared path


def two_objects() -> dict[str, tuple[list[np.ndarray], list[np.ndarray]]]:
    """Two objects that look nothing alike: the striped disc, and a flat two-tone square."""
    rng = np.random.default_rng(5)
    rings, rings_mask = striped_object(40)
    square = np.zeros((40, 40, 3), np.uint8)
    square[:, :20] = (20, 180, 60)
    square[:, 20:] = (240, 230, 40)
    square_mask = np.ones((40, 40), bool)
    out: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {}
    shapes = {"rings": (rings, rings_mask), "square": (square, square_mask)}
    for name, (obj, mask) in shapes.items():
        views = [
            paste(cloudy_background(rng, 96, 128), obj, mask, (64, 48), angle_deg=a)
            for a in (0.0, 30.0, 60.0)
        ]
        out[name] = ([v[0] for v in views], [v[1] for v in views])
    return out


def test_detector_train_puts_every_object_on_one_codebook_that_survives_files(tmp_path) -> None:
    objects = two_objects()
    detector = Detector.train(objects, **SMALL)
    assert detector.names == ["rings", "square"] and detector.n_codebooks == 1
    frame, _ = scene(3)
    layers = detector.scores(frame)
    for index, model in enumerate(detector.models):
        np.testing.assert_array_equal(model.scores(frame), layers[index])  # alone = together
        model.save(tmp_path / f"{model.name}.npz")
    loaded = Detector([RFCH.load(tmp_path / f"{name}.npz") for name in reversed(detector.names)])
    assert loaded.n_codebooks == 1
    np.testing.assert_array_equal(loaded.scores(frame), layers[::-1])


def test_an_object_added_to_a_detector_shares_its_codebook_and_changes_no_score() -> None:
    objects = two_objects()
    rings = Detector.train({"rings": objects["rings"]}, **SMALL)
    frame, _ = scene(4)
    before = rings.scores(frame)
    both = rings.add("square", *objects["square"])
    assert both.names == ["rings", "square"] and both.n_codebooks == 1
    np.testing.assert_array_equal(both.scores(frame)[:1], before)
    with pytest.raises(InputError, match="already has an object named 'rings'"):
        both.add("rings", *objects["rings"])


@pytest.mark.parametrize(
    ("objects", "message"),
    [
        ({}, "at least one object"),
        ({"a": ([np.zeros((8, 8, 3), np.uint8)], [])}, "1 training images but 0 masks"),
    ],
)
def test_bad_input_to_detector_train_is_one_line(objects, message) -> None:
    with pytest.raises(InputError, match=message) as error:
        Detector.train(objects)
    assert "\n" not in str(error.value)


def test_clustered_views_find_two_objects_shown_as_one() -> None:
    """Two objects' views given as one object's: the rule finds the two, and no more."""
    objects = two_objects()
    images = objects["rings"][0] + objects["square"][0]
    masks = objects["rings"][1] + objects["square"][1]
    model = RFCH.train("both", images, masks, views="clustered", **SMALL)
    assert len(model.histograms) == 2
    assert model.summary["view_models"] == [0, 0, 0, 1, 1, 1]
    # The cap wins over the similarity rule: one model when only one is allowed.
    capped = RFCH.train("both", images, masks, views="clustered", max_view_models=1, **SMALL)
    assert len(capped.histograms) == 1
    # A patch on either object scores its own model: as well as a merged model would, or better.
    merged = RFCH.train("both", images, masks, **SMALL)
    for frame in (images[0], images[4]):
        assert model.scores(frame).max() >= merged.scores(frame).max() - 1e-6
    with pytest.raises(InputError, match="view_similarity must be in"):
        RFCH.train("both", images, masks, views="clustered", view_similarity=1.5)
