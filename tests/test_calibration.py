"""Score calibration: LLR tables from column scores, in model files, in fusion, in the twin."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

import twin.sim
from twin.app.config import ObjectConfig
from twin.app.detection import prepare_detector
from twin.app.montecarlo import DEFAULT_FUSION, _rule_for
from twin.cli import main
from twin.core.errors import InputError
from twin.core.fusion import RULES, Calibrated, make_rule
from twin.rfch import RFCH
from twin.rfch.calibration import ScoreCalibration, isotonic
from twin.rfch.synthetic import cloudy_background, paste, striped_object


def beta_columns(n_on: int, n_off: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Scores on the object ~ Beta(5, 2), off it ~ Beta(2, 5), with a few left-out columns."""
    rng = np.random.default_rng(seed)
    scores = np.concatenate([rng.beta(5, 2, n_on), rng.beta(2, 5, n_off), rng.random(50)])
    truth = np.concatenate([np.ones(n_on), np.zeros(n_off), -np.ones(50)]).astype(np.int8)
    return scores, truth


def beta_llr(s: np.ndarray) -> np.ndarray:
    """The exact LLR of ``beta_columns``: log(Beta(5,2) / Beta(2,5)) = 3 log(s / (1 - s))."""
    return 3.0 * np.log(s / (1.0 - s))


def test_llr_recovers_a_known_ratio_and_is_monotone():
    cal = ScoreCalibration.from_columns(*beta_columns(20000, 20000), bins=20)
    assert cal.positives == 20000 and cal.negatives == 20000  # left-out columns not counted
    table = cal.table()
    assert np.all(np.diff(table) >= 0.0)
    centres = 0.5 * (np.array(cal.edges[:-1]) + np.array(cal.edges[1:]))
    # Where the exact LLR is within the clip and both classes fill the bin, it is recovered
    # up to the bin width (the LLR changes by about 0.5 across a central bin).
    inner = (np.abs(beta_llr(centres)) < 3.0) & (centres > 0.15) & (centres < 0.85)
    np.testing.assert_allclose(table[inner], beta_llr(centres)[inner], atol=0.35)
    assert table[0] == -cal.max_abs_llr and table[-1] == cal.max_abs_llr  # clipped ends
    assert cal.auc == pytest.approx(0.960, abs=0.005)  # P(Beta(5,2) > Beta(2,5)) = 0.9600


def test_llr_of_scores_uses_their_bins_and_clamps_out_of_range_scores():
    cal = ScoreCalibration.from_columns(*beta_columns(2000, 2000), bins=10)
    table = cal.table()
    np.testing.assert_array_equal(cal.llr(np.array([0.05, 0.55, 1.0])), table[[0, 5, 9]])
    np.testing.assert_array_equal(cal.llr(np.array([[-0.5, 1.5]])), [[table[0], table[-1]]])


def test_isotonic_pools_adjacent_violators_by_weight():
    np.testing.assert_allclose(
        isotonic(np.array([1.0, 3.0, 2.0, 4.0]), np.ones(4)), [1, 2.5, 2.5, 4]
    )
    # A heavy bin holds its value; a light violator moves to it.
    np.testing.assert_allclose(isotonic(np.array([2.0, 1.0]), np.array([1.0, 9.0])), [1.1, 1.1])
    with pytest.raises(InputError):
        isotonic(np.array([1.0, 2.0]), np.array([1.0, 0.0]))


def test_sparse_and_empty_bins_are_neutral_not_the_class_imbalance():
    # 100 positives all in bin 3, 10000 negatives in bins 0-1; bin 2 has one of each; bins 4+
    # hold nothing. Add-one smoothing would give the empty bins log(10000/100) = +4.6.
    edges = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
    cal = ScoreCalibration(edges, (0, 0, 1, 99, 0), (5000, 4999, 1, 0, 0))
    table = cal.table()
    assert np.all(np.diff(table) >= 0.0)
    assert table[0] < -3.0 and table[3] > 3.0
    assert table[4] == table[3]  # no data above: the nearest measured bin's value
    # One column of each in bin 2: its raw ratio (1/100) / (1/10000) = 100 is shrunk to 0.
    assert 0.0 < table[2] < math.log(100.0) - 1.0


