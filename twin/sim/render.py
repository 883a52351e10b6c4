"""Offscreen rendering: one MuJoCo renderer (one GL context) per camera, closed cleanly.

Headless by default: ``twin.sim`` sets ``MUJOCO_GL=egl`` before MuJoCo is imported; Mesa's
software EGL driver renders a 320x240 living-room frame in a few milliseconds because the scenes
turn shadow maps off.
"""

from __future__ import annotations

import math
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
    """Renders RGB images (H x W x 3 uint8, row 0 at the top), segmentation or depth for one
    camera.

    ``camera`` is a model camera's name, or a ``mujoco.MjvCamera`` (a free camera, whose
    vertical field of view is the model's ``<visual><global fovy>``) given to each call instead.
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
        self._model = model
        self._segmentation = False
        self._depth = False
        # per-pixel ratio of the distance along the ray to the distance along the optical axis,
        # for the last vertical field of view seen (a free camera's may change between calls)
        self._ray_scale: tuple[float, np.ndarray] | None = None

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
        renderer = self._mode(segmentation=False, depth=False)
        renderer.update_scene(data, camera=self._camera_id if free_camera is None else free_camera)
        return renderer.render().copy()

    def segment(
        self, data: mujoco.MjData, free_camera: mujoco.MjvCamera | None = None
    ) -> np.ndarray:
        """Geom id per pixel (H x W int32), -1 where no geom is seen."""
        renderer = self._mode(segmentation=True, depth=False)
        renderer.update_scene(data, camera=self._camera_id if free_camera is None else free_camera)
        seg = renderer.render()
        ids = seg[..., 0].astype(np.int32)
        ids[seg[..., 1] != int(mujoco.mjtObj.mjOBJ_GEOM)] = -1
        return ids

    def depth(
        self,
        data: mujoco.MjData,
        free_camera: mujoco.MjvCamera | None = None,
        scene_option: mujoco.MjvOption | None = None,
    ) -> np.ndarray:
        """Metres along each pixel's ray to the first surface (H x W float32, row 0 at the top
        like ``render``), NaN where nothing is drawn before the far clipping plane.

        MuJoCo reads its depth buffer back as distance along the optical axis; a visibility
        model compares it with distances from the camera's centre, so each pixel is scaled by
        its ray's length per unit of axis depth (pixel centres, square pixels, the camera's
        ``fovy``). ``scene_option`` chooses what is drawn (e.g. geom groups to leave out).
        """
        renderer = self._mode(segmentation=False, depth=True)
        renderer.update_scene(
            data,
            camera=self._camera_id if free_camera is None else free_camera,
            scene_option=scene_option,
        )
        axial = renderer.render().astype(float)
        model = self._model
        far = float(model.vis.map.zfar * model.stat.extent)
        # The cleared buffer reads back as the far plane (to float32's precision there, about
        # 3e-4 of it); nothing in a room is within 1 % of it (50 room extents by default).
        axial[axial >= 0.99 * far] = np.nan
        ray = axial * self._ray_scale_for(self._fovy(free_camera), *axial.shape)
        return ray.astype(np.float32)  # MuJoCo's own precision; half the memory per frame

    def _fovy(self, free_camera: mujoco.MjvCamera | None) -> float:
        """Vertical field of view (radians) the image was rendered with."""
        model = self._model
        if free_camera is not None or self._camera_id < 0:
            return math.radians(float(model.vis.global_.fovy))
        if np.any(model.cam_sensorsize[self._camera_id] > 0):
            raise TwinError(
                f"camera {self.camera!r} is given by sensor size and focal length; depth needs "
                "a camera given by fovy (square pixels, centred principal point)"
            )
        return math.radians(float(model.cam_fovy[self._camera_id]))

    def _ray_scale_for(self, fovy: float, height: int, width: int) -> np.ndarray:
        if self._ray_scale is None or self._ray_scale[0] != fovy:
            focal = (height / 2.0) / math.tan(fovy / 2.0)
            x = (np.arange(width) + 0.5 - width / 2.0) / focal
            y = (np.arange(height) + 0.5 - height / 2.0) / focal
            self._ray_scale = (fovy, np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2))
        return self._ray_scale[1]

    def _mode(self, *, segmentation: bool, depth: bool) -> mujoco.Renderer:
        """The renderer switched to the asked output (colour when neither flag is set)."""
        renderer = self._active()
        if segmentation != self._segmentation:
            if segmentation:
                renderer.enable_segmentation_rendering()
            else:
                renderer.disable_segmentation_rendering()
            self._segmentation = segmentation
        if depth != self._depth:
            if depth:
                renderer.enable_depth_rendering()
            else:
                renderer.disable_depth_rendering()
            self._depth = depth
        return renderer

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


def write_png(
    path: str | os.PathLike[str], rgb: np.ndarray, compression: int | None = None
) -> Path:
    """Write an RGB image (H x W x 3 uint8) as PNG, atomically; ``compression`` 0-9 (OpenCV's
    default when None; the generated textures use 9: they are committed)."""
    params = [] if compression is None else [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]
    bgr = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", bgr, params)
    if not ok:
        raise TwinError(f"could not encode a PNG for {path}; is the image H x W x 3 uint8?")
    return write_atomic(path, lambda handle: handle.write(buf.tobytes()))
