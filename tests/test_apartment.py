"""The apartment: four rooms whose walls and doors every obstacle test sees, several sought
objects each on its kind of support and alone on its training stage, and a robot that plans
its legs through the doors."""

from __future__ import annotations

import importlib.util
import math

import cv2
import mujoco
import numpy as np
import pytest

from twin.app.config import load_config
from twin.core.errors import InputError
from twin.nav.planner import PathPlanner
from twin.resources import models_dir, scenes_dir
from twin.sim.placement import SUPPORT_KINDS, place_targets, viewpoints, visible_fraction
from twin.sim.render import FrameRenderer
from twin.sim.scene_map import drive_map, scene_map
from twin.sim.supports import room_geoms, vertical_spans
from twin.sim.training import DEFAULT_ANGLES, DEFAULT_DISTANCES
from twin.sim.world import World

ROBOT_RADIUS, MARGIN = 0.30, 0.05  # the mission's planner (twin.app.localization)
# door openings: (wall line's axis, its coordinate in metres, the opening's from and to)
DOORS = {
    "living-hall": ("y", 6.05, 1.95, 2.95),
    "living-kitchen": ("x", 4.55, 3.8, 4.8),
    "hall-kitchen": ("x", 4.55, 6.6, 7.6),
    "kitchen-bedroom": ("y", 3.55, 5.0, 6.0),
}
# one free spot per room
ROOMS = {"living": (2.25, 2.5), "hall": (1.0, 6.9), "kitchen": (5.6, 6.6), "bedroom": (6.2, 2.2)}


@pytest.fixture(scope="module")
def world() -> World:
    return World("apartment")


@pytest.fixture(scope="module")
def maps(world: World):
    cut = scene_map(world, exclude_bodies=world.targets())
    return cut, drive_map(world, cut)


def test_the_scene_declares_four_objects_on_four_kinds_of_support(world: World) -> None:
    assert world.room_bounds() == (0.0, 0.0, 10.0, 8.0)
    assert world.targets() == ("rice_box", "tea_tin", "game_box", "toy_crate")
    kinds = world.target_supports()
    assert {k for ks in kinds.values() for k in ks} == set(SUPPORT_KINDS)
    assert world.robot_start() is not None
    start = world.robot_start()
    world.check_free(start.x, start.y, 0.35, "the start")


def test_every_furniture_body_is_named_and_directly_under_the_world(world: World) -> None:
    model = world.model
    robot = world.body_id("base")
    for body in range(1, model.nbody):
        if model.body_rootid[body] == robot:
            continue
        if model.body_parentid[body] == 0:
            assert model.body(body).name, f"body {body} has no name"
            assert model.body_weldid[body] == 0, model.body(body).name
    furniture = set(world.furniture())
    assert {"sofa", "kitchen_counter", "fridge", "bed", "bookshelf", "coat_rack"} <= furniture
    assert {"wall_living_hall_w", "wall_kitchen_bedroom_e"} <= furniture
    assert not furniture & set(world.targets())


def test_static_geoms_never_collide_and_decorations_are_visual_only(world: World) -> None:
    mujoco.mj_forward(world.model, world.data)
    for c in range(world.data.ncon):
        contact = world.data.contact[c]
        bodies = world.model.geom_bodyid[[contact.geom1, contact.geom2]]
        assert (world.model.body_weldid[bodies] != 0).any(), "two static geoms in contact"
    decor = [g for g in range(world.model.ngeom) if world.model.geom_group[g] == 1]
    assert decor and all(
        world.model.geom_contype[g] == 0 and world.model.geom_conaffinity[g] == 0 for g in decor
    )


def test_each_object_rests_on_a_level_of_its_declared_kind(world: World) -> None:
    for name, kinds in world.target_supports().items():
        geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
        x, y, z = world.body_position(name)
        bottom = z - world.model.geom_size[geom][2]
        spans = vertical_spans(world, room_geoms(world, [name]), np.array([[x, y]]))
        levels = spans.levels(headroom=2 * world.model.geom_size[geom][2])[:, 0]
        levels = levels[np.isfinite(levels)]
        assert np.min(np.abs(levels - bottom)) < 0.003, (name, bottom, levels)
        low, high = SUPPORT_KINDS[kinds[0]]
        assert low <= bottom <= high, (name, bottom, kinds)
        best = max(visible_fraction(world, name, spot) for spot in viewpoints(world, x, y))
        assert best >= 0.9, (name, best)


