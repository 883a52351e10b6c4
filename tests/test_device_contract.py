"""One contract, every implementation: what twin.core.devices promises, checked on each device.

Gymnasium-style: the same tests run against the MuJoCo sim devices, the OpenCV camera on a real
capture backend (a video file: no camera is attached here), and the serial hardware drivers
talking to their emulators over pseudo-terminals. A new device type joins by adding a factory.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator

import cv2
import numpy as np
import pytest

from twin.core.devices import Base, Camera, NotConnectedError, OutOfRangeError, PanTilt
from twin.core.geometry import Pose2D

DeviceFactory = Callable[[object], contextlib.AbstractContextManager]


# -- factories: each yields an unconnected device, and cleans up what it started -------------------


@contextlib.contextmanager
def sim_devices() -> Iterator:
    from twin.sim import make_sim_robot

    _sim, robot = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    yield robot


@contextlib.contextmanager
def sim_camera(tmp_path) -> Iterator[Camera]:
    with sim_devices() as robot:
        yield robot.camera


@contextlib.contextmanager
def sim_pantilt(tmp_path) -> Iterator[PanTilt]:
    with sim_devices() as robot:
        yield robot.pantilt


@contextlib.contextmanager
def sim_base(tmp_path) -> Iterator[Base]:
    with sim_devices() as robot:
        yield robot.base


@contextlib.contextmanager
def opencv_camera(tmp_path) -> Iterator[Camera]:
    from hardware.opencv_camera import OpenCVCamera

    video = tmp_path / "camera.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 15, (640, 480))
    for i in range(30):
        writer.write(np.full((480, 640, 3), 8 * i, np.uint8))
    writer.release()
    yield OpenCVCamera(str(video), reconnect_delay=0.01)


@contextlib.contextmanager
def serial_twins(wiring: str = "direct", time_scale: float = 4.0) -> Iterator:
    from twin.serial_twins.session import SerialTwins
    from twin.sim import make_sim_robot

    sim, _ = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    with SerialTwins(sim, time_scale=time_scale, vcc4_wiring=wiring) as twins:
        yield sim, twins


@contextlib.contextmanager
def vcc4_on_its_line(tmp_path) -> Iterator[PanTilt]:
    from hardware.vcc4 import VCC4

    with serial_twins() as (_, twins):
        yield VCC4.open(twins.vcc4_path)


@contextlib.contextmanager
def vcc4_on_the_aux_port(tmp_path) -> Iterator[PanTilt]:
    from hardware.arcos import ArcosBase
    from hardware.vcc4 import VCC4

    with serial_twins("aux") as (_, twins), ArcosBase.open(twins.arcos_path) as base:
        yield VCC4(base.aux_transport(1), answer_timeout=1.0)


@contextlib.contextmanager
def arcos_base(tmp_path) -> Iterator[Base]:
    from hardware.arcos import ArcosBase

    # Real time: a drive's duration is wall-clock time on the driver's side.
    with serial_twins(time_scale=1.0) as (sim, twins):
        yield ArcosBase.open(twins.arcos_path, start=sim.truth_pose())


CAMERAS = {"sim": sim_camera, "opencv": opencv_camera}
PANTILTS = {"sim": sim_pantilt, "vcc4": vcc4_on_its_line, "vcc4-aux": vcc4_on_the_aux_port}
BASES = {"sim": sim_base, "arcos": arcos_base}


@pytest.fixture(params=sorted(CAMERAS))
def camera(request, tmp_path):
    with CAMERAS[request.param](tmp_path) as device:
        yield device
        device.close()


@pytest.fixture(params=sorted(PANTILTS))
def pantilt(request, tmp_path):
    with PANTILTS[request.param](tmp_path) as device:
        yield device
        device.close()


@pytest.fixture(params=sorted(BASES))
def base(request, tmp_path):
    with BASES[request.param](tmp_path) as device:
        yield device
        device.close()


# -- every device ----------------------------------------------------------------------------------


def check_connect_lifecycle(device, use) -> None:
    """Work is refused before connect and after close; connect is idempotent; close too."""
    with pytest.raises(NotConnectedError, match=device.name):
        use(device)
    with device:
        device.connect()
        assert device.is_connected
        use(device)
    assert not device.is_connected
    device.close()
    with pytest.raises(NotConnectedError):
        use(device)


def test_a_camera_is_used_only_while_connected(camera):
    check_connect_lifecycle(camera, lambda d: d.grab())


def test_a_head_is_used_only_while_connected(pantilt):
    check_connect_lifecycle(pantilt, lambda d: d.position())


def test_a_base_is_used_only_while_connected(base):
    check_connect_lifecycle(base, lambda d: d.pose())


# -- cameras ---------------------------------------------------------------------------------------


def test_a_camera_delivers_rgb_frames_of_its_model_with_rising_timestamps(camera):
    with camera:
        frames = [camera.grab() for _ in range(3)]
    model = camera.model
    for frame in frames:
        assert frame.image.shape == (model.height, model.width, 3)
        assert frame.image.dtype == np.uint8
        assert math.isfinite(frame.timestamp)
    assert frames[0].timestamp <= frames[1].timestamp <= frames[2].timestamp
    assert 0 < model.hfov < math.pi


# -- pan-tilt heads --------------------------------------------------------------------------------


def test_a_head_reaches_angles_with_pan_positive_to_the_left(pantilt):
    with pantilt:
        for pan, tilt in [
            (math.radians(30), 0.0),
            (math.radians(-60), math.radians(10)),
            (0.0, 0.0),
        ]:
            reached = pantilt.move_to(pan, tilt)
            position = pantilt.position()
            for got in (reached, position):
                assert got[0] == pytest.approx(pan, abs=math.radians(1.0))
                assert got[1] == pytest.approx(tilt, abs=math.radians(1.0))
        pantilt.stop()


def test_a_head_refuses_angles_beyond_its_limits_and_stays_put(pantilt):
    with pantilt:
        pantilt.move_to(math.radians(20), 0.0)
        limits = pantilt.limits
        with pytest.raises(OutOfRangeError, match=pantilt.name):
            pantilt.move_to(limits.pan_max + math.radians(5), 0.0)
        with pytest.raises(OutOfRangeError):
            pantilt.move_to(0.0, limits.tilt_min - math.radians(5))
        assert pantilt.position()[0] == pytest.approx(math.radians(20), abs=math.radians(1.0))
    assert limits.pan_min <= -math.radians(90) and limits.pan_max >= math.radians(90)


# -- bases -----------------------------------------------------------------------------------------


def test_a_base_reports_the_pose_it_was_anchored_to(base):
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        pose = base.pose()
    assert pose.x == pytest.approx(2.5, abs=0.02) and pose.y == pytest.approx(3.3, abs=0.02)
    assert abs(pose.heading_error_to(Pose2D(0, 0, 0.0))) < math.radians(1.0)


def test_a_base_drives_forward_along_its_heading_and_turns_left_for_positive_rates(base):
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        moved = base.drive(0.2, 0.0, 1.0)
        assert moved.x - 2.5 == pytest.approx(0.2, rel=0.25)
        assert abs(moved.y - 3.3) < 0.03
        turned = base.drive(0.0, math.radians(30), 1.0)
        assert turned.heading_error_to(moved) == pytest.approx(-math.radians(30), rel=0.25)
        base.stop()


def test_a_base_goes_to_a_pose_within_5_cm_and_3_degrees(base):
    goal = Pose2D(2.0, 3.6, math.radians(120))
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        final = base.go_to(goal)
        pose = base.pose()
    for got in (final, pose):
        assert got.distance_to(goal) < 0.05
        assert abs(got.heading_error_to(goal)) < math.radians(3.0)
