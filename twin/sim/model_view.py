"""The twin as the real robot's visibility model: the room's MuJoCo model rendered at the robot's
localized camera pose gives the depth a visibility profile needs (``visibility_from_depth``),
since a real camera gives none.

What is drawn is the room alone. The robot is not part of what it looks at (its own body is
behind or below the camera), and the sought objects must not be: their depth is what the
visibility model asks about, so a target drawn where the scene file happens to put it would hide
the cells behind it, and a real target elsewhere would not. Both are hidden by moving their geoms
to a geom group the renderer leaves out, in this object's private copy of the model, so nothing
else that loads the scene is touched and no physics is stepped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

import mujoco
import numpy as np

from twin.core.errors import InputError
from twin.core.geometry import CameraModel
from twin.sim.render import FrameRenderer
from twin.sim.world import load_model, scene_path

# MuJoCo has 6 geom groups (0-5); the scenes use 0-3, so 5 is free to mean "not drawn here".
HIDDEN_GROUP = 5


class ModelDepth:
    """Depth images of a scene's room, rendered for ``camera`` at any camera pose.

    Hidden: every body that moves freely (a free joint at its root: the robot) with everything
    attached to it, and the bodies named in ``hidden_bodies`` (the sought objects, e.g.
    ``World.targets()``) with their descendants. Opens a GL context; ``close`` it (or use
    ``with``).
    """

    def __init__(
        self, scene: str | Path, camera: CameraModel, hidden_bodies: Sequence[str] = ()
    ) -> None:
        path = scene_path(scene)
        model = load_model(path)  # a private copy: geom groups and the free fovy are edited
        self.camera = camera
        self.hidden_geoms = _hidden_geoms(model, path.name, hidden_bodies)
        model.geom_group[self.hidden_geoms] = HIDDEN_GROUP
        # a free camera takes its vertical field of view from the model's global setting
        model.vis.global_.fovy = math.degrees(camera.vfov)
        model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), camera.width)
        model.vis.global_.offheight = max(int(model.vis.global_.offheight), camera.height)
        self._model = model
        self._data = mujoco.MjData(model)
        mujoco.mj_forward(model, self._data)
        # MuJoCo's default draws groups 0-2, as the twin's camera does; the hidden one never
        self._option = mujoco.MjvOption()
        self._option.geomgroup[HIDDEN_GROUP] = 0
        self._free = mujoco.MjvCamera()
        self._free.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._free.distance = 1.0
        self._renderer = FrameRenderer(model, camera.width, camera.height)

    def render(self, x: float, y: float, z: float, yaw: float, tilt: float) -> np.ndarray:
        """H x W float32 metres along each pixel's ray (row 0 at the top, NaN where nothing is
        within the far plane), for the optical centre at (x, y, z) metres in the map and the
        optical axis at bearing ``yaw`` (base yaw + pan) and elevation ``tilt`` (radians,
        positive up)."""
        for name, value in (("x", x), ("y", y), ("z", z), ("yaw", yaw), ("tilt", tilt)):
            if not math.isfinite(value):
                raise InputError(f"model depth camera {name} must be finite, got {value!r}")
        if not abs(tilt) < math.pi / 2:
            raise InputError(f"model depth tilt must be within +-90 degrees, got {tilt!r} rad")
        # MuJoCo's free camera sits `distance` behind `lookat` along its forward direction
        # (cos el cos az, cos el sin az, sin el); no roll, as the pan-tilt head has none
        forward = np.array(
            [math.cos(tilt) * math.cos(yaw), math.cos(tilt) * math.sin(yaw), math.sin(tilt)]
        )
        self._free.lookat[:] = np.array([x, y, z]) + self._free.distance * forward
        self._free.azimuth = math.degrees(yaw)
        self._free.elevation = math.degrees(tilt)
        return self._renderer.depth(self._data, self._free, self._option)

    def close(self) -> None:
        self._renderer.close()

    def __enter__(self) -> ModelDepth:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _hidden_geoms(model: mujoco.MjModel, scene: str, hidden_bodies: Sequence[str]) -> np.ndarray:
    """Ids of the geoms of freely moving bodies' trees and of the named bodies' subtrees."""
    hidden = np.zeros(model.nbody, dtype=bool)
    for name in hidden_bodies:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if body < 0:
            raise InputError(f"{scene}: no body named {name!r} to hide; check the object names")
        hidden[body] = True
    free = int(mujoco.mjtJoint.mjJNT_FREE)
    for joint in range(model.njnt):
        if int(model.jnt_type[joint]) == free:
            hidden[model.jnt_bodyid[joint]] = True
    # bodies are numbered parents first, so one pass hands hiding down each tree
    for body in range(1, model.nbody):
        hidden[body] |= hidden[model.body_parentid[body]]
    return np.nonzero(hidden[model.geom_bodyid])[0]
