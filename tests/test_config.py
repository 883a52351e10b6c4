"""Configs: typed device options, --set overrides, shipped configs by name, the run's copy."""

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Literal

import pytest

from twin.app.config import (
    ConfigError,
    apply_overrides,
    dump_toml,
    load_config,
    resolve_config,
    shipped_configs,
)
from twin.app.device_types import DEVICE_TYPES
from twin.cli import main
from twin.core.options import OptionError, describe_options, option, parse_options

SCENES = Path(__file__).resolve().parents[1] / "scenes"


# -- typed options -----------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Example:
    port: str = option(doc="required")
    width: int = option(320, unit="px", low=16, high=4096)
    gain: float = option(1.0, low=0.0)
    mode: Literal["a", "b"] = option("a")
    device: int | str = option(0)
    bias: tuple[float, float] = option((0.0, 0.0), low=-0.1, high=0.1)
    verbose: bool = option(False)
    name: str | None = option(None)


def test_options_are_parsed_into_their_types():
    parsed = parse_options(
        Example, {"port": "/dev/x", "width": 640, "gain": 2, "bias": [0.01, -0.02], "device": "v"}
    )
    assert parsed == Example("/dev/x", 640, 2.0, "a", "v", (0.01, -0.02), False, None)
    assert isinstance(parsed.gain, float)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"port": "p", "width": "wide"}, "width: expected a whole number of px in [16, 4096]"),
        ({"port": "p", "width": 8}, "width: expected a whole number of px in [16, 4096], got 8"),
        ({"port": "p", "width": True}, "width: expected a whole number"),
        ({"port": "p", "gain": -1}, "gain: expected a number >= 0"),
        ({"port": "p", "gain": float("nan")}, "gain: expected a number"),
        ({"port": "p", "mode": "c"}, "mode: expected one of a, b, got 'c'"),
        ({"port": "p", "device": 1.5}, "device: expected a whole number or a string"),
        ({"port": "p", "bias": [0.0]}, "bias: expected a list of 2 numbers"),
        ({"port": "p", "bias": [0.0, 0.5]}, "bias: expected a list of 2 numbers in [-0.1, 0.1]"),
        ({"port": "p", "verbose": 1}, "verbose: expected true or false"),
        ({"port": "p", "name": ""}, "name: expected a non-empty string"),
        ({}, "port: is required: give a non-empty string"),
        ({"port": "p", "widht": 3}, "widht: unknown option for type 'x'; known: port, width"),
    ],
)
def test_a_wrong_option_names_its_key_and_what_it_expects(table, message):
    with pytest.raises(OptionError) as caught:
        parse_options(Example, table, "type 'x'")
    assert message in str(caught.value)


def test_every_device_type_declares_documented_options_with_valid_defaults():
    for (role, name), declared in DEVICE_TYPES.items():
        assert declared.role == role and declared.name == name and declared.summary
        for info in describe_options(declared.options):
            assert info.doc, f"{role}.{name}.{info.name} has no description"
        required = {i.name: "x" for i in describe_options(declared.options) if i.required}
        parse_options(declared.options, required)  # the defaults themselves pass the checks


def test_twin_devices_lists_every_type_and_option(capsys):
    assert main(["devices"]) == 0
    printed = capsys.readouterr().out
    for (role, name), declared in DEVICE_TYPES.items():
        assert f'[robot.{role}] type = "{name}"' in printed
        for info in describe_options(declared.options):
            assert f"    {info.name}: " in printed


# -- --set -------------------------------------------------------------------------------------


