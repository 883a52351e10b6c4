"""The survey mission: planning, a reduced mission in the twin, resume, recording, bad configs."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from twin.app.config import ConfigError, MissionConfig, load_config
from twin.app.survey import SurveyContext, plan_views, run_survey
from twin.cli import main
from twin.core.devices import VCC4_LIMITS, Base, Camera, Frame, PanTilt, Robot
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D, wrap_angle
from twin.core.grid import AccumulatorGrid, GridSpec

SHIPPED = Path(__file__).resolve().parents[1] / "scenes" / "living_room_survey.toml"
REDUCED_STOPS = "[[1.1, 1.2], [2.5, 3.3], [2.7, 4.4]]"  # 3 of the paper's 5 stops: 24 views


def write_config(folder: Path, cache: Path, rerun: str = "off", **replace: str) -> Path:
    """The shipped config with the reduced mission, a shared model cache and given keys replaced."""
    lines = []
    settings = {
        "stops": REDUCED_STOPS,
        "rerun": f'"{rerun}"',
        "cache": f'"{cache}"',
        "file": f'"{SHIPPED.parent / "living_room.xml"}"',
        **replace,
    }
    for line in SHIPPED.read_text().splitlines():
        key = line.split("=")[0].strip()
        lines.append(f"{key} = {settings[key]}" if key in settings and "=" in line else line)
    path = folder / "survey.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="session")
def model_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("rfch-cache")


def read_result(out: Path) -> dict:
    return json.loads((out / "result.json").read_text())


# -- planning --------------------------------------------------------------------------------


def test_pan_mode_covers_every_heading_with_two_base_turns_per_stop():
    headings = tuple(math.radians(45 * i) for i in range(8))
    mission = MissionConfig((0.0, 0.0, 0.0), ((1.0, 1.0), (2.0, 2.0)), headings, "pan")
    plan = plan_views(mission, VCC4_LIMITS)
    assert len(plan) == 16
    for stop in (0, 1):
        views = [v for v in plan if v.stop == stop]
        assert len({round(v.base.yaw, 9) for v in views}) == 2
        seen = sorted(
            round(float(wrap_angle(v.base.yaw + v.pan)) % (2 * math.pi), 6) for v in views
        )
        assert seen == sorted(round(h % (2 * math.pi), 6) for h in headings)
        assert all(abs(v.pan) <= VCC4_LIMITS.pan_max for v in views)


def test_base_mode_faces_every_heading_with_the_head_straight():
    headings = tuple(math.radians(45 * i) for i in range(8))
    plan = plan_views(MissionConfig((0.0, 0.0, 0.0), ((1.0, 1.0),), headings, "base"), VCC4_LIMITS)
    assert [v.pan for v in plan] == [0.0] * 8
    assert sorted(round(v.base.yaw % (2 * math.pi), 6) for v in plan) == sorted(
        round(h % (2 * math.pi), 6) for h in headings
    )


# -- resume, exactly, on devices with exact poses -----------------------------------------------


class Switch:
    """connect/close for the stand-in devices: they only remember whether they are open."""

    _open = False

    def connect(self):
        self._open = True

    def close(self):
        self._open = False

    @property
    def is_connected(self):
        return self._open


class ExactBase(Switch, Base):
    name = "exact base"

    def __init__(self):
        self._pose = Pose2D(0.5, 0.5, 0.0)

    def pose(self):
        return self._pose

    def set_pose(self, pose):
        self._pose = pose

    def go_to(self, goal, *, timeout=60.0):
        self._pose = goal
        return goal

    def drive(self, speed, turn_rate, duration):
        return self._pose

    def stop(self):
        pass


class ExactHead(Switch, PanTilt):
    name = "exact head"

    def __init__(self):
        self.angles = (0.0, 0.0)

    @property
    def limits(self):
        return VCC4_LIMITS

    def move_to(self, pan, tilt=0.0, *, speed=None, timeout=10.0):
        self.angles = (pan, tilt)
        return self.angles

    def position(self):
        return self.angles

    def stop(self):
        pass


class PoseCamera(Switch, Camera):
    """Renders nothing: its image is a deterministic function of where the robot looks."""

    name = "pose camera"

    def __init__(self, base, head):
        self.base, self.head = base, head

    @property
    def model(self):
        return CameraModel(64, 48)

    def grab(self):
        pose, (pan, _) = self.base.pose(), self.head.position()
        seed = int(1e6 * (pose.x + 3 * pose.y + 7 * (pose.yaw + pan)) % 2**32)
        image = np.random.default_rng(seed).integers(0, 256, (48, 64, 3), dtype=np.uint8)
        return Frame(image, 0.0)


class MeanDetector:
    """A stand-in detector: a patch's score is its mean red level."""

    names = ("thing",)

    def scores(self, image):
        red = image[..., 0].astype(float) / 255
        return red.reshape(3, 16, 8, 8).mean(axis=(1, 3))[None]

    def patch_boxes(self, shape):
        return np.array(
            [[[8 * c, 16 * r, 8 * c + 8, 16 * r + 16] for c in range(8)] for r in range(3)]
        )

    def column_spans(self, width):
        return np.array([[8 * c, 8 * c + 8] for c in range(8)], dtype=float)


