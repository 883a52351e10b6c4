"""Where a view's depth comes from: the frame's own, the scene rendered at the pose, the map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.app.config import load_config
from twin.app.visibility_models import (
    DepthVisibility,
    MapDepthSource,
    ModelDepthSource,
    build_visibility,
    frame_depth,
)
from twin.core.devices import View
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel, Pose2D
from twin.rfch.params import PatchGrid
from twin.sim import World

CAMERA = CameraModel()
SPANS = PatchGrid().column_spans(CAMERA.width)
# From the living room's middle, looking at the sofa and the coffee table (+x is east).
POSE = Pose2D(2.5, 3.3, math.radians(150.0))


def _view(depth: np.ndarray | None = None) -> View:
    image = np.zeros((CAMERA.height, CAMERA.width, 3), np.uint8)
    return View(image, POSE, 0.0, 0.0, 0.0, None, depth)


@pytest.fixture(scope="module")
def world() -> World:
    return World("living_room")


def test_the_twin_uses_the_frames_depth_and_says_so_when_there_is_none(world):
    visibility = build_visibility(load_config(None), world, CAMERA)
    assert isinstance(visibility, DepthVisibility) and visibility.depth_of is frame_depth
    with pytest.raises(
        TwinError, match=r'gave no depth with its frame; set visibility\.source to "model"'
    ):
        visibility.profiles(_view(), CAMERA, SPANS)


def test_the_real_robot_renders_the_scene_at_its_pose(world):
    config = load_config("peoplebot_real")
    visibility = build_visibility(config, world, CAMERA)
    assert isinstance(visibility.depth_of, ModelDepthSource)
    profiles = visibility.profiles(_view(), CAMERA, SPANS).profiles
    assert profiles.shape[0] == len(SPANS)
    # The sofa and the walls hide much, the room's open middle little.
    assert (profiles == 0).mean() > 0.2 and (profiles == 1).mean() > 0.01
    # The sought object is not part of the room's model: the rendered depth passes through it.
    depth = visibility.depth_of(_view(), CAMERA, 1.0)
    assert depth.shape == (CAMERA.height, CAMERA.width) and np.isfinite(depth).mean() > 0.9


def test_with_only_a_map_its_obstacles_are_walls(world):
    from twin.sim.scene_map import scene_map

    config = load_config(None, overrides=["visibility.source=map", "visibility.supports=anywhere"])
    with pytest.raises(TwinError, match="needs the localization map"):
        build_visibility(config, world, CAMERA)
    visibility = build_visibility(config, world, CAMERA, scene_map(world))
    assert isinstance(visibility.depth_of, MapDepthSource)
    from_map = visibility.profiles(_view(), CAMERA, SPANS).profiles
    real = load_config("peoplebot_real", overrides=["visibility.supports=anywhere"])
    from_model = build_visibility(real, world, CAMERA).profiles(_view(), CAMERA, SPANS).profiles
    # A laser slice at 0.3 m makes the sofa and the tables walls up to 2 m: the map hides more.
    assert from_map.sum() < 0.9 * from_model.sum()


def test_none_means_the_papers_every_cell_is_seen(world):
    assert (
        build_visibility(load_config(None, overrides=["visibility.source=none"]), world, CAMERA)
        is None
    )


def test_a_large_object_does_not_hide_its_own_centre(world):
    """The depth test lets a point stand the object's near side plus half a cell behind what
    its pixel hits: before a wall 2.75 m away, a crate of radius 0.25 m counts as seen 0.1 m
    farther out than the default 0.15 m allows (its centre behind its own near side)."""
    depth = np.full((CAMERA.height, CAMERA.width), 2.75)

    def farthest_seen(radius: float) -> float:
        config = load_config(None, overrides=[f"visibility.object_radius_m={radius}"])
        visibility = build_visibility(config, world, CAMERA)
        assert visibility.tolerance == pytest.approx(radius + 0.05)
        profiles = visibility.profiles(_view(depth), CAMERA, SPANS)
        middle = profiles.profiles[len(SPANS) // 2]
        return (np.flatnonzero(middle > 0).max() + 1) * profiles.step

    near, far = farthest_seen(0.15), farthest_seen(0.25)
    assert 2.6 < near < 2.95 and far - near == pytest.approx(0.1, abs=0.051)