def test_interior_walls_are_in_the_laser_map_and_the_doors_are_open(world: World, maps) -> None:
    cut, drive = maps
    assert drive.occupied[cut.occupied].all()  # what the laser sees, the planner avoids too
    # the crate on the hall floor is below the laser's plane: only the drive map holds it
    row, col = cut.cell_of(*world.body_position("toy_crate")[:2])
    assert cut.free[row, col] and drive.occupied[row, col]
    for wall in (n for n in world.furniture() if n.startswith("wall_")):
        x0, y0, x1, y1 = world.footprint(wall).aabb
        xs = np.linspace(x0 + 0.02, x1 - 0.02, 5)
        ys = np.linspace(y0 + 0.02, y1 - 0.02, 20)
        rows, cols = cut.cell_of(*np.meshgrid(xs, ys))
        assert cut.occupied[rows, cols].all(), wall
    for door, (axis, line, lo, hi) in DOORS.items():
        along = np.linspace(lo + 0.03, hi - 0.03, 15)
        xs, ys = (
            (np.full_like(along, line), along)
            if axis == "x"
            else (along, np.full_like(along, line))
        )
        rows, cols = cut.cell_of(xs, ys)
        assert cut.free[rows, cols].all(), door
        assert hi - lo >= 0.9


def test_the_start_and_each_room_are_free_but_not_the_walls(world: World) -> None:
    for room, (x, y) in ROOMS.items():
        world.check_free(x, y, 0.35, room)
    with pytest.raises(InputError, match="wall_living_bedroom"):
        world.check_free(4.55, 2.0, 0.1, "in a wall")


def _crossings(path, axis: str, line: float) -> list[float]:
    """Where (the other coordinate, metres) the path's legs cross a wall's line."""
    k = 0 if axis == "x" else 1
    found = []
    for start, end in path.legs:
        a, b = start[k], end[k]
        if (a - line) * (b - line) < 0:
            t = (line - a) / (b - a)
            found.append(start[1 - k] + t * (end[1 - k] - start[1 - k]))
    return found


def test_a_plan_from_the_living_room_to_the_bedroom_goes_through_the_doors(world, maps) -> None:
    _, drive = maps
    planner = PathPlanner(drive, ROBOT_RADIUS, MARGIN, unknown_is_obstacle=False)
    path = planner.plan(ROOMS["living"], ROOMS["bedroom"])
    crossed = sorted(
        door
        for door, (axis, line, lo, hi) in DOORS.items()
        for at in _crossings(path, axis, line)
        if lo <= at <= hi
    )
    assert crossed == ["kitchen-bedroom", "living-kitchen"], path.waypoints
    for start, end in path.legs:  # clear of every wall and piece of furniture
        assert world.path_clearance(start, end) >= ROBOT_RADIUS, (start, end)
    for room in ("hall", "kitchen"):  # and the living room reaches the other rooms
        planner.plan(ROOMS["living"], ROOMS[room])


def test_each_object_is_alone_in_its_training_views() -> None:
    stage = World("training_stage")
    model = stage.model
    assert set(stage.targets()) == {"rice_box", "tea_tin", "game_box", "toy_crate"}
    owner = {
        name: np.flatnonzero(model.geom_bodyid == stage.body_id(name)) for name in stage.targets()
    }
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    with FrameRenderer(model, 160, 120) as renderer:
        for name in stage.targets():
            camera.lookat[:] = stage.body_position(name)
            yaw = stage.body_pose(name).yaw
            others = np.concatenate([g for other, g in owner.items() if other != name])
            seen_self = 0
            for distance in DEFAULT_DISTANCES:  # as twin.sim.training.training_views
                camera.distance = math.hypot(distance, 0.4)
                camera.elevation = -math.degrees(math.atan2(0.4, distance))
                for angle in DEFAULT_ANGLES:
                    camera.azimuth = math.degrees(yaw + angle + math.pi)
                    ids = renderer.segment(stage.data, camera)
                    assert not np.isin(ids, others).any(), (name, distance, angle)
                    seen_self += int(np.isin(ids, owner[name]).any())
            assert seen_self == len(DEFAULT_DISTANCES) * len(DEFAULT_ANGLES)


