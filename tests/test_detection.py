"""The survey's detector: scene objects trained together on one codebook, and cached."""

import numpy as np
import pytest

import twin.sim
from twin.app.config import ObjectConfig
from twin.app.detection import prepare_detector
from twin.rfch import RFCH

COLOURS = {"red_box": (200, 30, 30), "blue_box": (30, 40, 210)}


def synthetic_views(target, scene):
    """Two views of a coloured square on grey clutter, with exact masks."""
    rng = np.random.default_rng(len(target))
    images, masks = [], []
    for offset in (40, 120):
        image = rng.integers(90, 140, (240, 320, 3), dtype=np.uint8)
        mask = np.zeros((240, 320), bool)
        mask[80:140, offset : offset + 60] = True
        image[mask] = COLOURS[target]
        images.append(image)
        masks.append(mask)
    return np.array(images), np.array(masks)


@pytest.fixture
def counted_training(monkeypatch):
    calls = []

    def training_views(target=None, scene="training_stage", **_):
        calls.append(target)
        return synthetic_views(target, scene)

    monkeypatch.setattr(twin.sim, "training_views", training_views)
    return calls


PARAMS = {"n_clusters": 8}


def test_scene_objects_share_one_codebook_and_are_cached(tmp_path, counted_training):
    objects = [ObjectConfig(name, None, name) for name in COLOURS]
    detector = prepare_detector(objects, PARAMS, tmp_path, say=lambda _: None)
    assert detector.names == list(COLOURS)
    assert len({model.codebook_key for model in detector.models}) == 1
    assert sorted(counted_training) == sorted(COLOURS)
    again = prepare_detector(objects, PARAMS, tmp_path, say=lambda _: None)
    assert sorted(counted_training) == sorted(COLOURS)  # loaded from the cache: no training
    frame, _ = synthetic_views("blue_box", "")
    np.testing.assert_array_equal(again.scores(frame[0]), detector.scores(frame[0]))
    scores = detector.scores(frame[0])
    columns = scores.max(axis=1)
    blue = detector.names.index("blue_box")
    assert columns[blue].max() > columns[1 - blue].max()


def test_model_files_and_a_lone_scene_object_mix(tmp_path, counted_training):
    images, masks = synthetic_views("red_box", "")
    path = tmp_path / "red.npz"
    RFCH.train("red_box", list(images), list(masks), **PARAMS).save(path)
    objects = [ObjectConfig("red_box", path, None), ObjectConfig("blue_box", None, "blue_box")]
    detector = prepare_detector(objects, PARAMS, tmp_path / "cache", say=lambda _: None)
    assert detector.names == ["red_box", "blue_box"]
    assert counted_training == ["blue_box"]


def test_scene_objects_are_trained_from_the_recipes_elevations(tmp_path, monkeypatch):
    from twin.app.detection import TRAINING_RECIPE

    drops = []

    def training_views(target=None, scene="training_stage", camera_drop=0.4, **_):
        drops.append(camera_drop)
        return synthetic_views(target, scene)

    monkeypatch.setattr(twin.sim, "training_views", training_views)
    prepare_detector([ObjectConfig("red_box", None, "red_box")], PARAMS, tmp_path, lambda _: None)
    assert drops == [TRAINING_RECIPE["camera_drops"]]
    from twin.sim.training import ELEVATION_DROPS

    assert TRAINING_RECIPE["camera_drops"] == ELEVATION_DROPS  # the floor, table, counter, shelf


def test_training_views_from_several_elevations():
    from twin.core.errors import InputError
    from twin.sim.training import training_views

    images, masks = training_views(distances=(1.0,), angles=(0.0, 1.0), camera_drop=(0.9, 0.0))
    assert images.shape == (4, 240, 320, 3) and masks.shape == (4, 240, 320)
    # The same azimuth from above and level: the box is centred in both, its outline differs.
    above, level = masks[0], masks[2]
    assert above[120, 160] and level[120, 160]
    assert (above != level).mean() > 0.01
    with pytest.raises(InputError, match="camera_drop"):
        training_views(distances=(1.0,), angles=(0.0,), camera_drop=(0.4, float("nan")))


def test_the_cache_key_follows_what_frames_are_rendered_from_not_the_mission_configs(
    tmp_path, monkeypatch
):
    """A survey's stops (a .toml), the laser's map and the asset scripts change no frame: the
    detectors stay cached; an MJCF or a texture changes the key."""
    import twin.app.detection as detection

    models, scenes = tmp_path / "models", tmp_path / "scenes"
    (models / "textures").mkdir(parents=True)
    scenes.mkdir()
    (scenes / "room.xml").write_text("<mujoco/>")
    (scenes / "room.toml").write_text("[mission]\n")
    (models / "textures" / "box.png").write_bytes(b"png")
    monkeypatch.setattr(detection, "models_dir", lambda: models)
    monkeypatch.setattr(detection, "scenes_dir", lambda: scenes)
    obj = ObjectConfig("box", None, "box")

    def key() -> str:
        return detection.cache_key(obj, {"k": 1})

    first = key()
    (scenes / "room.toml").write_text("[mission]\nstops = [[1, 2]]\n")
    (models / "make_room.py").write_text("print()\n")
    (scenes / "room_map.pgm").write_bytes(b"P5")
    assert key() == first
    (models / "textures" / "box.png").write_bytes(b"png2")
    assert key() != first
