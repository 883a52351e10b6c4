"""The survey's detector: RFCH models loaded from files, or trained from the scene and cached.

An object given a ``model`` file is loaded from it. An object given only a scene ``body`` is
trained from the training stage's rendered views with exact segmentation masks; the trained
model is cached under a key that hashes everything it depends on (the MJCF models and scenes,
the detector parameters, the training views), so a changed scene or setting retrains and an
unchanged one loads in milliseconds.

With a ``calibration_scene``, each trained model also carries its score calibration
(``twin.rfch.calibration``): the trained detector scores head-camera views of that scene with the
object at random furniture tops (``twin.sim.training.calibration_views``, seeds from the reserved
``CALIBRATION_SEED`` range), and the histograms of its column scores on and off the object give
the LLR table of the ``calibrated`` fusion rule. The calibrated model is cached beside the plain
one under a key that adds the calibration recipe, so it is measured once (~5-15 s per object).
"""

from __future__ import annotations

import hashlib
import json
import math
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from twin import __version__
from twin.app.config import ObjectConfig
from twin.core.errors import InputError
from twin.resources import models_dir, scenes_dir

TRAINING_SCENE = "training_stage"
# How the training views are rendered (part of the model's cache key): camera drops (m above the
# object's centre) for ``twin.sim.training.training_views``, i.e. the elevations it is seen from:
# ``twin.sim.training.ELEVATION_DROPS`` (floor, table, counter, shelf). Against today's single
# 0.4 m drop, on 192 head-camera frames per object (benchmarks/rfch_rendered.py --views-table,
# docs/rfch.md): the frame's best column is on the object in 174 instead of 166 of 196 frames
# showing it, column AUC within +-0.01 per object.
TRAINING_RECIPE: dict[str, Any] = {"camera_drops": (0.9, 0.4, 0.0, -0.05)}
# How the calibration is measured: part of its cache key. 12 placements x 16 views give about
# 3500 columns of which about 130 lie on the rice box (measured in living_room).
CALIBRATION_RECIPE: dict[str, Any] = {
    "n_placements": 24,
    "views_per_placement": 16,
    "aimed_fraction": 0.5,  # enough positives for a table per distance band
    "min_cover": 0.25,
    # The survey's frames will not be lit as these were: each placement's lights vary.
    "lighting": (0.7, 1.3),
}
ROOM_OBJECT_HEIGHT = 0.2  # m: the room log's visibility, as [visibility]'s default


# Files under models/ and scenes/ that no frame is rendered from: the mission configs, the
# laser's map and the scripts that generate the assets (whose outputs are hashed). Editing a
# survey's stops must not retrain four detectors.
NOT_RENDERED = frozenset({".py", ".pyc", ".toml", ".yaml", ".pgm", ".md"})


