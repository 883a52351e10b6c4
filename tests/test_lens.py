"""The lens in the core: OpenCV's distortion model, its inversion, and the camera model through
it (column bearings, tilt-aware wedges, pixel rays), against OpenCV, direct rotations and the
ideal pinhole's formulas."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.lens import Lens
from twin.sim.camera_effects import VCC4_DISTORTION, lens_for_field, vcc4_lens

VCC4 = vcc4_lens()
SPANS = np.array([[u, u + 32.0] for u in range(0, 289, 16)])  # the detector's patch columns


def frame_pixels(width: int = 320, height: int = 240, step: int = 8) -> tuple[np.ndarray, ...]:
    u, v = np.meshgrid(np.arange(-0.5, width, step), np.arange(-0.5, height, step))
    return u.ravel(), v.ravel()


def test_distortion_is_opencvs() -> None:
    x, y = np.meshgrid(np.linspace(-0.5, 0.5, 11), np.linspace(-0.4, 0.4, 9))
    points = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
    projected, _ = cv2.projectPoints(
        points, np.zeros(3), np.zeros(3), VCC4.matrix, np.array(VCC4.coefficients)
    )
    u, v = VCC4.normalized_to_pixel(x.ravel(), y.ravel())
    np.testing.assert_allclose(np.stack([u, v], axis=1), projected[:, 0], atol=1e-9)


def test_undistortion_inverts_the_distortion_over_the_whole_frame() -> None:
    u, v = frame_pixels()
    x, y = VCC4.pixel_to_normalized(u, v)
    back_u, back_v = VCC4.normalized_to_pixel(x, y)
    assert np.max(np.abs(back_u - u)) < 1e-9 and np.max(np.abs(back_v - v)) < 1e-9
    # and agrees with OpenCV's own (iterated to convergence)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    points = np.stack([u, v], axis=1)[:, None, :]
    coefficients = np.array(VCC4.coefficients)
    theirs = cv2.undistortPoints(points, VCC4.matrix, coefficients, criteria=criteria)[:, 0]
    np.testing.assert_allclose(np.stack([x, y], axis=1), theirs, atol=1e-7)


def test_undistortion_far_outside_the_lens_is_an_error() -> None:
    with pytest.raises(InputError, match="did not converge"):
        Lens(100.0, 100.0, 0.0, 0.0, k1=-0.4).undistort(np.array([3.0]), np.array([0.0]))


def test_a_lens_is_built_from_opencv_and_config_lists_and_checked() -> None:
    same = Lens.from_opencv(VCC4.matrix, np.array([*VCC4.coefficients, 0.0, 0.0, 0.0]))
    assert same == VCC4
    assert Lens.from_lists(VCC4.intrinsics, VCC4.coefficients) == VCC4
    with pytest.raises(InputError, match="k1, k2, p1, p2, k3"):
        Lens.from_opencv(VCC4.matrix, np.array([0.1, 0, 0, 0, 0, 0.2]))
    with pytest.raises(InputError, match="intrinsics"):
        Lens.from_lists((1.0, 2.0), VCC4.coefficients)
    with pytest.raises(InputError, match="positive"):
        Lens(-1.0, 1.0, 0.0, 0.0)


# -- the camera model through a lens ------------------------------------------------------------


def test_without_a_lens_the_camera_is_todays_pinhole() -> None:
    """The default model is untouched: the old formulas, bit for bit."""
    camera = CameraModel()
    f = 160.0 / math.tan(math.radians(22.5))
    u = np.linspace(0.0, 320.0, 41)
    assert np.array_equal(camera.column_bearing(u), np.arctan((160.0 - u) / f))
    pose = Pose2D(1.0, 2.0, 0.3)
    wedges = camera.wedges(pose, 0.2, SPANS)
    axis = 0.5
    want = np.stack([axis + np.arctan((160.0 - SPANS[:, 1]) / f),
                     axis + np.arctan((160.0 - SPANS[:, 0]) / f)], axis=1)  # fmt: skip
    assert np.array_equal(wedges, want)


def test_an_ideal_lens_gives_the_pinhole_figures() -> None:
    plain = CameraModel()
    lensed = CameraModel.with_lens(320, 240, Lens.pinhole(320, 240, plain.hfov))
    assert lensed.hfov == pytest.approx(plain.hfov, abs=1e-12)
    assert lensed.vfov == pytest.approx(plain.vfov, abs=1e-12)
    pose = Pose2D(0.0, 0.0, 1.0)
    np.testing.assert_allclose(lensed.wedges(pose, 0.1, SPANS), plain.wedges(pose, 0.1, SPANS),
                               atol=1e-12)  # fmt: skip
    u, v = frame_pixels()
    for tilt in (0.0, 0.4):
        np.testing.assert_allclose(
            lensed.pixel_rays(u, v, tilt), plain.pixel_rays(u, v, tilt), atol=1e-12
        )


def test_level_pinhole_rays_are_the_textbook_angles() -> None:
    camera = CameraModel()
    u, v = frame_pixels()
    bearing, elevation = camera.pixel_rays(u, v, 0.0)
    f = camera.focal_px
    np.testing.assert_allclose(bearing, np.arctan((160.0 - u) / f), atol=1e-12)
    np.testing.assert_allclose(elevation, np.arctan2(120.0 - v, np.hypot(f, u - 160.0)), atol=1e-12)


def direction(bearing: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """Unit vectors (n, 3) in the head's frame: x forward at pan 0, y left, z up."""
    return np.stack([np.cos(elevation) * np.cos(bearing), np.cos(elevation) * np.sin(bearing),
                     np.sin(elevation)], axis=1)  # fmt: skip