def test_json_round_trip_and_rule():
    cal = ScoreCalibration.from_columns(*beta_columns(500, 3000), bins=25)
    data = json.loads(json.dumps(cal.to_json()))
    again = ScoreCalibration.from_json(data)
    assert again == cal
    np.testing.assert_array_equal(again.table(), cal.table())
    rule = cal.rule()
    values = np.linspace(0.0, 1.0, 101)
    np.testing.assert_array_equal(rule.column_weights(values), cal.llr(values))
    assert rule.read(np.array([[1.5, -2.0]]), np.ones((1, 2))).tolist() == [[1.5, -2.0]]
    # The grid header stores rule name + params as JSON and rebuilds the rule from lists.
    header = json.loads(json.dumps({"name": rule.name, **rule.params()}))
    assert make_rule(header.pop("name"), **header) == rule
    summary = cal.summary()
    assert summary["positives"] == 500 and summary["negatives"] == 3000
    assert "500 positive and 3000 negative columns" in cal.describe()
    with pytest.raises(InputError, match="version"):
        ScoreCalibration.from_json({**data, "version": 99})


@pytest.mark.parametrize(
    ("edges", "counts_on", "counts_off", "match"),
    [
        ((0.0, 0.5, 1.0), (0, 0), (3, 4), "on and off"),
        ((0.0, 0.5, 1.0), (1, 0, 0), (3, 4), "one count per bin"),
        ((0.0, 0.5, 0.5), (1, 1), (3, 4), "increase"),
    ],
)
def test_bad_calibrations_are_one_line_errors(edges, counts_on, counts_off, match):
    with pytest.raises(InputError, match=match) as info:
        ScoreCalibration(edges, counts_on, counts_off)
    assert "\n" not in str(info.value)


def test_calibrated_rule_checks_its_table():
    with pytest.raises(InputError, match="B\\+1 edges"):
        Calibrated(edges=(0.0, 1.0), llr=(0.0, 1.0))
    with pytest.raises(InputError, match="increase"):
        Calibrated(edges=(0.0, 0.6, 0.4), llr=(0.0, 1.0))
    with pytest.raises(InputError, match="bad parameters"):
        make_rule("calibrated")


def test_the_monte_carlo_cannot_build_calibrated_and_says_so():
    assert "calibrated" in RULES and "calibrated" not in DEFAULT_FUSION
    with pytest.raises(InputError, match="cannot supply its parameter") as info:
        _rule_for("calibrated", {"p_fp": 0.1, "p_fn": 0.05, "min_observed": 1.0})
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------- models and files


def square_views(colour, offsets, seed=0):
    """Frames of a coloured square on grey clutter at each column offset (None: no square)."""
    rng = np.random.default_rng(seed)
    images, masks = [], []
    for offset in offsets:
        image = rng.integers(90, 140, (240, 320, 3), dtype=np.uint8)
        mask = np.zeros((240, 320), bool)
        if offset is not None:
            mask[80:140, offset : offset + 60] = True
            image[mask] = colour
        images.append(image)
        masks.append(mask)
    return np.array(images), np.array(masks)


def test_model_files_keep_the_calibration_and_old_files_load_without(tmp_path):
    images, masks = square_views((200, 30, 30), (40, 120))
    model = RFCH.train("red", list(images), list(masks), n_clusters=8)
    assert model.calibration is None
    model.save(tmp_path / "plain.npz")
    assert RFCH.load(tmp_path / "plain.npz").calibration is None
    cal = ScoreCalibration.from_columns(*beta_columns(300, 900))
    model.calibration = cal
    model.save(tmp_path / "calibrated.npz")
    loaded = RFCH.load(tmp_path / "calibrated.npz")
    assert loaded.calibration == cal
    np.testing.assert_array_equal(loaded.histograms, model.histograms)


