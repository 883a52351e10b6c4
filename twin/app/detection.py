"""The survey's detector: RFCH models loaded from files, or trained from the scene and cached.

An object given a ``model`` file is loaded from it. An object given only a scene ``body`` is
trained from the training stage's rendered views with exact segmentation masks; the trained
model is cached under a key that hashes everything it depends on (the MJCF models and scenes,
the detector parameters, the training views), so a changed scene or setting retrains and an
unchanged one loads in milliseconds.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from twin import __version__
from twin.app.config import ObjectConfig
from twin.core.errors import InputError
from twin.resources import models_dir, scenes_dir

TRAINING_SCENE = "training_stage"


def _tree_digest(folders: Sequence[Path]) -> str:
    digest = hashlib.sha256()
    for folder in folders:
        for path in sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix != ".pyc"):
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
    }
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:16]


def prepare_detector(
    objects: Sequence[ObjectConfig],
    params: dict[str, Any],
    cache: Path,
    say: Callable[[str], None] = print,
):
    """A ``twin.rfch.Detector`` over ``objects``: models from files, and the scene's objects
    trained together on one shared codebook (so each extra object costs about 1 % of the
    first, not 55-90 %: docs/rfch.md), cached as a group."""
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
    if all(path.is_file() for path in paths.values()):
        trained = {name: RFCH.load(path) for name, path in paths.items()}
    else:
        trained = _train_from_scene(from_scene, params, say, cache)
        for name, model in trained.items():
            model.save(paths[name])
    models = [
        RFCH.load(obj.model) if obj.model is not None else trained[obj.name] for obj in objects
    ]
    detector = Detector(models)
    # The first call loads the compiled kernels (~0.3 s): pay it here, not in the first view.
    probe = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    detector.scores(probe)
    return detector


def _train_from_scene(
    objects: Sequence[ObjectConfig], params: dict[str, Any], say: Callable[[str], None], cache: Path
) -> dict[str, Any]:
    """Train ``objects`` from the training stage's views with exact masks: one object alone,
    several on one shared codebook."""
    from twin.rfch import RFCH
    from twin.sim import training_views

    names = ", ".join(repr(obj.name) for obj in objects)
    say(f"training the RFCH model of {names} from the training stage (cached in {cache})")
    views = {obj.name: training_views(target=obj.body, scene=TRAINING_SCENE) for obj in objects}
    if len(views) == 1:
        ((name, (images, masks)),) = views.items()
        return {name: RFCH.train(name, list(images), list(masks), **params)}
    shared = RFCH.train_shared({n: (list(i), list(m)) for n, (i, m) in views.items()}, **params)
    return {model.name: model for model in shared}
