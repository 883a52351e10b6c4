"""Placing an object on the visible surfaces: resting, never inside anything, fitting under the
shelf above, and in view from somewhere a robot could stand."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from twin.core.errors import InputError
from twin.sim.placement import (
    HEAD_MARGIN,
    SUPPORT_KINDS,
    place_on_surface,
    place_targets,
    random_surface_pose,
    visible_fraction,
)
from twin.sim.world import World

BOX = "rice_box"
SCENE_GROUPS = np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8)  # the scene's geoms, not the robot's


@pytest.fixture(scope="module")
def world() -> World:
    return World("living_room")


def _box_geom(world: World) -> int:
    return mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, BOX)


def _face_points(world: World, z_local: float, inset: float = 0.005) -> np.ndarray:
    """3 x 3 points on the box's bottom (z_local = -1) or top (+1) face, inset from its edges."""
    geom = _box_geom(world)
    half = world.model.geom_size[geom]
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    out = []
    for u in (-1, 0, 1):
        for v in (-1, 0, 1):
            local = np.array([u * (half[0] - inset), v * (half[1] - inset), z_local * half[2]])
            out.append(world.data.geom_xpos[geom] + rot @ local)
    return np.array(out)


def _cast(world: World, start: np.ndarray, direction: tuple[float, float, float]) -> float:
    found = np.zeros(1, dtype=np.int32)
    body = world.body_id(BOX)
    vec = np.array(direction, dtype=float)
    return mujoco.mj_ray(world.model, world.data, start, vec, SCENE_GROUPS, 1, body, found)


def _deepest_overlap(world: World) -> tuple[float, str]:
    """Most negative signed distance (m) from the box to any geom not the robot's."""
    box = _box_geom(world)
    worst, name = math.inf, ""
    for geom in range(world.model.ngeom):
        body = int(world.model.geom_bodyid[geom])
        if geom == box or world.model.body_weldid[body] != 0:
            continue
        dist = mujoco.mj_geomDistance(world.model, world.data, box, geom, 0.05, None)
        if dist < worst:
            worst, name = dist, world.model.geom(geom).name
    return worst, name


def _seen_from_somewhere(world: World) -> float:
    """Best visible fraction from free floor spots 1-2.5 m around the box, camera at 1.0 m
    (free: ``World.check_free`` with 0.25 m, an independent test of the placement's own)."""
    x, y, _ = world.body_position(BOX)
    best = 0.0
    for radius in (1.0, 1.5, 2.0, 2.5):
        for k in range(32):
            angle = 2 * math.pi * k / 32
            cx, cy = x + radius * math.cos(angle), y + radius * math.sin(angle)
            fraction = visible_fraction(world, BOX, (cx, cy, 1.0))
            if fraction <= best:
                continue
            try:
                world.check_free(cx, cy, 0.25, "camera")
            except InputError:
                continue
            best = fraction
            if best >= 0.9:
                return best
    return best


def test_random_placements_rest_on_a_surface_inside_nothing_and_in_view(world: World) -> None:
    supports = set()
    for seed in range(40):
        pose = random_surface_pose(world, BOX, np.random.default_rng(seed))
        where = f"seed {seed} at {pose}"
        depth, other = _deepest_overlap(world)
        assert depth >= -0.005, f"{where}: {-depth:.3f} m inside {other}"
        # resting: straight under every part of its bottom, the visible top within 1 cm
        below = [
            _cast(world, np.add(p, (0, 0, 0.001)), (0, 0, -1)) for p in _face_points(world, -1)
        ]
        assert all(0 <= d <= 0.011 for d in below), f"{where}: gaps below {below}"
        # head room: nothing over its top closer than the margin (a shelf above)
        above = [
            _cast(world, np.subtract(p, (0, 0, 0.001)), (0, 0, 1)) for p in _face_points(world, 1)
        ]
        assert all(d < 0 or d >= HEAD_MARGIN for d in above), f"{where}: above {above}"
        assert 0.3 <= world.body_position(BOX)[2] - 0.15 <= 1.3
        assert _seen_from_somewhere(world) >= 0.9, where
        supports.add(world.support_of(BOX))
    assert len(supports) >= 3  # generality: not one piece of furniture every time


def test_a_seed_gives_the_same_spot(world: World) -> None:
    first = random_surface_pose(world, BOX, np.random.default_rng(7))
    random_surface_pose(world, BOX, np.random.default_rng(8))
    again = random_surface_pose(world, BOX, np.random.default_rng(7))
    assert again == first