def test_set_values_are_toml_and_bare_words_are_strings():
    data = {"grid": {"fusion": "accumulate"}, "mission": {"views_per_stop": 8}}
    out, keys = apply_overrides(
        data,
        [
            "grid.fusion=normalized",
            'grid.rule="x y"',
            "mission.views_per_stop=4",
            "robot.base.wheel_radius_error=[0.0, 0.01]",
        ],
    )
    assert out["grid"] == {"fusion": "normalized", "rule": "x y"}
    assert out["mission"]["views_per_stop"] == 4
    assert out["robot"]["base"]["wheel_radius_error"] == [0.0, 0.01]
    assert data["grid"]["fusion"] == "accumulate"  # the caller's data is left alone
    assert keys == {
        "grid.fusion",
        "grid.rule",
        "mission.views_per_stop",
        "robot.base.wheel_radius_error",
    }


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("views", "--set 'views': expected KEY=VALUE"),
        ("=3", "--set '=3': expected KEY=VALUE"),
        ("a..b=3", "--set 'a..b=3': expected KEY=VALUE"),
        ("grid.extent=[1, 2", "--set grid.extent=[1, 2: VALUE is not TOML"),
        ("mission.stops.x=1", "--set mission.stops.x: mission.stops is not a table"),
    ],
)
def test_a_malformed_set_is_one_line(setting, message):
    with pytest.raises(ConfigError) as caught:
        load_config(None, overrides=[setting])
    assert message in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("robot.camera.width=wide", "--set robot.camera.width: expected a whole number of px"),
        ("mission.stopz=1", "--set mission.stopz: unknown key"),
        ("mission.stops=[[1.0]]", "--set mission.stops[0]: expected [x, y] in metres"),
        ("grid.fusion=bayes", "--set grid.fusion: expected one of accumulate, normalized"),
        ("robot.camera.type=warp", "--set robot.camera.type: unknown type 'warp'; use one of"),
        ("run.rerun=stream", "--set run.rerun: expected one of save, spawn, serve, off"),
        ("robot.base.pose_source=gps", "--set robot.base.pose_source: expected one of"),
    ],
)
def test_a_bad_set_key_or_value_is_named_as_a_set(setting, message):
    with pytest.raises(ConfigError, match="^" + message.replace("[", r"\[").replace("]", r"\]")):
        load_config(None, overrides=[setting])


def test_set_changes_the_config_it_names():
    config = load_config(
        "living_room_serial_twins",
        overrides=["grid.fusion=normalized", "mission.views_per_stop=4", "robot.base.baud=19200"],
    )
    assert config.grid.rule.name == "normalized"
    assert len(config.mission.headings) == 4
    assert config.devices["base"].options.baud == 19200
    assert config.devices["pantilt"].options.wiring == "aux"


# -- which config ------------------------------------------------------------------------------


def test_shipped_configs_are_found_by_name_and_all_load():
    assert {"living_room_survey", "living_room_serial_twins", "peoplebot_real"} <= set(
        shipped_configs()
    )
    for name in shipped_configs():
        assert resolve_config(name) == resolve_config(f"{name}.toml")
        load_config(name)


def test_an_unknown_config_name_lists_the_shipped_ones(tmp_path):
    with pytest.raises(ConfigError, match=r"no shipped config of that name; shipped: .*peoplebot"):
        resolve_config("kitchen")
    with pytest.raises(ConfigError, match="is a folder"):
        resolve_config(tmp_path)


def test_a_config_written_by_dump_toml_reads_back_the_same():
    for name in shipped_configs():
        data = tomllib.loads(resolve_config(name).read_text())
        assert tomllib.loads(dump_toml(data, "a comment\nover two lines")) == data
    odd = {"a": {"b c": 'quote " and \\ and \n', "list": [1, 2.5, True], "t": {"u": -0.0}}}
    assert tomllib.loads(dump_toml(odd)) == odd