def exact_context(out: Path, grid: AccumulatorGrid) -> SurveyContext:
    base, head = ExactBase(), ExactHead()
    mission = MissionConfig(
        (0.5, 0.5, 0.0),
        ((1.0, 1.0), (3.0, 1.5), (2.0, 3.0)),
        tuple(math.radians(60 * i) for i in range(6)),
    )
    return SurveyContext(
        Robot(PoseCamera(base, head), head, base), MeanDetector(), grid, mission, out
    )


def test_resume_after_an_interruption_gives_the_same_grid(tmp_path):
    spec = GridSpec(0.0, 0.0, 4.0, 4.0, 0.1)
    straight = exact_context(tmp_path / "straight", AccumulatorGrid(["thing"], spec))
    with straight.robot:
        run_survey(straight)

    interrupted = exact_context(tmp_path / "resumed", AccumulatorGrid(["thing"], spec))

    def stop_at_view_7(view):
        if view.index == 7:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), interrupted.robot:
        run_survey(interrupted, on_view=stop_at_view_7)
    saved = AccumulatorGrid.load(tmp_path / "resumed" / "checkpoint" / "grid.npz")
    assert saved.views("thing") == 7
    resumed = exact_context(tmp_path / "resumed", saved)
    with resumed.robot:
        state = run_survey(resumed, resume=True)
    assert state.views_done == 18 and len(state.path) == 18
    assert resumed.grid.views("thing") == 18
    np.testing.assert_array_equal(resumed.grid.layer("thing"), straight.grid.layer("thing"))
    np.testing.assert_array_equal(resumed.grid.observed("thing"), straight.grid.observed("thing"))


# -- the mission in the twin ------------------------------------------------------------------


@pytest.fixture(scope="module")
def reduced_run(tmp_path_factory, model_cache):
    folder = tmp_path_factory.mktemp("reduced")
    config = write_config(folder, model_cache, rerun="save")
    out = folder / "run"
    assert main(["survey", "--config", str(config), "--out", str(out), "--quiet"]) == 0
    return out


def test_a_reduced_mission_finds_the_rice_box(reduced_run):
    result = read_result(reduced_run)
    box = result["objects"]["rice_box"]
    assert result["views"] == 24
    assert box["error_m"] < 0.2
    assert box["peak_ratio"] is None or box["peak_ratio"] > 1.1
    assert set(result["timings_s"]) >= {"physics", "render", "detect", "fuse", "record", "total"}
    assert (reduced_run / "grid_rice_box.png").read_bytes()[:4] == b"\x89PNG"
    assert AccumulatorGrid.load(reduced_run / "grid.npz").views("rice_box") == 24


def test_the_recording_holds_the_expected_entities(reduced_run):
    from rerun.chunk import RrdReader

    store = RrdReader(reduced_run / "recording.rrd").store()
    entities = set(store.schema().entity_paths())
    expected = {
        "/world/room/outline",
        "/world/room/furniture/chair",
        "/world/truth/rice_box",
        "/world/robot",
        "/world/path",
        "/world/robot/camera",
        "/world/robot/camera/image",
        "/world/robot/camera/image/scores/rice_box",
        "/world/wedges/rice_box",
        "/world/grid/rice_box",
        "/world/estimate/rice_box",
        "/plots/peak/rice_box",
    }
    assert expected <= entities
    archetypes = {str(a) for a in store.schema().archetypes()}
    assert any("GridMap" in a for a in archetypes) and any("Pinhole" in a for a in archetypes)