def test_the_box_stands_on_the_sofa_cushion_not_inside_it(world: World) -> None:
    """The old bug: the seat frame (0.40 m) was the surface, so the box stood 12 cm deep in the
    visual-only cushion (top 0.52 m) and showed 75 % of itself."""
    pose = place_on_surface(world, BOX, 0.6, 4.3, 0.0)
    assert (pose.x, pose.y) == pytest.approx((0.6, 4.3))
    assert world.body_position(BOX)[2] - 0.15 == pytest.approx(0.52, abs=1e-6)
    assert _deepest_overlap(world)[0] >= -0.005
    # World.place_static_body now also stands it on what is seen
    world.place_static_body(BOX, 0.6, 4.3, 0.0)
    assert world.body_position(BOX)[2] - 0.15 == pytest.approx(0.52, abs=1e-6)


def test_visible_fraction_sees_a_box_sunk_in_the_cushion_only_in_part(world: World) -> None:
    camera = (1.6, 4.3, 1.0)
    place_on_surface(world, BOX, 0.6, 4.3, 0.0)
    assert visible_fraction(world, BOX, camera) == pytest.approx(1.0)
    world.model.body_pos[world.body_id(BOX)] = (0.6, 4.3, 0.40 + 0.15)  # on the seat frame
    world.forward()
    assert 0.5 < visible_fraction(world, BOX, camera) < 0.9


def test_visible_fraction_is_zero_behind_the_sofa_arm_and_ignores_the_robot(world: World) -> None:
    world.place_static_body(BOX, 0.5, 3.45, 0.0)  # on the floor off the sofa's low end
    assert visible_fraction(world, BOX, (0.6, 4.7, 1.0)) < 0.1  # the arm is in the way
    assert visible_fraction(world, BOX, (2.0, 3.45, 1.0)) == pytest.approx(1.0)
    world.data.qpos[:3] = (1.2, 3.45, 0.0)  # the robot between camera and box
    world.forward()
    try:
        assert visible_fraction(world, BOX, (2.0, 3.45, 1.0)) == pytest.approx(1.0)
    finally:
        world.data.qpos[:3] = 0.0
        world.forward()


def test_a_shelf_spot_fits_under_the_next_shelf(world: World) -> None:
    place_on_surface(world, BOX, 2.4, 0.28, math.pi / 2, level=0.41)
    assert world.body_position(BOX)[2] - 0.15 == pytest.approx(0.41, abs=1e-6)
    assert visible_fraction(world, BOX, (2.4, 1.5, 1.0)) >= 0.9
    before = world.body_position(BOX)
    with pytest.raises(InputError, match="not level"):  # across the shelf, it overhangs
        place_on_surface(world, BOX, 2.4, 0.28, 0.0, level=0.41)
    with pytest.raises(InputError, match="no surface"):  # a book stands there on shelf 1
        place_on_surface(world, BOX, 2.4, 0.15, math.pi / 2, level=0.41)
    assert world.body_position(BOX) == pytest.approx(before)  # a refused spot moves nothing


def test_a_box_on_a_shelf_above_the_camera_is_seen_without_its_bottom() -> None:
    """The face an object stands on is covered by its support: from a 1.0 m camera below a
    1.23 m shelf, the game box's bottom faces the camera but cannot count against it."""
    world = World("apartment")
    x, y, _ = world.body_position("game_box")
    assert visible_fraction(world, "game_box", (x, y - 2.0, 1.0)) >= 0.9


# per scene: the targets to place at once and their kinds (the apartment's are its own)
SEVERAL = {
    "living_room": {"rice_box": ("table", "counter", "shelf")},
    "apartment": None,
}


@pytest.mark.parametrize("scene", sorted(SEVERAL))
def test_place_targets_puts_each_on_its_kind_and_a_seed_repeats(scene: str) -> None:
    world = World(scene)
    supports = SEVERAL[scene] or world.target_supports()
    first = place_targets(world, np.random.default_rng(11), SEVERAL[scene])
    for name, kinds in supports.items():
        geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
        bottom = world.body_position(name)[2] - world.model.geom_size[geom][2]
        assert any(SUPPORT_KINDS[k][0] - 0.003 <= bottom <= SUPPORT_KINDS[k][1] for k in kinds), (
            name,
            bottom,
        )
    assert place_targets(world, np.random.default_rng(11), SEVERAL[scene]) == first
