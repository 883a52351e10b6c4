"""Camera model: pixel columns to bearings, and wedges in the map frame."""

import math

import numpy as np
import pytest

from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D, wrap_angle


def test_image_edges_see_half_the_field_of_view():
    camera = CameraModel(320, 240, math.radians(45))
    assert camera.column_bearing(0) == pytest.approx(math.radians(22.5))
    assert camera.column_bearing(320) == pytest.approx(-math.radians(22.5))
    assert camera.column_bearing(160) == pytest.approx(0.0)
    assert camera.bearing_column(camera.column_bearing(77.0)) == pytest.approx(77.0)


def test_vertical_fov_follows_from_square_pixels():
    camera = CameraModel(320, 240, math.radians(45))
    assert math.tan(camera.vfov / 2) == pytest.approx(math.tan(math.radians(22.5)) * 240 / 320)


def test_wedges_rotate_with_yaw_and_pan_and_leftmost_column_has_largest_bearings():
    camera = CameraModel()
    spans = np.array([[0, 20], [20, 40], [300, 320]])
    wedges = camera.wedges(Pose2D(1.0, 2.0, math.radians(90)), math.radians(30), spans)
    assert np.all(wedges[:, 0] < wedges[:, 1])
    assert wedges[0, 1] == pytest.approx(math.radians(120 + 22.5))
    assert wedges[-1, 0] == pytest.approx(math.radians(120 - 22.5))
    assert wedges[0, 0] == pytest.approx(wedges[1, 1])


def test_bad_camera_and_pose_input():
    with pytest.raises(InputError, match="pose must be finite"):
        Pose2D(math.nan, 0.0, 0.0)
    with pytest.raises(InputError, match="hfov"):
        CameraModel(hfov=math.pi)
    with pytest.raises(InputError, match="column_spans"):
        CameraModel().wedges(Pose2D(0, 0, 0), 0.0, np.array([[10, 5]]))


def test_wrap_angle():
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    np.testing.assert_allclose(wrap_angle(np.array([0.0, 2 * math.pi + 0.1])), [0.0, 0.1])


def test_compose_and_relative_are_inverse_rigid_transforms():
    import math

    from twin.core.geometry import Pose2D

    a = Pose2D(1.0, 2.0, math.radians(90.0))
    local = Pose2D(0.5, 0.0, math.radians(10.0))
    b = a.compose(local)
    assert (round(b.x, 9), round(b.y, 9), round(math.degrees(b.yaw), 9)) == (1.0, 2.5, 100.0)
    back = a.relative(b)
    assert (round(back.x, 9), round(back.y, 9), round(back.yaw, 9)) == (
        0.5,
        0.0,
        round(local.yaw, 9),
    )