def test_broken_toml_and_an_unknown_key_in_a_file_are_named(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("[grid\n")
    with pytest.raises(ConfigError, match=r"broken.toml: not valid TOML"):
        load_config(broken)
    data = tomllib.loads(resolve_config(None).read_text())
    data["mission"]["stopz"] = 1
    data["scene"]["file"] = str(SCENES / "living_room.xml")
    unknown = tmp_path / "unknown.toml"
    unknown.write_text(dump_toml(data))
    with pytest.raises(ConfigError, match=r"^unknown.toml: mission.stopz: unknown key"):
        load_config(unknown)


# -- what the config checks before anything runs -------------------------------------------------


def test_logodds_without_its_rates_and_threshold_is_refused():
    for missing in ("p_fp", "p_fn", "threshold"):
        given = [f"grid.{k}=0.1" for k in ("p_fp", "p_fn", "threshold") if k != missing]
        with pytest.raises(ConfigError, match=f"grid.{missing}: logodds needs the detector's"):
            load_config(None, overrides=["grid.fusion=logodds", *given])
    config = load_config(
        None,
        overrides=[
            "grid.fusion=logodds",
            "grid.p_fp=0.1",
            "grid.p_fn=0.05",
            "grid.threshold=0.162",
        ],
    )
    assert config.grid.rule.threshold == 0.162


def test_a_head_on_aux_needs_an_arcos_base_and_a_direct_head_needs_a_port():
    with pytest.raises(ConfigError, match=r"robot.pantilt.wiring: \"aux\" tunnels through"):
        load_config(None, overrides=["robot.pantilt.type=vcc4", "robot.pantilt.wiring=aux"])
    with pytest.raises(ConfigError, match=r"robot.pantilt.port: give the serial port"):
        load_config(None, overrides=["robot.pantilt.type=vcc4"])


def test_a_follow_up_without_a_map_is_refused_at_load():
    """Its drives are planned on the localization map: refused before any view, not after."""
    assert load_config("apartment").search.follow_up_views > 0
    with pytest.raises(ConfigError, match=r"search.follow_up_views: the follow-up plans"):
        load_config("apartment", overrides=["robot.base.pose_source=odometry"])
    config = load_config("apartment", overrides=["robot.base.pose_source=odometry",
                                                 "search.follow_up_views=0"])  # fmt: skip
    assert config.localization is None


def test_bad_detector_parameters_are_named_at_load(tmp_path):
    message = r"^--set detector.n_clusters: n_clusters must be an integer"
    with pytest.raises(ConfigError, match=message):
        load_config(None, overrides=["detector.n_clusters=many"])


def test_visibility_and_confidence_are_typed_tables_checked_at_load():
    config = load_config(None)
    assert config.visibility.source == "auto" and config.visibility.supports == "model"
    assert config.confidence.radius_m == 0.2
    with pytest.raises(ConfigError, match=r"^--set visibility.source: expected one of"):
        load_config(None, overrides=["visibility.source=sonar"])
    with pytest.raises(ConfigError, match=r"^--set confidence.p_absent: expected a number"):
        load_config(None, overrides=["confidence.p_absent=1.5"])
    # A real camera gives no depth: the config says what to use instead.
    with pytest.raises(ConfigError, match=r"visibility.source: a 'opencv' camera gives no depth"):
        load_config("peoplebot_real", overrides=["visibility.source=depth"])
    assert load_config("peoplebot_real").visibility.source == "auto"


def test_the_calibrated_rule_waits_for_the_models_and_refuses_one_without_calibration():
    from types import SimpleNamespace

    from twin.app.run import make_grids
    from twin.core.errors import InputError
    from twin.core.fusion import make_rule

    config = load_config(None, overrides=["grid.fusion=calibrated", "grid.direction_bins=8"])
    assert config.grid.rule is None and config.grid.direction_bins == 8
    table = SimpleNamespace(rule=lambda **_: make_rule("calibrated", edges=(0, 1), llr=(0.5,)))
    calibrated = SimpleNamespace(name="rice_box", calibration=table)
    grid, belief = make_grids(config, SimpleNamespace(models=[calibrated]))
    assert grid is belief and grid.rule.name == "calibrated" and grid.direction_bins == 8
    bare = SimpleNamespace(name="rice_box", calibration=None)
    with pytest.raises(InputError, match="needs each model's score calibration; 'rice_box'"):
        make_grids(config, SimpleNamespace(models=[bare]))
    # Another rule runs without one; there is then no confidence.
    plain = load_config(None, overrides=["grid.fusion=accumulate"])
    grid, belief = make_grids(plain, SimpleNamespace(models=[bare]))
    assert grid.rule.name == plain.grid.fusion and belief is None
    with pytest.raises(ConfigError, match=r"grid.direction_bins: expected a whole number >= 1"):
        load_config(None, overrides=["grid.direction_bins=0"])
    with pytest.raises(ConfigError, match=r"grid.direction_bins: expected 1 \(off\) to 64"):
        load_config(None, overrides=["grid.direction_bins=65"])


def test_the_grid_covers_the_scene_unless_told_otherwise(tmp_path):
    """A config that leaves the extent to the scene gets the scene's floor; a given extent
    wins; a scene without a floor to read is refused in one line that says what to give."""
    spec = load_config(None).grid.spec
    assert (spec.x_min, spec.y_min, spec.x_max, spec.y_max) == (0.0, 0.0, 4.5, 6.0)
    told = load_config(None, overrides=["grid.extent=[1.0, 1.0, 3.0, 4.0]"])
    assert (told.grid.spec.x_min, told.grid.spec.y_max) == (1.0, 4.0)
    stage = load_config(None, overrides=['scene.file="training_stage.xml"'])
    assert (stage.grid.spec.x_min, stage.grid.spec.x_max) == (-5.0, 5.0)  # the stage's floor
    bare = tmp_path / "bare.xml"
    bare.write_text('<mujoco><worldbody><geom type="sphere" size="1"/></worldbody></mujoco>')
    with pytest.raises(ConfigError) as caught:
        load_config(None, overrides=[f'scene.file="{bare}"'])
    message = str(caught.value)
    assert "grid.extent" in message and "floor" in message and "\n" not in message


def test_each_stop_may_have_its_own_tilt():
    """stop_tilts_deg: one tilt per stop (the views of a stop share it); a list of the wrong
    length, or a tilt out of the head's range, is refused in one line naming the key."""
    from twin.app.survey import plan_views
    from twin.core.devices import VCC4_LIMITS

    stops = "mission.stops=[[1.1, 1.2], [2.5, 3.3]]"
    config = load_config(None, overrides=[stops, "mission.stop_tilts_deg=[-20, 5]"])
    tilts = {
        (v.stop, round(math.degrees(v.tilt), 6)) for v in plan_views(config.mission, VCC4_LIMITS)
    }
    assert tilts == {(0, -20.0), (1, 5.0)}
    assert load_config(None, overrides=[stops]).mission.tilt_at(1) == 0.0
    for bad, key in (("[-20]", "mission.stop_tilts_deg"), ("[-20, -45]", "stop_tilts_deg[1]")):
        with pytest.raises(ConfigError, match=key.replace("[", r"\[")) as caught:
            load_config(None, overrides=[stops, f"mission.stop_tilts_deg={bad}"])
        assert "\n" not in str(caught.value)


def test_a_floor_sweep_looks_for_the_objects_that_stand_on_the_floor():
    """floor_tilt_deg: every stop sweeps again that far down, for the objects whose stands_on
    names the floor; an unknown kind of surface or a tilt up is refused in one line."""
    from twin.app.survey import plan_views
    from twin.core.devices import VCC4_LIMITS

    stops = "mission.stops=[[1.1, 1.2], [2.5, 3.3]]"
    config = load_config(
        "apartment", overrides=[stops, "mission.floor_tilt_deg=-25", "mission.tilt_deg=-4"]
    )
    assert config.floor_objects == ("toy_crate",)
    plan = plan_views(config.mission, VCC4_LIMITS, config.floor_objects)
    assert len(plan) == 2 * 2 * 8 and [v.index for v in plan] == list(range(len(plan)))
    down = [v for v in plan if v.objects is not None]
    assert {v.objects for v in down} == {("toy_crate",)}
    assert {round(math.degrees(v.tilt), 6) for v in down} == {-25.0}
    for stop in (0, 1):
        level = [v for v in plan if v.stop == stop and v.objects is None]
        floor = [v for v in plan if v.stop == stop and v.objects is not None]
        assert len(level) == len(floor) == 8

        def headings(views):
            return {round(math.degrees(v.base.yaw + v.pan)) % 360 for v in views}

        assert headings(floor) == headings(level) and len(headings(level)) == 8
    assert len(plan_views(config.mission, VCC4_LIMITS)) == 16  # no floor objects: no sweep
    for bad, key in (
        ("mission.floor_tilt_deg=5", "floor_tilt_deg"),
        ('objects.toy_crate.stands_on=["rug"]', "stands_on"),
        ('objects.toy_crate.stands_on="floor"', "stands_on"),
    ):
        with pytest.raises(ConfigError, match=key) as caught:
            load_config("apartment", overrides=[stops, bad])
        assert "\n" not in str(caught.value)


def test_each_object_may_say_how_tall_it_is():
    """``[objects.X] object_height_m``: an object's own height, else the visibility model's;
    a height that is no height is refused in one line that names the key."""
    config = load_config("apartment")
    assert config.object_heights == {
        "rice_box": 0.30, "tea_tin": 0.14, "game_box": 0.22, "toy_crate": 0.25,
    }  # fmt: skip
    board = load_config("calibration_board", overrides=["visibility.object_height_m=0.4"])
    assert board.object_heights == {"calibration_board": 0.4}
    for bad in ("0", "-0.3", "4.0", '"tall"'):
        with pytest.raises(ConfigError, match="object_height_m") as caught:
            load_config("apartment", overrides=[f"objects.rice_box.object_height_m={bad}"])
        assert "\n" not in str(caught.value)
