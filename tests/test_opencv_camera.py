"""The OpenCV camera on a real capture backend (a video file stands in for the device), timed by
a ``ManualClock``: reconnect delays, read timeouts and frame stamps are virtual seconds."""

import cv2
import numpy as np
import pytest

import hardware.opencv_camera as opencv_camera
from hardware.opencv_camera import OpenCVCamera
from twin.core.clock import ManualClock
from twin.core.devices import ConnectionLostError, DeviceError, DeviceTimeoutError


def write_video(path, frames=8, size=(640, 480), bgr=(0, 40, 200)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, size)
    for _ in range(frames):
        writer.write(np.full((size[1], size[0], 3), bgr, np.uint8))
    writer.release()
    return path


def test_frames_are_rgb_resized_to_the_model_and_stamped_on_the_camera_clock(tmp_path):
    video = write_video(tmp_path / "red.avi")
    clock = ManualClock(42.0)
    with OpenCVCamera(str(video), clock=clock) as camera:
        frame = camera.grab()
        clock.advance(0.5)
        later = camera.grab()
        assert camera.now() == clock.now() == 42.5
    image = frame.image
    assert image.shape == (240, 320, 3)
    red, green, blue = image.reshape(-1, 3).mean(axis=0)
    assert red > 150 and blue < 40 and 20 < green < 60  # BGR (0, 40, 200) is orange-red
    assert (frame.timestamp, later.timestamp) == (42.0, 42.5)


def test_a_missing_device_or_unreadable_source_is_one_line(tmp_path):
    with pytest.raises(DeviceError, match="no such device or file; check the path"):
        OpenCVCamera(str(tmp_path / "video0")).connect()
    (tmp_path / "not_a_video.avi").write_bytes(b"junk")
    with pytest.raises(DeviceError, match="OpenCV cannot open it"):
        OpenCVCamera(str(tmp_path / "not_a_video.avi")).connect()


def test_the_camera_reconnects_when_the_device_comes_back_and_gives_up_when_it_does_not(tmp_path):
    video = write_video(tmp_path / "cam.avi", frames=3)
    clock = ManualClock()
    camera = OpenCVCamera(str(video), reconnect_attempts=2, reconnect_delay=0.5, clock=clock)
    with camera:
        camera.grab()  # reads the short stream to its end
        hidden = video.rename(tmp_path / "unplugged.avi")
        start = clock.now()
        with pytest.raises(ConnectionLostError, match="no frames after 2 reconnects"):
            camera.grab()
        assert clock.now() - start == pytest.approx(2 * 0.5)  # waited before each reopening
        hidden.rename(video)  # plugged in again
        assert camera.grab().image.shape == (240, 320, 3)
    assert camera.reconnects == 3


class StuckCapture:
    """A capture whose every grab and read takes ``seconds`` of the camera's clock."""

    seconds = 0.0
    clock: ManualClock

    def __init__(self, *args: object) -> None:
        pass

    def isOpened(self) -> bool:  # OpenCV's name
        return True

    def set(self, *args: object) -> bool:
        return True

    def grab(self) -> bool:
        self.clock.advance(self.seconds)
        return True

    def read(self) -> tuple[bool, np.ndarray]:
        self.clock.advance(self.seconds)
        return True, np.zeros((240, 320, 3), np.uint8)

    def release(self) -> None:
        pass


def test_a_grab_longer_than_four_read_timeouts_is_a_timeout(monkeypatch):
    clock = ManualClock()
    monkeypatch.setattr(opencv_camera.cv2, "VideoCapture", StuckCapture)
    monkeypatch.setattr(StuckCapture, "clock", clock, raising=False)
    with OpenCVCamera(0, read_timeout=1.0, clock=clock) as camera:
        monkeypatch.setattr(StuckCapture, "seconds", 1.0)  # 2 stale frames and a read: 3 s
        assert camera.grab().timestamp == clock.now() == 3.0
        monkeypatch.setattr(StuckCapture, "seconds", 1.5)  # 4.5 s, over 4 x 1 s: it hangs
        with pytest.raises(DeviceTimeoutError, match=r"grab a frame: took 4\.5 s"):
            camera.grab()


def test_a_calibrated_lens_from_the_config_is_the_cameras_model(tmp_path):
    """`twin calibrate` writes intrinsics and distortion into [robot.camera]; the camera built
    from that table carries them, so wedges go through the real lens, not the nominal 45 deg."""
    from twin.app.config import ConfigError, DeviceConfig
    from twin.app.device_types import OpenCVCameraOptions
    from twin.app.factory import opencv_camera as build
    from twin.core.geometry import CameraModel

    video = write_video(tmp_path / "red.avi")
    options = OpenCVCameraOptions(
        device=str(video),
        intrinsics=(377.0, 377.2, 161.9, 118.4),
        distortion=(-0.2, 0.03, 5e-4, -3e-4, 0.0),
    )
    camera = build(DeviceConfig("camera", "opencv", options), None)
    assert camera.model.lens is not None and camera.model.lens.k1 == -0.2
    assert camera.model.hfov == pytest.approx(np.radians(47.5), abs=np.radians(0.1))
    assert camera.model != CameraModel()
    nominal = build(DeviceConfig("camera", "opencv", OpenCVCameraOptions(str(video))), None)
    assert nominal.model == CameraModel()  # no calibration: the nominal pinhole as before
    half = OpenCVCameraOptions(device=str(video), intrinsics=(377.0, 377.2, 161.9, 118.4))
    with pytest.raises(ConfigError, match=f"opencv camera {video}: .*twin calibrate"):
        build(DeviceConfig("camera", "opencv", half), None)