def _tree_digest(folders: Sequence[Path]) -> str:
    digest = hashlib.sha256()
    for folder in folders:
        files = (p for p in folder.rglob("*") if p.is_file() and p.suffix not in NOT_RENDERED)
        for path in sorted(files):
            digest.update(str(path.relative_to(folder)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_key(obj: ObjectConfig, params: dict[str, Any], group: Sequence[str] = ()) -> str:
    """What a trained model depends on, hashed: assets, parameters, object, the objects it
    shares a codebook with, code version."""
    recipe = {
        "object": obj.name,
        "body": obj.body,
        "params": params,
        "version": __version__,
        "group": sorted(group),
        "assets": _tree_digest([models_dir(), scenes_dir()]),
        "training": TRAINING_RECIPE,
    }
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:16]


def prepare_detector(
    objects: Sequence[ObjectConfig],
    params: dict[str, Any],
    cache: Path,
    say: Callable[[str], None] = print,
    calibration_scene: str | None = None,
    calibration_effects: Any = None,
    calibration_tilt: float = 0.0,
):
    """A ``twin.rfch.Detector`` over ``objects``: models from files, and the scene's objects
    trained together on one shared codebook (``Detector.train``: each extra object costs a few
    % of the first, not 55-90 %: docs/rfch.md), cached as a group.

    ``calibration_scene`` (a scene name, e.g. the survey's): the scene-trained models get a
    score calibration measured there (``model.calibration``; module docstring). None: no
    calibration is measured; model files keep whatever calibration they carry.
    ``calibration_effects``: the calibration frames pass through this camera
    (``effects(image, depth, rng) -> (image, depth)`` or a ``CameraEffects``; see
    ``twin.sim.training.calibration_views``), so the calibration sees the frames the survey
    sees; part of the calibration's cache key (``effects_tag``). None: clean frames.
    ``calibration_tilt`` (radians, up positive): the head's in the calibration frames, the
    survey's (a room seen 4 degrees down is not the room seen level: on the apartment's
    development runs the desk by the bedroom door outscored the rice box in 5 of 16 runs
    with a level calibration, in 3 with one at the survey's tilt).
    """
    detector, _ = _prepared(
        objects, params, cache, say, calibration_scene, calibration_effects, calibration_tilt
    )
    return detector


def _prepared(
    objects: Sequence[ObjectConfig],
    params: dict[str, Any],
    cache: Path,
    say: Callable[[str], None],
    calibration_scene: str | None,
    calibration_effects: Any,
    calibration_tilt: float = 0.0,
) -> tuple[Any, dict[str, Any]]:
    """``prepare_detector``'s detector and the room logs its calibration measured (or loaded
    with it), from one computation of the cache keys: keys computed again later could name
    other files if the scene's assets changed meanwhile, and the mission would silently lose
    its room baseline."""
    from twin.app.view_log import ViewLog
    from twin.rfch import RFCH, Detector, RFCHParams

    try:
        RFCHParams(**params)
    except TypeError as exc:
        raise InputError(f"detector: {exc}; see twin.rfch.RFCHParams for the keys") from None
    from_scene = [obj for obj in objects if obj.model is None]
    group = [obj.name for obj in from_scene]
    paths = {
        obj.name: cache / f"rfch_{obj.name}_{cache_key(obj, params, group)}.npz"
        for obj in from_scene
    }
    # The calibrated model sits beside the plain one: a new calibration recipe re-measures the
    # calibration only, not the training.
    calibrated = {
        name: _calibrated_path(path, calibration_scene, calibration_effects, calibration_tilt)
        for name, path in paths.items()
        if calibration_scene is not None
    }
    ready = all(p.is_file() and room_log_path(p).is_file() for p in calibrated.values())
    rooms: dict[str, Any] = {}
    if calibration_scene is not None and ready:
        trained = {name: RFCH.load(path) for name, path in calibrated.items()}
        rooms = {name: ViewLog.load(room_log_path(path)) for name, path in calibrated.items()}
    else:
        if all(path.is_file() for path in paths.values()):
            trained = {name: RFCH.load(path) for name, path in paths.items()}
        else:
            trained = _train_from_scene(from_scene, params, say, cache)
            for name, model in trained.items():
                model.save(paths[name])
        if calibration_scene is not None:
            measured = _calibrate_all(
                trained, from_scene, calibration_scene, say, calibration_effects, calibration_tilt
            )
            for obj, (model, room) in zip(from_scene, measured, strict=True):
                # The room's log first: a calibrated model without one is calibrated again.
                room.save(room_log_path(calibrated[obj.name]))
                model.save(calibrated[obj.name])
                trained[obj.name] = model
                rooms[obj.name] = room
    models = [
        RFCH.load(obj.model) if obj.model is not None else trained[obj.name] for obj in objects
    ]
    detector = Detector(models)
    # The first call loads the compiled kernels (~0.3 s): pay it here, not in the first view.
    probe = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    detector.scores(probe)
    return detector, rooms


def effects_tag(effects: Any) -> str | None:
    """What identifies a camera-effects chain in a cache key: its settings' repr (a
    ``CameraEffects`` or the object of a bound ``apply``), else the callable's qualified name;
    None for clean frames."""
    if effects is None:
        return None
    owner = effects if hasattr(effects, "apply") else getattr(effects, "__self__", None)
    settings = getattr(owner, "settings", None)
    if settings is not None:
        return f"{type(owner).__qualname__}:{settings!r}"
    return f"{getattr(effects, '__module__', '')}.{getattr(effects, '__qualname__', repr(effects))}"


def _calibrated_path(
    model_path: Path, scene: str | None, effects: Any = None, tilt: float = 0.0
) -> Path:
    """Where the calibrated model of ``model_path`` is kept (beside it)."""
    key = calibration_key(model_path.stem, scene, effects, tilt)
    return model_path.with_name(f"{model_path.stem}_cal{key}.npz")


def mission_detector(config: Any, say: Callable[[str], None] = print) -> tuple[Any, dict[str, Any]]:
    """The detector a mission config asks for, calibrated on its scene through its camera, and
    the room logs measured with it, as every mission, batch and benchmark uses them."""
    effects = calibration_camera(config)
    return _prepared(
        config.objects, config.detector, config.cache, say, str(config.scene), effects,
        config.mission.tilt,
    )  # fmt: skip


def calibration_camera(config: Any) -> Any:
    """The camera a mission's score calibration frames pass through: the twin's camera as the
    config sets it up (None for an ideal one), so the calibration and the room's look are
    measured on the frames the mission will see. A real camera's calibration is still measured
    in the twin, through the twin's default model of the VC-C4: the closest stand-in it has."""
    from twin.app.device_types import SimCameraOptions
    from twin.app.factory import sim_camera_parts

    camera = config.devices["camera"]
    options = camera.options if camera.type == "sim" else SimCameraOptions()
    if options.effects == "ideal":
        return None
    # The sim robot is only needed for an ideal camera's field of view, ruled out above.
    return sim_camera_parts(options, None)[1]


def calibration_key(
    model_key: str, scene: str | None, effects: Any = None, tilt: float = 0.0
) -> str:
    """What a calibration depends on beyond its model, hashed: the scene, the recipe, the
    calibration format, the reserved seed, the camera effects if any (``effects_tag``; clean
    frames leave the key as it was before effects existed) and the head's tilt if not level
    (likewise). (The scene's assets and the code version are in ``model_key`` already.)"""
    from twin.rfch.calibration import CALIBRATION_VERSION, DEFAULT_RANGES
    from twin.sim.training import CALIBRATION_SEED

    recipe = {
        "model": model_key,
        "scene": scene,
        "recipe": CALIBRATION_RECIPE,
        "format": CALIBRATION_VERSION,
        "seed": CALIBRATION_SEED,
        "ranges": DEFAULT_RANGES,
        # 2: a target the scene gives kinds of support stands on those (calibration_views)
        "placement": 2,
        # the room log's visibility sees nothing past walls and tall furniture (TallMap)
        "visibility": "walls",
    }
    if effects is not None:
        recipe["effects"] = effects_tag(effects)
    if tilt != 0.0:
        recipe["tilt_deg"] = round(math.degrees(tilt), 3)
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:12]


