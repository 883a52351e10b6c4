"""The twin's imperfect camera: each effect does what it says and only that, off is the plain
renderer bit for bit, a rendered straight edge bends as the lens says, and runs reproduce."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

# isort: off
import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
import mujoco

# isort: on
from twin.app.config import load_config
from twin.app.factory import sim_camera_parts
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.sim.camera_effects import CameraEffects, EffectSettings, vcc4_lens
from twin.sim.robot import SimCamera, SimRobot
from twin.sim.world import World

LENS = vcc4_lens()
IDEAL = EffectSettings.ideal()
GOLDEN = Path(__file__).parent / "data" / "sim_golden_living_room.png"
GOLDEN_POSE = Pose2D(2.5, 3.3, math.radians(134.0))  # tests/test_sim.py's golden frame


def only(**on) -> EffectSettings:
    """Every effect off but the ones named."""
    return replace(IDEAL, **on)


def flat(value, size=(240, 320)) -> np.ndarray:
    return np.full((*size, 3), value, np.uint8)


# -- each effect alone, on synthetic frames ------------------------------------------------------


def test_ideal_settings_change_nothing() -> None:
    image = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    depth = np.random.default_rng(1).random((240, 320)).astype(np.float32)
    out, out_depth = CameraEffects(IDEAL, 320, 240).apply(image, depth, np.random.default_rng(2))
    assert np.array_equal(out, image) and np.array_equal(out_depth, depth)


def luma_of(image: np.ndarray) -> float:
    return float(image.astype(float).mean(axis=(0, 1)) @ [0.299, 0.587, 0.114])


def test_auto_exposure_brings_the_mean_to_its_target_with_a_lag_and_clips() -> None:
    effects = CameraEffects(only(auto_exposure=True), 320, 240)
    rng = np.random.default_rng(0)
    dark = flat((40, 50, 30))
    out, _ = effects.apply(dark, None, rng)
    assert luma_of(out) == pytest.approx(0.45 * 255, abs=1.0)  # the first frame starts settled
    assert out[0, 0, 0] / out[0, 0, 1] == pytest.approx(40 / 50, rel=0.02)  # one gain for all
    # the light doubles: 0.1 s later the gain has moved 1 - exp(-0.1 / 0.3) = 28 % of the way
    bright = flat((80, 100, 60))
    out, _ = effects.apply(bright, None, rng, dt=0.1)
    g_old, g_new = 0.45 * 255 / luma_of(dark), 0.45 * 255 / luma_of(bright)
    keep = math.exp(-0.1 / 0.3)
    expected = math.exp(math.log(g_new) + (math.log(g_old) - math.log(g_new)) * keep)
    assert out[120, 160, 1] == pytest.approx(100 * expected, abs=1.0)
    assert out[120, 160, 1] > 100 * g_new + 20  # still too bright: the gain lags
    out, _ = effects.apply(bright, None, rng, dt=5.0)  # settled again
    assert out[120, 160, 1] == pytest.approx(100 * g_new, abs=1.0)
    # a highlight in a dark frame clips once the gain lifts the rest
    dark[:20] = 250
    out, _ = effects.apply(dark, None, rng, dt=5.0)
    assert np.all(out[:20] == 255) and out[100, 0, 1] > 50


def test_white_balance_pulls_a_cast_toward_grey_partly_and_leaves_its_own() -> None:
    effects = CameraEffects(only(white_balance=True), 320, 240)
    rng = np.random.default_rng(0)
    warm = flat((150, 120, 90))
    out, _ = effects.apply(warm, None, rng)
    r, g, b = out[0, 0].astype(float)
    assert g == 120  # green is the reference: brightness stays
    assert r / g == pytest.approx(150 / 120 * (120 / 150) ** 0.8 * 1.03, rel=0.01)
    assert b / g == pytest.approx(90 / 120 * (120 / 90) ** 0.8 * 0.97, rel=0.01)
    # a grey frame gets exactly the residual cast
    effects.reset()
    out, _ = effects.apply(flat(100), None, rng)
    assert tuple(out[0, 0]) == (103, 100, 97)
    # the light turns cold: a video frame later the gains have moved 1 - exp(-1/30) = 3 % of
    # the way to the cold scene's (1 s time constant)
    out, _ = effects.apply(flat((90, 120, 150)), None, rng)
    moved = 1.0 - math.exp(-1.0 / 30.0)
    assert out[0, 0, 0] == pytest.approx(90 * (120 / 90) ** (0.8 * moved) * 1.03, abs=0.6)
    out, _ = effects.apply(flat((90, 120, 150)), None, rng, dt=10.0)
    assert out[0, 0, 0] == pytest.approx(90 * (120 / 90) ** 0.8 * 1.03, abs=0.6)


def test_noise_is_shot_plus_read_noise_seeded_and_unbiased() -> None:
    effects = CameraEffects(only(noise=True), 320, 240)
    grey = flat(128)
    out, _ = effects.apply(grey, None, np.random.default_rng(5))
    sigma = math.sqrt(1.0 + 0.02 * 128)
    assert out.astype(float).std() == pytest.approx(sigma, rel=0.05)
    assert out.astype(float).mean() == pytest.approx(128, abs=0.05)
    dark = CameraEffects(only(noise=True), 320, 240).apply(flat(10), None, np.random.default_rng(5))
    assert dark[0].astype(float).std() < 0.75 * sigma  # shot noise grows with the signal
    again, _ = CameraEffects(only(noise=True), 320, 240).apply(grey, None, np.random.default_rng(5))
    other, _ = CameraEffects(only(noise=True), 320, 240).apply(grey, None, np.random.default_rng(6))
    assert np.array_equal(out, again) and not np.array_equal(out, other)


def edge_width(profile: np.ndarray) -> float:
    """10-90 % rise of a dark-to-bright step, pixels."""
    lo, hi = profile.min(), profile.max()
    above = lambda level: np.argmax(profile >= lo + level * (hi - lo))  # noqa: E731
    return float(above(0.9) - above(0.1))


def test_motion_blur_smears_along_the_turn_by_rate_exposure_and_focal_length() -> None:
    effects = CameraEffects(only(motion_blur=True), 320, 240)
    step = flat(30)
    step[:, 160:] = 220
    still, _ = effects.apply(step, None, np.random.default_rng(0), (0.0, 0.0))
    assert np.array_equal(still, step)
    rate = math.radians(90.0)  # the VC-C4's top pan speed
    length = rate * 0.01667 * (160 / math.tan(math.radians(22.5)))  # about 10 px
    assert effects.blur_length((rate, 0.0)) == pytest.approx((length, 0.0))
    panned, _ = effects.apply(step, None, np.random.default_rng(0), (rate, 0.0))
    assert edge_width(panned[120, :, 0].astype(float)) == pytest.approx(0.8 * length, abs=1.5)
    assert np.array_equal(panned[:, :140], step[:, :140])  # only near the edge
    tilted, _ = effects.apply(step, None, np.random.default_rng(0), (0.0, rate))
    assert np.array_equal(tilted, step)  # a tilt smears along columns: a vertical edge stays


def test_jpeg_and_the_analog_look_are_mild_and_only_themselves() -> None:
    image = np.ascontiguousarray(cv2.imread(str(GOLDEN))[..., ::-1])  # a rendered room
    coded, _ = CameraEffects(only(jpeg_quality=80), 320, 240).apply(
        image, None, np.random.default_rng(0)
    )
    psnr = 10 * math.log10(255**2 / np.mean((coded.astype(float) - image) ** 2))
    assert 25.0 < psnr < 60.0
    analog, _ = CameraEffects(only(analog=True), 320, 240).apply(
        image, None, np.random.default_rng(0)
    )
    luma = lambda im: cv2.cvtColor(im, cv2.COLOR_RGB2YCrCb)[..., 0].astype(float)  # noqa: E731
    chroma = lambda im: cv2.cvtColor(im, cv2.COLOR_RGB2YCrCb)[..., 1:].astype(float)  # noqa: E731
    assert np.abs(luma(analog) - luma(image)).mean() < 3.0  # luma kept (to rounding)
    # chroma loses detail along the line only: across a block edge in x, not in y
    assert (
        np.abs(np.diff(chroma(analog), axis=1)).sum()
        < 0.8 * np.abs(np.diff(chroma(image), axis=1)).sum()
    )


def test_a_frame_of_the_wrong_size_is_refused_in_one_line() -> None:
    effects = CameraEffects(only(lens=LENS), 320, 240)
    with pytest.raises(InputError, match="canvas_size"):
        effects.apply(flat(0), None, np.random.default_rng(0))


# -- in the twin --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def room() -> SimRobot:
    return SimRobot(World("living_room"), GOLDEN_POSE)


def grab(robot: SimRobot, model: CameraModel, effects=None, seed=0, n=1):
    camera = SimCamera(robot, model, effects=effects, seed=seed)
    with camera:
        return [camera.grab() for _ in range(n)]


def test_effects_off_is_the_plain_renderer_bit_for_bit(room: SimRobot) -> None:
    plain = grab(room, CameraModel())[0]
    off = grab(room, CameraModel(), CameraEffects(IDEAL, 320, 240))[0]
    assert np.array_equal(off.image, plain.image) and np.array_equal(off.depth, plain.depth)
    config = load_config(None, overrides=('robot.camera.effects="ideal"',))
    model, effects = sim_camera_parts(config.devices["camera"].options, room)
    assert effects is None and model.lens is None
    assert model.hfov == pytest.approx(CameraModel().hfov, abs=1e-6)
    golden = cv2.imread(str(GOLDEN))[..., ::-1]
    assert np.abs(plain.image.astype(float) - golden).mean() < 3.0  # test_sim's tolerance


def test_the_lens_bends_colour_and_depth_alike_and_depth_stays_true(room: SimRobot) -> None:
    true = CameraModel.with_lens(320, 240, LENS)
    frame = grab(room, true, CameraEffects(only(lens=LENS), 320, 240))[0]
    assert frame.image.shape == (240, 320, 3) and frame.depth.shape == (240, 320)
    # nearest sampling: every depth is one the renderer drew (no blend of two surfaces)
    effects = CameraEffects(only(lens=LENS), 320, 240)
    camera = SimCamera(room, true, effects=effects)
    with camera:
        _, canvas_depth = camera._render_canvas(room.world.data)
    drawn = canvas_depth[np.isfinite(canvas_depth)]
    seen = frame.depth[np.isfinite(frame.depth)]
    assert np.isin(seen, drawn).all()
    # and the MJCF camera's own field is restored after the wider render
    assert float(room.world.model.cam_fovy[room.camera_id]) == pytest.approx(34.5159)


def test_seeded_frames_reproduce_and_seeds_differ(room: SimRobot) -> None:
    settings = EffectSettings(lens=LENS)
    true = CameraModel.with_lens(320, 240, LENS)
    a = grab(room, true, CameraEffects(settings, 320, 240), seed=4, n=2)
    b = grab(room, true, CameraEffects(settings, 320, 240), seed=4, n=2)
    c = grab(room, true, CameraEffects(settings, 320, 240), seed=5)
    assert all(np.array_equal(x.image, y.image) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0].image, c[0].image)
    assert not np.array_equal(a[0].image, a[1].image)  # fresh noise each frame


def test_the_realistic_camera_is_the_default_and_its_model_is_the_true_lens(room) -> None:
    model, effects = sim_camera_parts(load_config(None).devices["camera"].options, room)
    assert effects is not None and model.lens == effects.settings.lens
    assert math.degrees(model.hfov) == pytest.approx(47.5)
    assert effects.settings == EffectSettings(lens=model.lens)  # the documented defaults


# -- a straight edge through the lens -----------------------------------------------------------


def corner_rows(image: np.ndarray) -> np.ndarray | None:
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    found, corners = cv2.findChessboardCorners(gray, (9, 6))
    if not found:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), crit).reshape(6, 9, 2)


def straightness(points: np.ndarray) -> float:
    """The bow of a row of points (pixels): the middle point's distance from the chord through
    the first and last."""
    chord = points[-1] - points[0]
    normal = np.array([-chord[1], chord[0]]) / np.linalg.norm(chord)
    return float(abs((points[len(points) // 2] - points[0]) @ normal))


def test_a_rendered_straight_edge_bends_as_the_lens_says() -> None:
    """The chessboard's rows are straight lines in the world. Put the board high in the frame
    (where barrel distortion bows horizontal lines most): through the ideal camera they stay
    straight, through the twin's lens they bow, and undistorted by the lens they are straight
    again to a tenth of a pixel."""
    from twin.app.calibrate import _board_mover, _rotation

    robot = SimRobot(World("scenes/calibration_board.xml"), Pose2D(0.0, 0.0, 0.0))
    move = _board_mover(robot)
    move(np.array([0.0, 0.19, -1.25]), _rotation(0.0, 0.0, 0.0))
    ideal = corner_rows(grab(robot, CameraModel())[0].image)
    bent = corner_rows(grab(robot, CameraModel.with_lens(320, 240, LENS),
                            CameraEffects(only(lens=LENS), 320, 240))[0].image)  # fmt: skip
    assert ideal is not None and bent is not None
    top_ideal, top_bent = ideal[np.argmin(ideal[:, 0, 1])], bent[np.argmin(bent[:, 0, 1])]
    assert straightness(top_ideal) < 0.15
    assert straightness(top_bent) > 0.6  # about 0.9 px of barrel bow here
    x, y = LENS.pixel_to_normalized(top_bent[:, 0], top_bent[:, 1])
    assert straightness(np.stack([x, y], axis=1) * LENS.fx) < 0.15


@pytest.mark.parametrize(("lensed", "tilt_deg"), [(False, 20.0), (True, -15.0), (True, 25.0)])
def test_pixel_rays_point_at_rendered_corners_with_the_head_tilted(lensed, tilt_deg) -> None:
    """Rays through rendered geometry: the chessboard's inner corners are known points in the
    world; the rays ``pixel_rays`` gives for the pixels where they were found point at them
    (from the optical centre, with the head panned and tilted), to 0.04 degrees."""
    from twin.app.calibrate import _board_mover, _rotation

    robot = SimRobot(World("scenes/calibration_board.xml"), Pose2D(0.0, 0.0, 0.3))
    pan, tilt = math.radians(10.0), math.radians(tilt_deg)
    pan, tilt = robot.move_head(pan, tilt)  # where the servos settled (to 0.2 deg)
    _board_mover(robot)(np.array([0.1, -0.05, -1.3]), _rotation(0.3, -0.2, 0.1))
    model = CameraModel.with_lens(320, 240, LENS) if lensed else CameraModel()
    effects = CameraEffects(only(lens=LENS), 320, 240) if lensed else None
    corners = corner_rows(grab(robot, model, effects)[0].image)
    assert corners is not None
    pixels = corners.reshape(-1, 2) + 0.5  # OpenCV's pixel centres -> edge coordinates
    bearing, elevation = model.pixel_rays(pixels[:, 0], pixels[:, 1], tilt)
    # the truth: each inner corner's world point seen from the optical centre
    data, board = robot.world.data, robot.world.model.body("calibration_board").id
    mocap = robot.world.model.body_mocapid[board]
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, data.mocap_quat[mocap])
    i, j = np.meshgrid(np.arange(9) - 4.0, np.arange(6) - 2.5)
    local = np.stack([i.ravel() * 0.06, j.ravel() * 0.06, np.full(54, 0.005)], axis=1)
    points = data.mocap_pos[mocap] + local @ rotation.reshape(3, 3).T
    ray = points - robot.camera_position()
    heading = robot.truth_pose().yaw + robot.head()[0]
    true_bearing = np.arctan2(ray[:, 1], ray[:, 0]) - heading
    true_elevation = np.arctan2(ray[:, 2], np.hypot(ray[:, 0], ray[:, 1]))
    seen = np.stack([bearing, elevation], axis=1)[:, None, :]
    truth = np.stack([true_bearing, true_elevation], axis=1)[None, :, :]
    nearest = np.degrees(np.linalg.norm(seen - truth, axis=2).min(axis=1))
    assert nearest.max() < 0.04  # 0.26 px at the lens's focal length


def test_a_restarted_camera_sees_what_a_fresh_one_does(room: SimRobot) -> None:
    """A batch reuses its world between runs: restart puts the noise, exposure and white
    balance back to power-on, so a run does not depend on the runs before it."""
    true = CameraModel.with_lens(320, 240, LENS)
    camera = SimCamera(room, true, effects=CameraEffects(EffectSettings(lens=LENS), 320, 240))
    with camera:
        first = camera.grab().image
        camera.grab()
        camera.restart()
        again = camera.grab().image
        camera.restart(seed=9)
        other = camera.grab().image
    assert np.array_equal(first, again) and not np.array_equal(first, other)


def test_a_world_reset_restarts_the_camera_by_itself() -> None:
    robot = SimRobot(World("living_room"), GOLDEN_POSE)
    true = CameraModel.with_lens(320, 240, LENS)
    camera = SimCamera(robot, true, effects=CameraEffects(EffectSettings(lens=LENS), 320, 240))
    with camera:
        first = camera.grab().image
        robot.advance(0.5)
        camera.grab()
        robot.world.reset()
        robot.place(GOLDEN_POSE)
        assert np.array_equal(camera.grab().image, first)
        # an episode that repeats the last one grabs at the very same world time
        robot.advance(0.5)
        second = camera.grab().image
        robot.world.reset()
        robot.place(GOLDEN_POSE)
        camera.grab()
        robot.advance(0.5)
        assert np.array_equal(camera.grab().image, second)
    assert camera._watch not in robot.listeners  # closing stops watching
