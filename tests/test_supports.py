"""The support map: per plan cell, the heights an object could stand at in the living room."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from twin.core.errors import InputError
from twin.core.visibility import SupportLevels
from twin.sim.supports import support_levels
from twin.sim.world import World


@pytest.fixture(scope="module")
def world() -> World:
    return World("living_room")


@pytest.fixture(scope="module")
def levels(world: World) -> SupportLevels:
    return support_levels(world)


def _at(levels: SupportLevels, x: float, y: float) -> list[float]:
    row = levels.sample(np.array(x), np.array(y))
    return [float(h) for h in row[np.isfinite(row)]]


def test_grid_shape_and_nan_padding(world: World, levels: SupportLevels) -> None:
    ny, nx, k = levels.levels.shape
    assert (ny, nx) == (60, 45) and k >= 6
    assert (levels.x_min, levels.y_min, levels.cell_size) == (0.0, 0.0, 0.1)
    finite = np.isfinite(levels.levels)
    # per cell: the heights first, ascending, then only NaN
    assert np.all(finite[..., :-1] | ~finite[..., 1:])
    steps = np.diff(levels.levels, axis=2)
    assert np.all(steps[np.isfinite(steps)] > 0)
    assert finite[..., -1].any()  # k is no larger than the busiest cell needs
    assert np.nanmax(levels.levels) <= 2.0
    assert support_levels(world, cell_size=0.2).levels.shape[:2] == (30, 23)


def test_the_sofa_seat_holds_the_cushion_top_not_the_frame(levels: SupportLevels) -> None:
    assert _at(levels, 0.6, 4.3) == pytest.approx([0.52])


def test_a_bookcase_cell_holds_every_shelf_and_the_top(world: World, levels: SupportLevels) -> None:
    # the front strip, clear of books at x = 2.45: the five shelves and the top at 1.8 m
    assert _at(levels, 2.45, 0.25) == pytest.approx([0.05, 0.41, 0.77, 1.13, 1.49, 1.8])
    # among the books: each shelf's book tops instead, still one level per shelf
    books = _at(levels, 2.05, 0.15)
    assert len(books) == 6 and books[-1] == pytest.approx(1.8)
    low = support_levels(world, max_height=1.5)
    assert _at(low, 2.45, 0.25) == pytest.approx([0.05, 0.41, 0.77, 1.13, 1.49])


def test_open_floor_is_only_the_floor_and_a_table_adds_its_top(levels: SupportLevels) -> None:
    assert _at(levels, 3.05, 3.55) == [0.0]
    coffee = _at(levels, 1.75, 4.95)  # floor (under a 4 mm rug), then the table top
    assert coffee == pytest.approx([0.0, 0.45], abs=0.005)


def test_the_target_and_the_robot_are_not_supports(world: World) -> None:
    box = world.body_position("rice_box")
    assert _at(support_levels(world), box[0], box[1]) == pytest.approx([0.0, 0.45], abs=0.005)
    world.data.qpos[:2] = (3.05, 3.55)  # the robot on the open floor cell
    world.forward()
    try:
        assert _at(support_levels(world), 3.05, 3.55) == [0.0]
    finally:
        world.data.qpos[:2] = 0.0
        world.forward()


def test_bad_cell_size_is_refused(world: World) -> None:
    with pytest.raises(InputError, match="cell size"):
        support_levels(world, cell_size=-0.1)
    with pytest.raises(InputError, match="max height"):
        support_levels(world, max_height=math.nan)


@pytest.mark.parametrize("scene", ["living_room", "apartment"])
def test_every_target_stands_on_a_level_of_the_map_and_the_grid_covers_the_floor(scene) -> None:
    world = World(scene)
    levels = support_levels(world)
    x0, y0, x1, y1 = world.room_bounds()
    assert levels.levels.shape[:2] == (round((y1 - y0) / 0.1), round((x1 - x0) / 0.1))
    floor = levels.levels[..., 0] <= 0.005  # the floor, or a rug or tiles on it
    assert floor.mean() > 0.5  # most of the floor is free floor
    for name in world.targets():
        geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
        x, y, z = world.body_position(name)
        bottom = z - world.model.geom_size[geom][2]
        here = _at(levels, x, y)
        assert min(abs(h - bottom) for h in here) < 0.005, (name, bottom, here)