def test_an_interrupted_survey_resumes_from_its_folder(
    tmp_path, model_cache, monkeypatch, reduced_run
):
    import twin.app.run

    config = write_config(tmp_path, model_cache, rerun="save")
    out = tmp_path / "run"
    real = twin.app.run.run_survey

    def interrupted(context, on_view=None, resume=False):
        def hook(view):
            on_view(view)
            if view.index == 10:
                raise KeyboardInterrupt

        return real(context, on_view=hook, resume=resume)

    monkeypatch.setattr(twin.app.run, "run_survey", interrupted)
    assert main(["survey", "--config", str(config), "--out", str(out), "--quiet"]) == 130
    assert not (out / "result.json").exists()
    assert AccumulatorGrid.load(out / "checkpoint" / "grid.npz").views("rice_box") == 10
    monkeypatch.setattr(twin.app.run, "run_survey", real)
    assert main(["survey", "--resume", str(out), "--quiet"]) == 0
    result = read_result(out)
    assert result["views"] == 24
    assert (out / "recording-resumed-1.rrd").is_file()
    resumed = AccumulatorGrid.load(out / "grid.npz").layer("rice_box")
    straight = AccumulatorGrid.load(reduced_run / "grid.npz").layer("rice_box")
    # The resumed robot reaches each stop by another path, so poses differ by millimetres.
    assert np.corrcoef(resumed.ravel(), straight.ravel())[0, 1] > 0.99
    assert (
        result["objects"]["rice_box"]["estimate_m"]
        == read_result(reduced_run)["objects"]["rice_box"]["estimate_m"]
    )


def test_random_target_placement_moves_the_truth(tmp_path, model_cache):
    config = write_config(tmp_path, model_cache, stops="[[2.5, 3.3]]", views_per_stop="2")
    out = tmp_path / "run"
    argv = [
        "survey",
        "--config",
        str(config),
        "--out",
        str(out),
        "--quiet",
        "--place-target",
        "random",
        "--seed",
        "3",
    ]
    assert main(argv) == 0
    truth = read_result(out)["objects"]["rice_box"]["truth_m"]
    assert math.dist(truth, (1.5, 5.0)) > 0.3


# -- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("replace", "match"),
    [
        ({"stops": "[[1.0]]"}, "mission.stops[0]: expected [x, y]"),
        ({"stops": "[]"}, "mission.stops: expected a list"),
        ({"cell_size": "-0.1"}, "grid.cell_size: expected a positive size"),
        ({"extent": "[0.0, 0.0, 4.55, 6.0]"}, "grid.extent: grid extent along x"),
        ({"fusion": '"bayes"'}, "grid.fusion: expected one of"),
        ({"fusion": '"logodds"'}, "grid.p_fp: logodds needs"),
        ({"views_per_stop": "0"}, "mission.views_per_stop: expected a whole number"),
        ({"turn": '"spin"'}, "mission.turn: expected one of pan, base"),
        ({"rerun": "stream"}, "run.rerun: expected one of"),
        ({"pose_source": '"gps"'}, "sim base pose source 'gps'"),
        ({"start": "[1.0, 2.0]"}, "mission.start: expected [x, y, yaw_deg]"),
        ({"file": '"no_such_room.xml"'}, "scene.file: no scene file"),
    ],
)
def test_bad_configs_are_one_line_errors_naming_the_key(
    tmp_path, model_cache, capsys, replace, match
):
    config = write_config(tmp_path, model_cache, **replace)
    code = main(["survey", "--config", str(config), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert match in err and len(err.splitlines()) == 1


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (("[mission]", "[mission]\nstopz = 1"), "mission.stopz: unknown key"),
        (("[grid]", "[grid\n"), "not valid TOML"),
    ],
)
def test_unknown_keys_and_broken_toml_are_named(tmp_path, model_cache, edit, match):
    path = tmp_path / "bad.toml"
    path.write_text(write_config(tmp_path, model_cache).read_text().replace(*edit))
    with pytest.raises(ConfigError, match=match):
        load_config(path)


def test_an_unknown_device_type_is_named_with_the_known_ones(tmp_path, model_cache):
    from twin.app.factory import build_robot

    path = tmp_path / "bad.toml"
    text = write_config(tmp_path, model_cache).read_text()
    path.write_text(text.replace('type = "sim"', 'type = "warp"', 1))
    with pytest.raises(InputError, match=r"robot\.camera\.type: unknown type 'warp'; use one of"):
        build_robot(load_config(path))


def test_folders_are_never_overwritten_and_resume_needs_a_run(tmp_path, reduced_run, capsys):
    assert main(["survey", "--out", str(reduced_run), "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["survey", "--resume", str(tmp_path), "--quiet"]) == 2
    assert "holds no survey to resume" in capsys.readouterr().err
