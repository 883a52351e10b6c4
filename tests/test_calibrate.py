"""``twin calibrate`` against the closest stand-in for a real camera: the twin's realistic camera
(its VC-C4 lens, noise, JPEG) looking at a chessboard that moves through seeded poses. The
calibration must find the true lens, and wedges computed through it must agree with the true
ones; bad inputs are one-line errors."""

from __future__ import annotations

import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

# isort: off
import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)

# isort: on
from twin.app.calibrate import (
    Calibration,
    calibrate,
    frames_from_camera,
    parse_pattern,
    with_calibration,
)
from twin.app.config import ConfigError, load_config
from twin.app.factory import build_camera, configured_lens
from twin.cli import main
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.resources import scenes_dir

SPANS = np.array([[u, u + 32.0] for u in range(0, 289, 16)])  # the detector's patch columns


@pytest.fixture(scope="module")
def grabbed() -> tuple[list[np.ndarray], CameraModel]:
    """20 frames of the board from the twin's default (realistic) camera, and its true model."""
    config = load_config("calibration_board")
    camera, context = build_camera(config)
    with camera:
        frames = frames_from_camera(camera, context.sim_in_use, 20, 0.0, 0, lambda _: None)
    return frames, camera.model


@pytest.fixture(scope="module")
def result(grabbed) -> Calibration:
    return calibrate(grabbed[0], (9, 6), 0.06)


def test_the_calibration_recovers_the_twins_true_lens(result: Calibration, grabbed) -> None:
    true = grabbed[1]
    assert result.views >= 15 and result.rms_px < 0.3  # noise and JPEG: well under a pixel
    assert math.degrees(abs(result.camera.hfov - true.hfov)) < 1.0
    assert math.degrees(abs(result.camera.vfov - true.vfov)) < 1.0
    # k1 within 0.01 (5 %): at the frame's r <= 0.56 a change of k1 by 0.01 that k2 half
    # compensates moves the edge pixels by under 0.3 px, the accuracy of the corners themselves
    assert abs(result.lens.k1 - true.lens.k1) < 0.01
    assert abs(result.lens.cx - true.lens.cx) < 1.0 and abs(result.lens.cy - true.lens.cy) < 1.0
    # the whole mapping: every pixel's ray within 0.5 px of the truth's
    u, v = np.meshgrid(np.arange(0.0, 321.0, 10.0), np.arange(0.0, 241.0, 10.0))
    x, y = result.camera.normalized(u, v)
    tu, tv = true.lens.normalized_to_pixel(x, y)
    assert np.hypot(tu + 0.5 - u, tv + 0.5 - v).max() < 0.5


def test_wedges_through_the_calibrated_lens_agree_with_the_true_ones(result, grabbed) -> None:
    true = grabbed[1]
    pose = Pose2D(1.0, 2.0, 0.4)
    for tilt in (0.0, math.radians(-20.0)):
        got = result.camera.wedges(pose, 0.3, SPANS, tilt=tilt)
        want = true.wedges(pose, 0.3, SPANS, tilt=tilt)
        # 0.1 degree: a 0.1 m grid cell spans 1.9 degrees at 3 m
        assert np.degrees(np.abs(got - want)).max() < 0.1
    # while the ideal 45-degree pinhole the survey assumed before is off by degrees at the edges
    assert np.degrees(np.abs(CameraModel().wedges(pose, 0.3, SPANS) - want)).max() > 1.0


def test_the_command_writes_into_the_config_keeping_comments_and_the_twin_uses_it(tmp_path):
    config = tmp_path / "robot.toml"
    text = (scenes_dir() / "calibration_board.toml").read_text()
    text = text.replace(
        'file = "calibration_board.xml"', f'file = "{scenes_dir()}/calibration_board.xml"'
    )
    config.write_text(text)
    assert main(["calibrate", "--config", str(config), "--frames", "8"]) == 0
    written = config.read_text()
    assert written.count("#") == text.count("#") + 1  # every comment kept, one note added
    camera = tomllib.loads(written)["robot"]["camera"]
    assert len(camera["intrinsics"]) == 4 and len(camera["distortion"]) == 5
    # a second calibration replaces the lines (and the note) instead of adding more
    assert main(["calibrate", "--config", str(config), "--frames", "8", "--seed", "1"]) == 0
    again = config.read_text()
    assert again.count("intrinsics") == 1 and again.count("# calibrated by") == 1
    loaded = load_config(config, overrides=('robot.camera.lens_model="calibrated"',))
    camera, _ = build_camera(loaded)
    assert camera.model.lens.intrinsics == pytest.approx(
        tomllib.loads(again)["robot"]["camera"]["intrinsics"]
    )


def test_the_toml_edit_replaces_a_multiline_value_and_keeps_its_neighbours(result) -> None:
    text = (
        '# my robot\n[robot.camera]  # the VC-C4\ntype = "opencv"\nintrinsics = [\n  1, 2,\n'
        '  3, 4,\n]  # old\nwidth = 320\n\n[robot.base]\ntype = "arcos"\n'
    )
    new = with_calibration(text, result, "test")
    data = tomllib.loads(new)
    assert data["robot"]["camera"]["intrinsics"] == pytest.approx(list(result.lens.intrinsics))
    assert data["robot"]["camera"]["width"] == 320 and data["robot"]["base"]["type"] == "arcos"
    assert "# my robot" in new and "# the VC-C4" in new and "# old" in new
    with pytest.raises(InputError, match=r"no \[robot.camera\]"):
        with_calibration("[robot.base]\ntype = 'sim'\n", result, "test")


def test_a_calibrated_lens_in_a_config_is_checked_with_the_device_and_remedy() -> None:
    with pytest.raises(ConfigError, match=r"opencv camera 0: .*not both; run `twin calibrate"):
        configured_lens("opencv camera 0", 320, 240, (300.0, 300.0, 160.0, 120.0), None)
    with pytest.raises(ConfigError, match="do not fit a 320x240 image"):
        configured_lens("opencv camera 0", 320, 240, (600.0, 600.0, 320.0, 240.0), (0,) * 5)
    lens = configured_lens("x", 320, 240, (300.0, 300.0, 160.0, 120.0), (-0.2, 0, 0, 0, 0))
    assert lens is not None and lens.k1 == -0.2
    with pytest.raises(ConfigError, match='lens_model = "calibrated" needs intrinsics'):
        build_camera(
            load_config("calibration_board", overrides=('robot.camera.lens_model="calibrated"',))
        )


def test_bad_inputs_are_one_line_errors(tmp_path, capsys) -> None:
    def error(*argv: str) -> str:
        assert main(["calibrate", *argv]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1
        return lines[0]

    assert "no such folder" in error("--images", str(tmp_path / "missing"))
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "no images" in error("--images", str(empty))
    shutil.copy(Path(__file__).parent / "data" / "sim_golden_living_room.png", empty / "room.png")
    assert "found in 0 of 1 frames" in error("--images", str(empty))
    assert "shipped config" in error("--config", "calibration_board")
    assert "COLSxROWS" in error("--pattern", "nine", "--images", str(empty))
    with pytest.raises(InputError):
        parse_pattern("1x6")


def test_calibration_from_a_folder_of_images(grabbed, tmp_path, capsys) -> None:
    import cv2

    for i, frame in enumerate(grabbed[0][:10]):
        cv2.imwrite(str(tmp_path / f"board_{i:02d}.png"), frame[..., ::-1])
    assert main(["calibrate", "--images", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "RMS reprojection error" in out and "field of view 47." in out
    assert "nothing written" in out