@pytest.fixture
def counted_views(monkeypatch):
    """Training and calibration views replaced by synthetic ones; the calls are recorded."""
    calls: dict[str, list] = {"training": [], "calibration": []}

    def training_views(target=None, scene="training_stage", **_):
        calls["training"].append(target)
        return square_views((30, 40, 210), (40, 120))

    def calibration_views(scene="living_room", target=None, **recipe):
        calls["calibration"].append((scene, target, recipe))
        # Most frames without the square, as in the twin's calibration views.
        from twin.sim.training import CalibrationViews

        images, masks = square_views(
            (30, 40, 210), (None, 20, None, 200, None, None, 100, None), seed=1
        )
        n = len(images)
        # Taken from the room's middle looking round, a wall 3 m away in every frame.
        poses = np.stack([np.full(n, 2.25), np.full(n, 3.0), np.linspace(0, 6, n)], axis=1)
        depths = np.full((n, 240, 320), 3.0, np.float32)
        return CalibrationViews(images, masks, np.linspace(1.0, 4.0, n), depths, poses)

    monkeypatch.setattr(twin.sim, "training_views", training_views)
    monkeypatch.setattr(twin.sim.training, "calibration_views", calibration_views)
    return calls


def test_prepare_detector_calibrates_once_and_caches(tmp_path, counted_views):
    said: list[str] = []
    objects = [ObjectConfig("blue", None, "blue_box")]
    params = {"n_clusters": 8}
    plain = prepare_detector(objects, params, tmp_path, say=said.append)
    assert plain.models[0].calibration is None and counted_views["calibration"] == []
    detector = prepare_detector(
        objects, params, tmp_path, say=said.append, calibration_scene="living_room"
    )
    # The cached plain model was calibrated, not retrained.
    assert counted_views["training"] == ["blue_box"]
    ((scene, target, recipe),) = counted_views["calibration"]
    assert (scene, target) == ("living_room", "blue_box") and recipe["n_placements"] >= 1
    cal = detector.models[0].calibration
    assert cal is not None and cal.positives > 0 and cal.negatives > cal.positives
    assert cal.auc > 0.9  # the blue square is easy to tell from grey clutter
    assert any("calibration of 'blue'" in line and "AUC" in line for line in said)
    again = prepare_detector(
        objects, params, tmp_path, say=said.append, calibration_scene="living_room"
    )
    assert again.models[0].calibration == cal and len(counted_views["calibration"]) == 1
    # Another scene is another recipe: measured anew.
    prepare_detector(objects, params, tmp_path, say=said.append, calibration_scene="training_stage")
    assert len(counted_views["calibration"]) == 2