@pytest.mark.parametrize("tilt_deg", [-25.0, 0.0, 30.0, 70.0])
def test_pixel_rays_invert_a_direct_rotation_through_the_lens(tilt_deg: float) -> None:
    """Brute force the other way: rotate known rays into the tilted camera with a rotation
    matrix, project them through OpenCV, and get the rays back from pixel_rays."""
    tilt = math.radians(tilt_deg)
    rng = np.random.default_rng(3)
    bearing = rng.uniform(-0.35, 0.35, 200)
    elevation = tilt + rng.uniform(-0.28, 0.28, 200)
    rays = direction(bearing, elevation)
    # the camera's axes in the head frame: right, down, forward (tilted up about -y)
    c, s = math.cos(tilt), math.sin(tilt)
    rotation = np.array([[0.0, -1.0, 0.0], [s, 0.0, -c], [c, 0.0, s]])
    in_camera = rays @ rotation.T
    pixels, _ = cv2.projectPoints(
        in_camera, np.zeros(3), np.zeros(3), VCC4.matrix, np.array(VCC4.coefficients)
    )
    camera = CameraModel.with_lens(320, 240, VCC4)
    got_b, got_e = camera.pixel_rays(pixels[:, 0, 0] + 0.5, pixels[:, 0, 1] + 0.5, tilt)
    np.testing.assert_allclose(got_b, bearing, atol=1e-9)
    np.testing.assert_allclose(got_e, elevation, atol=1e-9)


