"""The survey with the laser in the loop: a base whose right wheel is 1 % larger than its
odometry believes, localized on the scene's map, against the same base on odometry alone."""

import json
import tomllib
from pathlib import Path

import pytest

from twin.app.config import ConfigError, dump_toml, load_config, resolve_config
from twin.cli import main

REDUCED = "mission.stops=[[1.1, 1.2], [2.5, 3.3], [2.7, 4.4]]"
MISCALIBRATED = "robot.base.wheel_radius_error=[0.0, 0.01]"


@pytest.fixture(scope="module")
def model_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("rfch-cache")


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
