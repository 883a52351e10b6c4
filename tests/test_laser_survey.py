"""The survey with the laser in the loop: a base whose right wheel is 1 % larger than its
odometry believes, localized on the scene's map, against the same base on odometry alone."""

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from twin.app.config import ConfigError, dump_toml, load_config, resolve_config
from twin.cli import main

REDUCED = "mission.stops=[[1.1, 1.2], [2.5, 3.3], [2.7, 4.4]]"
MISCALIBRATED = "robot.base.wheel_radius_error=[0.0, 0.01]"


def survey(out: Path, cache: Path, *sets: str) -> dict:
    argv = ["survey", "--out", str(out), "--quiet"]
    for setting in (REDUCED, "run.rerun=off", f"run.cache={cache}", MISCALIBRATED, *sets):
        argv += ["--set", setting]
    code = main(argv)
    result = json.loads((out / "result.json").read_text())
    assert (code == 0) == (result["status"] == "complete")
    return result


def test_the_laser_keeps_the_pose_true_where_odometry_drifts(tmp_path, model_cache):
    laser = survey(tmp_path / "laser", model_cache, "robot.base.pose_source=laser")
    assert laser["status"] == "complete" and laser["views"] == 24
    assert laser["pose_error"]["max_m"] <= 0.05 and laser["pose_error"]["max_deg"] <= 2.0
    assert laser["objects"]["rice_box"]["error_m"] < 0.2
    assert laser["views_refused"] == []
    odometry = survey(tmp_path / "odometry", model_cache, "robot.base.pose_source=odometry")
    # odometry alone: a drifting pose, reported as such in the sim (or a contact on the way)
    assert odometry["pose_error"]["max_m"] > 2 * laser["pose_error"]["max_m"]


def test_a_laser_pose_needs_a_laser_and_a_scene_map_needs_the_twin(tmp_path):
    data = tomllib.loads(resolve_config(None).read_text())
    del data["robot"]["laser"]
    data["scene"]["file"] = str(resolve_config(None).parent / data["scene"]["file"])
    no_laser = tmp_path / "no_laser.toml"
    no_laser.write_text(dump_toml(data))
    with pytest.raises(ConfigError, match=r'pose_source: "laser" needs a \[robot.laser\]'):
        load_config(no_laser)
    with pytest.raises(ConfigError, match=r'localization.map: "scene" cuts the map'):
        load_config("peoplebot_real", overrides=["localization.map=scene"])
    with pytest.raises(ConfigError, match=r"--set localization.particles: expected a whole"):
        load_config(None, overrides=["robot.base.pose_source=odometry", "localization.particles=5"])
    odometry = load_config(None, overrides=["robot.base.pose_source=odometry"])
    assert odometry.localization is None  # the shipped table stays, unused


def test_twin_map_builds_a_map_the_localizer_can_use(tmp_path, capsys):
    """A mapping drive in the twin (a short route, a 1 % wheel error): the corrected trajectory
    stays true where odometry drifts, the map agrees with the scene's own, and it loads."""
    from twin.nav.maps import load_map

    out = tmp_path / "room.yaml"
    argv = ["map", "--out", str(out), "--quiet", "--set", "mission.stops=[[2.5, 3.3], [1.2, 3.2]]",
            "--set", MISCALIBRATED]  # fmt: skip
    assert main(argv) == 0
    report = json.loads(out.with_suffix(".report.json").read_text())
    assert report["trajectory_error_m"]["max"] < 0.05
    assert report["odometry_error_m"]["max"] > 2 * report["trajectory_error_m"]["max"]
    assert report["agreement_with_scene"]["precision"] > 0.9
    built = load_map(out)
    assert built.resolution == 0.05 and built.occupied.any()
    # a map is never overwritten
    assert main(argv) == 2
    assert "exists; a map is never overwritten" in capsys.readouterr().err


def test_twin_map_from_the_scene_is_the_shipped_reference(tmp_path):
    from twin.nav.maps import load_map

    out = tmp_path / "scene.yaml"
    assert main(["map", "--from-scene", "--out", str(out), "--quiet"]) == 0
    shipped = load_map(resolve_config(None).parent / "living_room_map.yaml")
    np.testing.assert_array_equal(load_map(out).occupancy, shipped.occupancy)


def test_a_robot_carried_off_in_the_twin_is_found_again():
    """The kidnapped robot in the twin: lifted to another part of the living room while its
    odometry saw nothing, it re-localizes on the scene's map from its LMS200's scans."""
    import math

    from twin.app.factory import build_robot
    from twin.core.geometry import Pose2D

    config = load_config(None)
    robot, context = build_robot(config)
    try:
        with robot:
            base, sim = robot.base, context.sim_in_use
            base.go_to(Pose2D(2.5, 3.3, 0.0))
            before = sim.odometry_pose()
            sim.place(Pose2D(3.2, 1.3, math.radians(135.0)))  # carried off and turned
            sim.reset_odometry(before)  # the wheels never turned: odometry still says "here"
            truth = sim.truth_pose()
            estimate = base._settle()
            assert estimate.localized
            assert math.dist((estimate.pose.x, estimate.pose.y), (truth.x, truth.y)) < 0.05
            assert abs(math.degrees(truth.heading_error_to(estimate.pose))) < 2.0
    finally:
        context.close()