def room_log_path(calibrated_model: Path) -> Path:
    """Where the room's look without the object (``twin.app.room``) is kept: beside the
    calibrated model it was measured with."""
    return calibrated_model.with_name(f"{calibrated_model.stem}_room.npz")


def _calibrate_all(
    models: dict[str, Any],
    objects: Sequence[ObjectConfig],
    scene: str,
    say: Callable[[str], None],
    effects: Any = None,
    tilt: float = 0.0,
    recipe: dict[str, Any] | None = None,
    workers: int | None = None,
) -> list[tuple[Any, Any]]:
    """``_calibrate`` for each of ``objects``, in ``workers`` processes (default: as many as
    there are objects and cores): each object's frames are rendered and scored on their own (a
    cold apartment survey spent 178 s calibrating four objects one after another). The results
    are the same either way: every object's frames come from its own seeds and a camera reset
    for it."""
    workers = min(len(objects), workers or os.cpu_count() or 1)
    if workers < 2:
        return [_calibrate(models[o.name], o, scene, say, effects, tilt, recipe) for o in objects]
    names = ", ".join(repr(o.name) for o in objects)
    say(f"calibrating the RFCH models of {names} on {scene} views ({workers} processes)")
    # spawn, not fork: a forked child would share the parent's MuJoCo and EGL state.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        jobs = [
            pool.submit(_calibrate_telling, models[o.name], o, scene, effects, tilt, recipe)
            for o in objects
        ]
        out = []
        for job in jobs:
            model, room, said = job.result()
            for line in said[1:]:  # the first, "calibrating ...", was said above for all
                say(line)
            out.append((model, room))
    return out