@pytest.mark.parametrize(("lensed", "tilt_deg"), [(True, 0.0), (False, 35.0), (True, 35.0)])
def test_a_wedge_covers_every_pixel_of_its_column_and_no_more(lensed: bool, tilt_deg: float):
    camera = CameraModel.with_lens(320, 240, VCC4) if lensed else CameraModel()
    tilt = math.radians(tilt_deg)
    wedges = camera.wedges(Pose2D(0.0, 0.0, 0.0), 0.0, SPANS, tilt=tilt)
    for (u0, u1), (a0, a1) in zip(SPANS, wedges, strict=True):
        u, v = np.meshgrid(np.linspace(u0, u1, 33), np.linspace(0.0, 240.0, 481))
        bearing, _ = camera.pixel_rays(u, v, tilt)
        # covers (to 1e-6 rad: the extreme of a bulging edge may fall between sampled rows)
        assert bearing.min() >= a0 - 1e-6 and bearing.max() <= a1 + 1e-6
        assert bearing.min() == pytest.approx(a0, abs=2e-5)  # tight: no wider than the column
        assert bearing.max() == pytest.approx(a1, abs=2e-5)
    # a distorted or tilted column is wider than the level pinhole's at the frame's edge
    level = CameraModel().wedges(Pose2D(0.0, 0.0, 0.0), 0.0, SPANS)
    if not lensed:
        assert np.all(np.diff(wedges, axis=1) >= np.diff(level, axis=1) - 1e-12)


def test_wedges_over_some_rows_and_with_pose_and_pan() -> None:
    camera = CameraModel.with_lens(320, 240, VCC4)
    whole = camera.wedges(Pose2D(0.0, 0.0, 0.0), 0.0, SPANS, tilt=0.2)
    middle = camera.wedges(Pose2D(0.0, 0.0, 0.0), 0.0, SPANS, tilt=0.2, rows=(100.0, 140.0))
    assert np.all(middle[:, 0] >= whole[:, 0]) and np.all(middle[:, 1] <= whole[:, 1])
    assert np.any(np.diff(middle, axis=1) < np.diff(whole, axis=1) - 1e-4)
    turned = camera.wedges(Pose2D(3.0, 1.0, 0.5), 0.25, SPANS, tilt=0.2)
    np.testing.assert_allclose(turned, whole + 0.75, atol=1e-12)
    with pytest.raises(InputError, match="rows"):
        camera.wedges(Pose2D(0.0, 0.0, 0.0), 0.0, SPANS, rows=(100.0, 50.0))


def test_the_vcc4_lens_has_its_datasheet_field_and_barrel_distortion() -> None:
    camera = CameraModel.with_lens(320, 240, VCC4)
    assert math.degrees(camera.hfov) == pytest.approx(47.5, abs=1e-9)
    # barrel: the edges of the frame see further out than the pinhole of the same focal length
    edge = camera.column_bearing(np.array([0.0]))[0]
    assert edge > math.atan((VCC4.cx + 0.5) / VCC4.fx) + math.radians(0.4)
    # column_bearing (on the principal row) and bearing_column (where the level horizon's ray
    # lands) invert each other but for the tangential terms' bend of that row, 1e-4 px here
    u = np.linspace(0.0, 320.0, 17)
    np.testing.assert_allclose(camera.bearing_column(camera.column_bearing(u)), u, atol=1e-4)
    assert lens_for_field(640, 480, math.radians(47.5), VCC4_DISTORTION).fx == pytest.approx(
        2 * lens_for_field(320, 240, math.radians(47.5), VCC4_DISTORTION).fx, rel=1e-9
    )


def test_a_camera_whose_hfov_disagrees_with_its_lens_is_refused() -> None:
    with pytest.raises(InputError, match="with_lens"):
        CameraModel(320, 240, math.radians(45.0), VCC4)


@pytest.mark.parametrize("lensed", [False, True])
def test_ray_pixels_inverts_pixel_rays(lensed: bool) -> None:
    camera = CameraModel.with_lens(320, 240, VCC4) if lensed else CameraModel()
    u, v = frame_pixels()
    for tilt in (-0.3, 0.0, 0.5):
        back_u, back_v = camera.ray_pixels(*camera.pixel_rays(u, v, tilt), tilt)
        np.testing.assert_allclose(back_u, u, atol=1e-8)
        np.testing.assert_allclose(back_v, v, atol=1e-8)
    behind_u, _ = camera.ray_pixels(np.array([math.pi]), np.array([0.0]), 0.0)
    assert np.isnan(behind_u).all()
