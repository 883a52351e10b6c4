"""The MJCF files: they compile, step cleanly, are reproducible, and match the paper's facts."""

from __future__ import annotations

import importlib.util
import math

import cv2
import numpy as np
import pytest

# isort: off
import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
import mujoco

# isort: on
from twin.core.geometry import CameraModel
from twin.resources import models_dir, scenes_dir
from twin.sim.world import World

SCENES = sorted(p.stem for p in scenes_dir().glob("*.xml"))
MODELS = sorted(models_dir().glob("*.xml"))


def test_there_are_scenes_and_models() -> None:
    assert {"living_room", "training_stage"} <= set(SCENES)
    assert {"peoplebot.xml", "rice_box.xml"} <= {p.name for p in MODELS}


@pytest.mark.parametrize("scene", SCENES)
def test_scene_steps_two_seconds_of_random_controls_without_warnings(scene: str) -> None:
    world = World(scene)
    model, data = world.model, world.data
    rng = np.random.default_rng(7)
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    steps_per_control = max(1, round(0.1 / world.timestep))
    for _ in range(round(2.0 / world.timestep / steps_per_control)):
        data.ctrl[:] = rng.uniform(lo, hi)
        world.step(steps_per_control)
    assert world.time == pytest.approx(2.0, abs=world.timestep)
    assert world.warnings() == {}
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))


@pytest.mark.parametrize("path", MODELS, ids=lambda p: p.name)
def test_each_model_file_compiles_alone_or_is_included_by_a_scene(path) -> None:
    text = path.read_text()
    if "<worldbody>" in text or "<asset>" in text:
        mujoco.MjModel.from_xml_path(str(path))
    else:  # a fragment meant for <include> inside a body, by a scene or by a fragment it includes
        included = {p.name for p in scenes_dir().glob("*.xml")}
        texts = {p.name: p.read_text() for p in [*scenes_dir().glob("*.xml"), *MODELS]}
        for _ in range(len(texts)):  # follow includes down to any depth
            for name in texts:
                if any(f'file="../models/{name}"' in texts[i] for i in included):
                    included.add(name)
        assert path.name in included, path.name


def test_assets_script_reproduces_the_committed_files(tmp_path) -> None:
    spec = importlib.util.spec_from_file_location("make_assets", models_dir() / "make_assets.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(tmp_path)
    made = sorted((tmp_path / "textures").glob("*.png"))
    assert made, "the script made no textures"
    for png in made:
        committed = cv2.imread(str(models_dir() / "textures" / png.name))
        np.testing.assert_array_equal(cv2.imread(str(png)), committed, err_msg=png.name)
    assert (tmp_path / "bookcase_contents.xml").read_text() == (
        models_dir() / "bookcase_contents.xml"
    ).read_text()


def test_robot_is_peoplebot_sized_with_the_paper_camera() -> None:
    world = World("living_room")
    model, data = world.model, world.data
    robot_bodies = [b for b in range(model.nbody) if model.body_rootid[b] == world.body_id("base")]
    mass = float(model.body_mass[robot_bodies].sum())
    assert 15.0 < mass < 40.0
    assert world.footprint("base").top == pytest.approx(1.2, abs=0.03)
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "head_camera")
    assert data.cam_xpos[cam, 2] == pytest.approx(1.0, abs=0.002)
    assert model.cam_fovy[cam] == pytest.approx(math.degrees(CameraModel().vfov), abs=0.01)


def test_head_servos_carry_the_vcc4_limits_and_speeds() -> None:
    model = World("living_room").model

    def actuator(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)

    np.testing.assert_allclose(
        np.degrees(model.actuator_actrange[actuator("pan")]), [-100, 100], atol=1e-4
    )
    np.testing.assert_allclose(
        np.degrees(model.actuator_actrange[actuator("tilt")]), [-30, 90], atol=1e-4
    )
    np.testing.assert_allclose(
        np.degrees(model.actuator_ctrlrange[actuator("pan")]), [-90, 90], atol=1e-4
    )
    np.testing.assert_allclose(
        np.degrees(model.actuator_ctrlrange[actuator("tilt")]), [-70, 70], atol=1e-4
    )


def test_living_room_follows_the_papers_layout() -> None:
    world = World("living_room")
    assert world.room_bounds() == pytest.approx((0.0, 0.0, 4.5, 6.0))
    assert world.targets() == ("rice_box",)
    xmin, ymin, xmax, ymax = world.room_bounds()
    box = world.body_position("rice_box")
    assert box[0] < (xmin + xmax) / 2 and box[1] > (ymin + ymax) / 2  # upper-left quarter
    chair = world.body_position("chair")
    assert chair[0] > 0.7 * xmax and 0.3 * ymax < chair[1] < 0.7 * ymax  # centre right
    assert world.footprint("bookcase").aabb[1] < 0.1  # along the bottom wall
    # the box (0.2 x 0.07 x 0.3 m) stands on the coffee table
    geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "rice_box")
    assert sorted(2 * world.model.geom_size[geom]) == pytest.approx([0.07, 0.2, 0.3])
    table = world.footprint("coffee_table")
    tx0, ty0, tx1, ty1 = table.aabb
    assert tx0 < box[0] < tx1 and ty0 < box[1] < ty1
    assert box[2] - 0.15 == pytest.approx(world.surface_height(*box[:2], exclude="rice_box"))
    assert world.surface_height(*box[:2], exclude="rice_box") == pytest.approx(0.45)
    assert {"sofa", "coffee_table", "chair", "table", "bookcase"} <= set(world.furniture())


def test_the_laser_sits_on_the_front_at_030_m_and_the_robot_is_outside_the_scene_groups() -> None:
    """The LMS200's scan plane is 0.30 m above the floor at the base's front, its housing a
    visible massless box within the chassis' footprint; every robot geom is in group 2 or 3, so
    a cast at the scene's groups 0 and 1 never meets the robot."""
    world = World("living_room")
    model = world.model
    base = world.body_id("base")
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "laser")
    assert model.site_bodyid[site] == base
    x, y, z = model.site_pos[site]
    assert (y, z) == pytest.approx((0.0, 0.30))
    assert 0.1 < x < 0.2  # in front of the axle, behind the bumper
    housing = model.geom("laser_housing").id
    assert model.geom_group[housing] <= 2 and model.geom_contype[housing] == 0
    chassis = model.geom("chassis").id
    front = model.geom_pos[chassis, 0] + model.geom_size[chassis, 0]
    assert model.geom_pos[housing, 0] + model.geom_size[housing, 0] <= front
    own = model.body_rootid[model.geom_bodyid] == base
    assert set(model.geom_group[own]) <= {2, 3}
    assert set(model.geom_group[~own]) <= {0, 1}
    # the wheels touch the floor where they should, as wide as the tyre drawn over them
    wheel, tyre = model.geom("left_wheel").id, model.geom("left_tyre").id
    assert model.geom_size[wheel, 0] == model.geom_size[tyre, 0]
    assert model.geom_size[wheel, 2] == model.geom_size[tyre, 1]