def _calibrate_telling(
    model: Any,
    obj: ObjectConfig,
    scene: str,
    effects: Any,
    tilt: float,
    recipe: dict[str, Any] | None,
) -> tuple[Any, Any, list[str]]:
    """``_calibrate`` in a worker process, with what it would have said."""
    said: list[str] = []
    calibrated, room = _calibrate(model, obj, scene, said.append, effects, tilt, recipe)
    return calibrated, room, said


def _calibrate(
    model: Any,
    obj: ObjectConfig,
    scene: str,
    say: Callable[[str], None],
    effects: Any = None,
    tilt: float = 0.0,
    recipe: dict[str, Any] | None = None,
) -> tuple[Any, Any]:
    """``model`` with its score calibration measured on ``scene`` (module docstring), and the
    room's look without the object from the same frames (``twin.app.room``); the frames pass
    through the camera ``effects`` if given, with the head at ``tilt`` (``calibration_views``),
    by ``recipe`` (default ``CALIBRATION_RECIPE``)."""
    from dataclasses import replace

    from twin.app.room import room_log
    from twin.rfch import Detector
    from twin.rfch.calibration import ScoreCalibration
    from twin.rfch.roc import column_truth
    from twin.sim import World, training
    from twin.sim.robot import PAPER_CAMERA
    from twin.sim.supports import support_levels, tall_map

    recipe = dict(CALIBRATION_RECIPE if recipe is None else recipe)
    min_cover = recipe.pop("min_cover")
    say(f"calibrating the RFCH model of {obj.name!r} on {scene} views")
    if effects is not None and hasattr(effects, "reset"):
        effects.reset()  # the camera's exposure and white balance start afresh, as in a survey
    views = training.calibration_views(
        scene=scene, target=obj.body, effects=effects, tilt=tilt, **recipe
    )
    detector = Detector([model])
    scores = [detector.scores(image)[0].max(axis=0) for image in views.images]
    truth = [column_truth(mask, model.params.grid, min_cover) for mask in views.masks]
    # Every column of a view sees the object (if at all) at the view's distance.
    distances = [np.full(len(t), d) for t, d in zip(truth, views.distances, strict=True)]
    calibration = ScoreCalibration.from_columns(
        np.concatenate(scores),
        np.concatenate(truth),
        min_cover=min_cover,
        distances=np.concatenate(distances),
    )
    say(f"calibration of {obj.name!r}: {calibration.describe()}")
    world = World(scene)
    x0, y0, x1, y1 = world.room_bounds()
    room = room_log(
        obj.name, views.poses, views.depths, scores, truth, PAPER_CAMERA,
        model.params.grid.column_spans(PAPER_CAMERA.width), support_levels(world),
        ROOM_OBJECT_HEIGHT, math.hypot(x1 - x0, y1 - y0), tall=tall_map(world), tilt=tilt,
    )  # fmt: skip
    return replace(model, calibration=calibration), room


def _train_from_scene(
    objects: Sequence[ObjectConfig], params: dict[str, Any], say: Callable[[str], None], cache: Path
) -> dict[str, Any]:
    """Train ``objects`` from the training stage's views (``TRAINING_RECIPE``) with exact
    masks, all on one shared codebook."""
    from twin.rfch import Detector
    from twin.sim import training_views

    names = ", ".join(repr(obj.name) for obj in objects)
    say(f"training the RFCH model of {names} from the training stage (cached in {cache})")
    drops = TRAINING_RECIPE["camera_drops"]
    views = {
        obj.name: training_views(target=obj.body, scene=TRAINING_SCENE, camera_drop=drops)
        for obj in objects
    }
    detector = Detector.train({n: (list(i), list(m)) for n, (i, m) in views.items()}, **params)
    return {model.name: model for model in detector.models}
