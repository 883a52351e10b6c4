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
from twin.config import ObjectConfig
from twin.errors import InputError
from twin.resources import models_dir, scenes_dir

TRAINING_SCENE = "training_stage"


def _tree_digest(folders: Sequence[Path]) -> str:
    digest = hashlib.sha256()
    for folder in folders:
        for path in sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix != ".pyc"):
            digest.update(str(path.relative_to(folder)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_key(obj: ObjectConfig, params: dict[str, Any]) -> str:
    """What a trained model depends on, hashed: assets, parameters, object, code version."""
    recipe = {
        "object": obj.name,
        "body": obj.body,
        "params": params,
        "version": __version__,
        "assets": _tree_digest([models_dir(), scenes_dir()]),
    }
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode()).hexdigest()[:16]


def prepare_detector(
    objects: Sequence[ObjectConfig],
    params: dict[str, Any],
    cache: Path,
    say: Callable[[str], None] = print,
):
    """A ``twin.rfch.Detector`` over ``objects`` (loading, or training and caching, models)."""
    from twin.rfch import RFCH, Detector, RFCHParams

    try:
        RFCHParams(**params)
    except TypeError as exc:
        raise InputError(f"detector: {exc}; see twin.rfch.RFCHParams for the keys") from None
    models = []
    for obj in objects:
        if obj.model is not None:
            models.append(RFCH.load(obj.model))
            continue
        path = cache / f"rfch_{obj.name}_{cache_key(obj, params)}.npz"
        if path.is_file():
            models.append(RFCH.load(path))
            continue
        from twin.sim import training_views

        say(f"training the RFCH model of {obj.name!r} from the training stage (cached in {path})")
        images, masks = training_views(target=obj.body, scene=TRAINING_SCENE)
        model = RFCH.train(obj.name, list(images), list(masks), **params)
        model.save(path)
        models.append(model)
    detector = Detector(models)
    # The first call loads the compiled kernels (~0.3 s): pay it here, not in the first view.
    probe = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    detector.scores(probe)
    return detector
