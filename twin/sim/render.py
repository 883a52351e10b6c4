"""Offscreen rendering: one MuJoCo renderer (one GL context) per camera, closed cleanly.

Headless by default: ``twin.sim`` sets ``MUJOCO_GL=egl`` before MuJoCo is imported; Mesa's
software EGL driver renders a 320x240 living-room frame in a few milliseconds because the scenes
turn shadow maps off.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType

import cv2
import mujoco
import numpy as np

from twin.core.errors import TwinError
from twin.core.store import write_atomic

_GL_HINT = (
    "install Mesa's EGL (apt-get install libegl1 libgl1-mesa-dri) or set MUJOCO_GL=osmesa "
    "(with libosmesa6)"
)


class FrameRenderer:
    """Renders RGB images (H x W x 3 uint8, row 0 at the top) or segmentation for one camera.

    ``camera`` is a model camera's name, or a ``mujoco.MjvCamera`` (a free camera) given to each
    ``render`` call instead.
    """

    def __init__(
        self, model: mujoco.MjModel, width: int, height: int, camera: str | None = None
    ) -> None:
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise TwinError(
                f"a {width}x{height} image does not fit the model's offscreen buffer "
                f"({model.vis.global_.offwidth}x{model.vis.global_.offheight}); raise "
                "<visual><global offwidth/offheight> in the scene"
            )
        self._camera_id = -1
        if camera is not None:
            self._camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
            if self._camera_id < 0:
                raise TwinError(f"the model has no camera named {camera!r}; check the MJCF")
        self.camera = camera
        try:
            self._renderer: mujoco.Renderer | None = mujoco.Renderer(model, height, width)
        except Exception as exc:  # GL failures surface as several exception types
            backend = os.environ.get("MUJOCO_GL", "default")
            raise TwinError(
                f"cannot create an offscreen OpenGL context (MUJOCO_GL={backend}: "
                f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''}); "
                f"{_GL_HINT}"
            ) from exc
        self._segmentation = False

    @property
    def closed(self) -> bool:
        return self._renderer is None

    def _active(self) -> mujoco.Renderer:
        if self._renderer is None:
            raise TwinError(f"renderer for camera {self.camera!r} is closed; create a new one")
        return self._renderer

    def render(
        self, data: mujoco.MjData, free_camera: mujoco.MjvCamera | None = None
    ) -> np.ndarray:
        """RGB image of the current state (a fresh array the caller may keep)."""
        renderer = self._active()
        if self._segmentation:
            renderer.disable_segmentation_rendering()
            self._segmentation = False
        renderer.update_scene(data, camera=self._camera_id if free_camera is None else free_camera)
        return renderer.render().copy()

    def segment(
        self, data: mujoco.MjData, free_camera: mujoco.MjvCamera | None = None
    ) -> np.ndarray:
        """Geom id per pixel (H x W int32), -1 where no geom is seen."""
        renderer = self._active()
        if not self._segmentation:
            renderer.enable_segmentation_rendering()
            self._segmentation = True
        renderer.update_scene(data, camera=self._camera_id if free_camera is None else free_camera)
        seg = renderer.render()
        ids = seg[..., 0].astype(np.int32)
        ids[seg[..., 1] != int(mujoco.mjtObj.mjOBJ_GEOM)] = -1
        return ids

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> FrameRenderer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def write_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an RGB image (H x W x 3 uint8) as PNG, atomically."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    if not ok:
        raise TwinError(f"could not encode a PNG for {path}; is the image H x W x 3 uint8?")
    return write_atomic(path, lambda handle: handle.write(buf.tobytes()))