def write_frames(root: Path) -> tuple[Path, Path]:
    rng = np.random.default_rng(3)
    obj, mask = striped_object(30)
    frames, masks = root / "frames", root / "masks"
    frames.mkdir()
    masks.mkdir()
    for index in range(6):
        frame, frame_mask = paste(
            cloudy_background(rng, 72, 96), obj, mask, (16 + 12 * index, 36), 1.0, 20.0 * index
        )
        if index % 3 == 2:  # some frames without the object
            frame, frame_mask = cloudy_background(rng, 72, 96), np.zeros((72, 96), bool)
        cv2.imwrite(str(frames / f"f{index}.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(masks / f"f{index}.png"), frame_mask.astype(np.uint8) * 255)
    return frames, masks


def test_roc_prints_the_llr_table_and_stores_it_when_asked(tmp_path, capsys):
    rng = np.random.default_rng(0)
    obj, mask = striped_object(30)
    images, masks = [], []
    for angle in (0.0, 60.0):
        frame, frame_mask = paste(cloudy_background(rng, 72, 96), obj, mask, (48, 36), 1.0, angle)
        images.append(frame)
        masks.append(frame_mask)
    model_path = tmp_path / "rings.npz"
    RFCH.train("rings", images, masks, n_clusters=12, patch_size=24, stride=12).save(model_path)
    frames, frame_masks = write_frames(tmp_path)
    args = ["roc", "--model", str(model_path), "--images", str(frames), "--masks"]
    args += [str(frame_masks), "--out", str(tmp_path / "roc.png"), "--bins", "10"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "LLR" in printed and printed.count("\n[") == 10  # one table row per bin
    assert RFCH.load(model_path).calibration is None  # not stored unless asked
    assert main([*args, "--store"]) == 0
    stored = RFCH.load(model_path).calibration
    assert stored is not None and len(stored.on_counts) == 10
    assert f"{stored.positives} positive" in capsys.readouterr().out


def test_calibration_views_render_the_target_among_the_furniture():
    from twin.sim.training import calibration_views

    views = calibration_views(n_placements=1, views_per_placement=4, aimed_fraction=1.0)
    images, masks, distances = views.images, views.masks, views.distances
    assert images.shape == (4, 240, 320, 3) and images.dtype == np.uint8
    assert masks.shape == (4, 240, 320) and masks.dtype == bool
    assert distances.shape == (4,) and np.all(distances >= 0.6)  # min_distance from the target
    assert views.depths.shape == (4, 240, 320) and views.poses.shape == (4, 3)
    seen = masks.reshape(4, -1).sum(axis=1)
    assert seen.max() > 50  # views aimed at the box show it (some may have it hidden)
    # The box's pixels are nearer than the distance to its stand's far side
    box = masks[int(np.argmax(seen))]
    assert np.nanmedian(views.depths[int(np.argmax(seen))][box]) < distances.max() + 0.5
    again = calibration_views(n_placements=1, views_per_placement=4, aimed_fraction=1.0)
    np.testing.assert_array_equal(again.images, images)  # seeded: the same frames every time


def test_a_calibration_keeps_one_table_per_distance_band() -> None:
    rng = np.random.default_rng(7)
    # Near the object scores high; far it fades into the background.
    near = rng.beta(8, 6, 400)
    far = rng.beta(2, 12, 400)
    off = rng.beta(2, 14, 4000)
    scores = np.concatenate([near, far, off])
    truth = np.concatenate([np.ones(800, int), np.zeros(4000, int)])
    distances = np.concatenate([np.full(400, 1.0), np.full(400, 4.0), np.full(4000, 2.0)])
    cal = ScoreCalibration.from_columns(scores, truth, distances=distances, ranges=(2.0,))
    tables = cal.range_tables()
    assert tables.shape == (2, len(cal.on_counts))
    strong = cal.llr(np.array([0.6]))[0]
    high = int(np.searchsorted(cal.edges, 0.6, side="right") - 1)
    assert tables[0, high] > tables[1, high]  # a high score is stronger evidence near than far
    assert tables[0, high] >= strong - 1e-9  # and the pooled table lies between the bands
    assert cal.range_on_counts[0] != cal.range_on_counts[1]
    again = ScoreCalibration.from_json(json.loads(json.dumps(cal.to_json())))
    np.testing.assert_array_equal(again.range_tables(), tables)
    assert cal.rule().ranges == () and not cal.rule().range_llr  # pooled unless asked
    rule = cal.rule(by_distance=True)
    assert rule.ranges == (2.0,) and len(rule.range_llr) == 2
    assert "LLR by the object's distance" in cal.table_text()


def test_the_ranged_rule_mixes_visibility_into_the_likelihood_ratio() -> None:
    rule = make_rule(
        "calibrated", edges=(0.0, 0.5, 1.0), llr=(-1.0, 2.0), ranges=(2.0,),
        range_llr=((-2.0, 3.0), (-0.5, 1.0)),
    )  # fmt: skip
    values = np.array([0.9, 0.1])
    visibility = np.array([[1.0, 0.5, 0.0, 1.0], [1.0, 0.5, 0.0, 1.0]])
    step = 1.0  # bins centred at 0.5, 1.5 (near band), 2.5, 3.5 m (far band)
    w = rule.weight_profiles(values, visibility, step)
    assert w[0, 0] == pytest.approx(3.0) and w[1, 0] == pytest.approx(-2.0)
    assert w[0, 1] == pytest.approx(math.log(0.5 * math.exp(3.0) + 0.5))
    assert w[1, 1] == pytest.approx(math.log(0.5 * math.exp(-2.0) + 0.5))
    assert w[0, 2] == 0.0 and w[1, 2] == 0.0  # hidden: no evidence either way
    assert w[0, 3] == pytest.approx(1.0) and w[1, 3] == pytest.approx(-0.5)  # far band
    # The pooled table is what callers without distances get.
    np.testing.assert_array_equal(rule.column_weights(values), [2.0, -1.0])


def test_the_grid_fuses_the_ranged_rule_cell_by_cell() -> None:
    from twin.core.grid import AccumulatorGrid, GridSpec
    from twin.core.visibility import ColumnVisibility

    rule = make_rule(
        "calibrated", edges=(0.0, 0.5, 1.0), llr=(-1.0, 2.0), ranges=(1.0,),
        range_llr=((-2.0, 3.0), (-0.5, 1.0)),
    )  # fmt: skip
    spec = GridSpec(0.0, 0.0, 3.0, 2.0, 0.1)
    grid = AccumulatorGrid(["box"], spec, rule, 4)
    wedge = np.array([[-0.05, 0.05]])
    seen = ColumnVisibility(np.array([[1.0] * 20 + [0.5] * 20]), 0.05)  # half seen beyond 1 m
    grid.fuse_all((0.0, 1.0), wedge, {"box": np.array([0.9])}, None, seen)
    observed, layer = grid.observed("box"), grid.layer("box")
    near, far = (10, 7), (10, 15)  # cells on the axis at 0.75 m and 1.55 m
    assert layer[near] == pytest.approx(3.0 * observed[near])
    # observed counts the view's coverage; its visibility is in the weight already
    blind = AccumulatorGrid(["box"], spec, rule, 4)
    blind.fuse_all((0.0, 1.0), wedge, {"box": np.array([0.9])}, 2.0)
    assert observed[far] == pytest.approx(blind.observed("box")[far]) and observed[far] > 0
    assert layer[far] == pytest.approx(math.log(0.5 * math.e + 0.5) * observed[far])


def test_calibration_frames_pass_through_camera_effects_with_their_masks():
    """A camera that mirrors the frame: the images, depths and masks all come out mirrored,
    poses are the same as without it, and its rng is its own."""
    from twin.sim.training import calibration_views

    seen_rngs = []

    def mirror(image, depth, rng):
        seen_rngs.append(rng)
        rng.normal()  # a camera's noise must not move the next pose
        return np.ascontiguousarray(image[:, ::-1]), np.ascontiguousarray(depth[:, ::-1])

    recipe = {"n_placements": 1, "views_per_placement": 2, "aimed_fraction": 1.0, "seed": 1234}
    clean = calibration_views(**recipe)
    through = calibration_views(**recipe, effects=mirror)
    assert len(seen_rngs) == 2
    np.testing.assert_array_equal(through.poses, clean.poses)
    np.testing.assert_array_equal(through.images, clean.images[:, :, ::-1])
    np.testing.assert_array_equal(through.masks, clean.masks[:, :, ::-1])
    assert through.masks.any()
    np.testing.assert_array_equal(through.depths, clean.depths[:, :, ::-1])

    def shrink(image, depth, rng):
        return image[:100], depth[:100]

    with pytest.raises(InputError, match="camera effects returned"):
        calibration_views(**recipe, effects=shrink)
    with pytest.raises(InputError, match="effects must be callable"):
        calibration_views(**recipe, effects=42)


def test_prepare_detector_calibrates_through_effects_under_their_own_key(tmp_path, counted_views):
    from twin.app.detection import calibration_key

    objects = [ObjectConfig("blue", None, "blue_box")]
    params = {"n_clusters": 8}

    def camera(image, depth, rng):
        return image, depth

    prepare_detector(objects, params, tmp_path, say=lambda _: None, calibration_scene="living_room")
    prepare_detector(
        objects, params, tmp_path, say=lambda _: None, calibration_scene="living_room",
        calibration_effects=camera,
    )  # fmt: skip
    assert [c[2].get("effects") for c in counted_views["calibration"]] == [None, camera]
    # Clean frames keep the key they had before effects existed; a camera changes it.
    assert calibration_key("m", "x") == calibration_key("m", "x", None)
    assert calibration_key("m", "x", camera) != calibration_key("m", "x")


def test_calibration_frames_are_taken_at_the_surveys_tilt(tmp_path, counted_views):
    """A survey that looks 4 degrees down is calibrated on frames 4 degrees down, under its own
    key (a level calibration keeps the key it had)."""
    from twin.app.detection import calibration_key

    objects = [ObjectConfig("blue", None, "blue_box")]
    prepare_detector(
        objects, {"n_clusters": 8}, tmp_path, say=lambda _: None, calibration_scene="living_room",
        calibration_tilt=math.radians(-4.0),
    )  # fmt: skip
    assert counted_views["calibration"][0][2]["tilt"] == pytest.approx(math.radians(-4.0))
    assert calibration_key("m", "x", None, 0.0) == calibration_key("m", "x")
    assert calibration_key("m", "x", None, math.radians(-4.0)) != calibration_key("m", "x")


def test_calibration_views_look_down_at_the_tilt_from_the_same_poses():
    """The floor comes nearer in the bottom row of frames taken 20 degrees down."""
    from twin.sim.training import calibration_views

    recipe = {"n_placements": 1, "views_per_placement": 2, "aimed_fraction": 0.0}
    level = calibration_views(**recipe)
    down = calibration_views(**recipe, tilt=math.radians(-20.0))
    np.testing.assert_array_equal(level.poses, down.poses)
    assert np.nanmedian(down.depths[:, -1, :]) < 0.8 * np.nanmedian(level.depths[:, -1, :])


def test_objects_calibrated_in_parallel_processes_match_one_after_another():
    """``_calibrate_all`` in two spawned processes gives each object what calibrating it in
    this process gives (its own seeds, its camera reset), and says what each measured."""
    from twin.app.detection import _calibrate_all
    from twin.rfch import RFCH

    images, masks = square_views((200, 60, 40), (40, 120, 200))
    model = RFCH.train("box", list(images), list(masks), n_clusters=8)
    objects = [ObjectConfig("near", None, "rice_box"), ObjectConfig("far", None, "rice_box")]
    models = {"near": model, "far": model}
    recipe = {"n_placements": 1, "views_per_placement": 3, "aimed_fraction": 1.0,
              "min_cover": 0.25, "lighting": (0.8, 1.2)}  # fmt: skip
    said: list[str] = []
    apart = _calibrate_all(models, objects, "living_room", said.append, recipe=recipe, workers=2)
    alone = _calibrate_all(models, objects, "living_room", lambda _: None, recipe=recipe, workers=1)
    assert "2 processes" in said[0] and sum("calibration of" in line for line in said) == 2
    for obj, (model_a, room_a), (model_b, room_b) in zip(objects, apart, alone, strict=True):
        assert model_a.calibration == model_b.calibration
        assert room_a.objects == room_b.objects == (obj.name,) and len(room_a) == 3
        for view_a, view_b in zip(room_a.views, room_b.views, strict=True):
            np.testing.assert_array_equal(view_a.values[obj.name], view_b.values[obj.name])