def test_several_targets_placed_at_random_each_on_its_kind_apart_and_in_view(world) -> None:
    kinds = world.target_supports()
    supports = set()
    try:
        for seed in range(3):
            poses = place_targets(world, np.random.default_rng(seed))
            assert list(poses) == list(kinds)
            names = list(poses)
            for i, name in enumerate(names):
                geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
                bottom = world.body_position(name)[2] - world.model.geom_size[geom][2]
                low, high = SUPPORT_KINDS[kinds[name][0]]
                assert low - 0.003 <= bottom <= high, (seed, name, bottom)
                supports.add(world.support_of(name))
                for other in names[i + 1 :]:
                    a, b = poses[name], poses[other]
                    assert math.hypot(a.x - b.x, a.y - b.y) >= 0.5
                    other_geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, other)
                    gap = mujoco.mj_geomDistance(
                        world.model, world.data, geom, other_geom, 0.1, None
                    )
                    assert gap >= 0.0, (seed, name, other)
        again = place_targets(world, np.random.default_rng(2))
        assert again == poses
    finally:
        world.reset()
    assert len(supports) >= 4  # not the same furniture every time


def test_an_unknown_support_kind_is_refused(world: World) -> None:
    with pytest.raises(InputError, match="unknown support kind 'roof'"):
        place_targets(world, np.random.default_rng(0), {"tea_tin": ("roof",)})


def test_the_mission_config_seeks_every_object_over_the_whole_apartment() -> None:
    config = load_config(scenes_dir() / "apartment.toml")
    assert config.scene.name == "apartment.xml"
    assert {o.body for o in config.objects} == set(World("apartment").targets())
    world = World("apartment")
    for x, y in config.mission.stops:
        world.check_free(x, y, 0.35, "a stop")


def test_the_apartment_script_reproduces_the_committed_files(tmp_path) -> None:
    spec = importlib.util.spec_from_file_location(
        "make_apartment", models_dir() / "make_apartment.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path / "models", tmp_path / "scenes")
    made = sorted((tmp_path / "models" / "textures").glob("*.png"))
    assert len(made) >= 9
    for png in made:
        committed = cv2.imread(str(models_dir() / "textures" / png.name))
        np.testing.assert_array_equal(cv2.imread(str(png)), committed, err_msg=png.name)
    for xml in (tmp_path / "models").glob("*.xml"):
        assert xml.read_text() == (models_dir() / xml.name).read_text(), xml.name
    assert (tmp_path / "scenes" / "apartment.xml").read_text() == (
        scenes_dir() / "apartment.xml"
    ).read_text()


def test_a_calibration_placement_keeps_each_object_on_its_own_kind() -> None:
    """The detector's calibration puts the floor crate on the floor and the shelf box on a
    shelf, as the missions will find them, not on a random furniture top."""
    from twin.sim.training import _random_spot

    world = World("apartment")  # its own: the placements move the targets
    rng = np.random.default_rng(12)
    for name, kinds in world.target_supports().items():
        geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
        for _ in range(2):
            _random_spot(world, name, rng)
            bottom = world.body_position(name)[2] - world.model.geom_size[geom][2]
            assert any(SUPPORT_KINDS[k][0] <= bottom <= SUPPORT_KINDS[k][1] for k in kinds), name


def test_a_placement_that_cuts_off_a_stop_is_drawn_again(world: World, maps) -> None:
    """A crate left on a stop (or across the only door) ends a survey before it has seen
    anything: the batch's placements are judged by ``stops_reachable`` and drawn again."""
    from twin.app.run import place_bodies_randomly, stops_reachable
    from twin.core.errors import TwinError

    occupancy, _ = maps
    config = load_config("apartment")
    start = tuple(config.mission.start[:2])
    stops = config.mission.stops
    crate = world.body_id("toy_crate")
    saved = world.model.body_pos[crate].copy()
    judge = stops_reachable(world, occupancy, start, stops, 0.30, 0.05)
    try:
        assert judge()  # as the scene ships
        world.model.body_pos[crate][:2] = stops[1]  # on the second stop
        world.forward()
        assert not judge()
        verdicts = iter([False, False, True])
        drawn = []

        def third_time_lucky() -> bool:
            drawn.append(tuple(world.model.body_pos[crate][:2]))
            return next(verdicts)

        place_bodies_randomly(world, ["toy_crate"], np.random.default_rng(4), third_time_lucky)
        assert len(drawn) == 3 and len(set(drawn)) == 3  # three different draws
        with pytest.raises(TwinError, match="left the mission's stops reachable"):
            place_bodies_randomly(world, ["toy_crate"], np.random.default_rng(4), lambda: False)
    finally:
        world.model.body_pos[crate] = saved
        world.forward()
