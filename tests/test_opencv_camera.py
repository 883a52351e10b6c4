"""The OpenCV camera on a real capture backend: a video file stands in for the device."""

import cv2
import numpy as np
import pytest

from hardware.opencv_camera import OpenCVCamera
from twin.core.devices import ConnectionLostError, DeviceError


def write_video(path, frames=8, size=(640, 480), bgr=(0, 40, 200)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, size)
    for _ in range(frames):
        writer.write(np.full((size[1], size[0], 3), bgr, np.uint8))
    writer.release()
    return path


def test_frames_are_rgb_and_resized_to_the_model(tmp_path):
    video = write_video(tmp_path / "red.avi")
    with OpenCVCamera(str(video)) as camera:
        image = camera.grab().image
    assert image.shape == (240, 320, 3)
    red, green, blue = image.reshape(-1, 3).mean(axis=0)
    assert red > 150 and blue < 40 and 20 < green < 60  # BGR (0, 40, 200) is orange-red


def test_a_missing_device_or_unreadable_source_is_one_line(tmp_path):
    with pytest.raises(DeviceError, match="no such device or file; check the path"):
        OpenCVCamera(str(tmp_path / "video0")).connect()
    (tmp_path / "not_a_video.avi").write_bytes(b"junk")
    with pytest.raises(DeviceError, match="OpenCV cannot open it"):
        OpenCVCamera(str(tmp_path / "not_a_video.avi")).connect()


def test_the_camera_reconnects_when_the_device_comes_back_and_gives_up_when_it_does_not(tmp_path):
    video = write_video(tmp_path / "cam.avi", frames=3)
    camera = OpenCVCamera(str(video), reconnect_attempts=2, reconnect_delay=0.01)
    with camera:
        camera.grab()  # reads the short stream to its end
        hidden = video.rename(tmp_path / "unplugged.avi")
        with pytest.raises(ConnectionLostError, match="no frames after 2 reconnects"):
            for _ in range(3):
                camera.grab()
        hidden.rename(video)  # plugged in again
        assert camera.grab().image.shape == (240, 320, 3)
    assert camera.reconnects >= 3
