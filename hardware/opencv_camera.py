"""A real camera through OpenCV: a V4L2 device (index or /dev/videoN), a stream URL or a file.

Frames come out as the survey needs them: H x W x 3 uint8 RGB at the configured size (320x240
by default, resized if the device cannot deliver it), stamped at capture on the camera's clock
(``now()``: the system's monotonic clock unless a test injects its own). ``grab`` drops frames
the driver buffered before the call, so a frame is never older than the pan-tilt move that
preceded it. When the device stops delivering (unplugged, a stream
ends), ``grab`` reconnects a few times before it gives up with a one-line error.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import cv2
import numpy as np

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import Camera, ConnectionLostError, DeviceError, DeviceTimeoutError, Frame
from twin.core.geometry import CameraModel
from twin.core.lens import Lens

# How many buffered frames to discard before the one we keep (V4L2 keeps up to 4).
STALE_FRAMES = 2


class OpenCVCamera(Camera):
    """``device``: an index (0 = /dev/video0), a device path, a URL, or a video file.

    ``reconnect_delay`` and ``read_timeout`` are seconds of ``clock``, which also stamps the
    frames. ``lens``: the calibrated intrinsics and distortion, which the camera's model then
    carries (so wedges are computed through them) instead of the nominal ``hfov``. OpenCV's own
    open and read timeouts are real milliseconds inside the backend; the driver measures a grab
    on its clock and calls one longer than four read timeouts stuck."""

    def __init__(
        self,
        device: int | str,
        width: int = 320,
        height: int = 240,
        hfov: float = math.radians(45.0),
        name: str = "opencv camera",
        reconnect_attempts: int = 3,
        reconnect_delay: float = 0.5,
        read_timeout: float = 2.0,
        clock: Clock = SYSTEM_CLOCK,
        lens: Lens | None = None,
    ) -> None:
        self.device, self.clock = device, clock
        self.name = f"{name} {device}"
        # a calibrated lens (``twin calibrate``) replaces the nominal field of view
        self._model = (
            CameraModel(width, height, hfov)
            if lens is None
            else CameraModel.with_lens(width, height, lens)
        )
        self.reconnect_attempts = reconnect_attempts
        self.reconnect_delay = reconnect_delay
        self.read_timeout = read_timeout
        self._capture: cv2.VideoCapture | None = None
        self._connected = False  # what the user asked for; the capture may be down meanwhile
        self.reconnects = 0

    @property
    def model(self) -> CameraModel:
        return self._model

    @property
    def is_connected(self) -> bool:
        return self._connected

    def now(self) -> float:
        return self.clock.now()

    def connect(self) -> None:
        if self._capture is None:
            self._capture = self._open()
        self._connected = True

    def _open(self) -> cv2.VideoCapture:
        self._check_path()
        previous = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
        try:
            capture = cv2.VideoCapture(self.device, cv2.CAP_ANY, self._open_params())
        finally:
            cv2.utils.logging.setLogLevel(previous)
        if not capture.isOpened():
            capture.release()
            raise DeviceError(self.name, "open the camera", "OpenCV cannot open it",
                              "check the index or path ('twin hw probe' lists cameras) and that "
                              "no other program holds it")  # fmt: skip
        capture.set(cv2.CAP_PROP_FRAME_WIDTH, self._model.width)
        capture.set(cv2.CAP_PROP_FRAME_HEIGHT, self._model.height)
        capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        return capture

    def _open_params(self) -> list[int]:
        timeout_ms = int(1000 * self.read_timeout)
        return [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, timeout_ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC,
                timeout_ms]  # fmt: skip

    def _check_path(self) -> None:
        """Name the usual failures of a device path before OpenCV hides them."""
        if isinstance(self.device, int) or "://" in str(self.device):
            return
        path = Path(self.device)
        if not path.exists():
            raise DeviceError(self.name, "open the camera", "no such device or file",
                              "check the path; 'twin hw probe' lists the cameras")  # fmt: skip
        if not os.access(path, os.R_OK):
            raise DeviceError(self.name, "open the camera", "permission denied",
                              "add your user to the 'video' group and log in again")  # fmt: skip

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()
            self._capture = None
        self._connected = False

    def grab(self) -> Frame:
        self.require_connected("grab a frame")
        for attempt in range(self.reconnect_attempts + 1):
            if attempt:
                self._reopen()
            image = self._read_fresh() if self._capture is not None else None
            if image is not None:
                return Frame(self._to_rgb(image), self.clock.now())
        raise ConnectionLostError(self.name, "grab a frame",
                                  f"no frames after {self.reconnect_attempts} reconnects",
                                  "check the cable and that the device still exists")  # fmt: skip

    def _read_fresh(self) -> np.ndarray | None:
        assert self._capture is not None
        started = self.clock.now()
        for _ in range(STALE_FRAMES):
            if not self._capture.grab():
                return None
        ok, image = self._capture.read()
        took = self.clock.now() - started
        if took > 4 * self.read_timeout:
            raise DeviceTimeoutError(self.name, "grab a frame", f"took {took:.1f} s",
                                     "check the device's frame rate and exposure")  # fmt: skip
        return image if ok and image is not None and image.size else None

    def _reopen(self) -> None:
        """Release the capture and open the device again (it may have been replugged)."""
        if self._capture is not None:
            self._capture.release()
            self._capture = None
        self.clock.sleep(self.reconnect_delay)
        self.reconnects += 1
        try:
            self._capture = self._open()
        except DeviceError:
            self._capture = None  # still gone: the next attempt tries again

    def _to_rgb(self, image: np.ndarray) -> np.ndarray:
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        size = (self._model.width, self._model.height)
        if (image.shape[1], image.shape[0]) != size:
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(image[..., 2::-1])
