"""Where a view's depth comes from, for the visibility model of ``twin.core.visibility``.

A wedge may credit or penalise only the cells an object standing there would have been seen in.
That needs the depth along each pixel's ray, and three sources give it, most faithful first:

* ``depth``: the frame's own depth. The twin renders it with the colour image, so it holds
  everything in the room, the sought object included.
* ``model``: the twin's model of the room rendered at the localized camera pose, with the robot
  and the sought objects hidden. This is how the real robot, whose camera gives colour only, uses
  the digital twin as its visibility model. It misses what the model lacks (a chair moved, a
  person), so it errs towards "visible".
* ``map``: the laser's occupancy map, its obstacles taken as full-height walls. It has one slice
  at the laser's height, so it hides too much behind low furniture and knows no shelves.

Where an object could stand (``supports``) comes from the scene's surfaces (``model``), or, with
no model, from every height up to 2 m (``anywhere``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.core.devices import View
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel
from twin.core.height import HeightCheck
from twin.core.visibility import ColumnVisibility, SupportLevels, TallMap, visibility_from_depth

if TYPE_CHECKING:
    from twin.app.config import SurveyConfig
    from twin.sim.world import World

SOURCES = ("depth", "model", "map", "none")
SUPPORTS = ("model", "anywhere")

DepthSource = Callable[[View, CameraModel, float], np.ndarray]


@dataclass(frozen=True)
class DepthVisibility:
    """A ``twin.app.mission.VisibilityModel``: per view, the columns' visibility profiles from
    the depth ``depth_of(view, camera, camera_height)`` gives, up to ``reach`` metres."""

    depth_of: DepthSource
    supports: SupportLevels
    object_height: float
    reach: float
    camera_height: float = 1.0
    step: float = 0.05
    tall: TallMap | None = None  # walls and tall furniture: nothing is seen past them
    # metres a point may stand behind the surface its pixel's depth hits and still be seen
    # (``visibility_from_depth``): the object's own near side, plus half a grid cell
    tolerance: float = 0.2

    def profiles(
        self, view: View, camera: CameraModel, column_spans: np.ndarray
    ) -> ColumnVisibility:
        depth = self.depth_of(view, camera, self.camera_height)
        return visibility_from_depth(
            depth,
            camera,
            column_spans,
            origin=(view.pose.x, view.pose.y),
            axis=view.pose.yaw + view.pan,
            tilt=view.tilt,
            camera_height=self.camera_height,
            supports=self.supports,
            object_height=self.object_height,
            reach=self.reach,
            step=self.step,
            tall=self.tall,
            tolerance=self.tolerance,
        )


def frame_depth(view: View, camera: CameraModel, camera_height: float) -> np.ndarray:
    """The depth the camera gave with the frame (the twin's camera renders one)."""
    if view.depth is None:
        raise TwinError(
            'the camera gave no depth with its frame; set visibility.source to "model" (the '
            'scene rendered at the robot\'s pose) or "map"'
        )
    return view.depth


class ModelDepthSource:
    """The room's model rendered at the view's pose (``twin.sim.model_view.ModelDepth``)."""

    def __init__(self, scene: object, camera: CameraModel, hidden_bodies: tuple[str, ...]) -> None:
        from twin.sim.model_view import ModelDepth

        self._model = ModelDepth(scene, camera, hidden_bodies)

    def __call__(self, view: View, camera: CameraModel, camera_height: float) -> np.ndarray:
        return self._model.render(
            view.pose.x, view.pose.y, camera_height, view.pose.yaw + view.pan, view.tilt
        )


class MapDepthSource:
    """The occupancy map's obstacles as walls (``twin.nav.visibility.depth_from_map``)."""

    def __init__(self, occupancy: object) -> None:
        self._map = occupancy

    def __call__(self, view: View, camera: CameraModel, camera_height: float) -> np.ndarray:
        from twin.nav.visibility import depth_from_map

        return depth_from_map(
            self._map,
            camera,
            origin=(view.pose.x, view.pose.y),
            axis=view.pose.yaw + view.pan,
            tilt=view.tilt,
            camera_height=camera_height,
        )


def default_reach(extent: tuple[float, float, float, float], max_range: float | None) -> float:
    """How far a profile must reach: the wedges' range, or the grid's diagonal."""
    diagonal = math.hypot(extent[2] - extent[0], extent[3] - extent[1])
    return diagonal if max_range is None else min(max_range, diagonal)


def build_visibility(
    config: SurveyConfig, world: World, camera: CameraModel, occupancy: object | None = None
) -> DepthVisibility | None:
    """The visibility model ``config``'s ``[visibility]`` asks for, or None for "none".

    ``camera`` is the robot camera's model; ``world`` the scene (the twin's own world in the
    simulation, the scene file loaded as a model of the room on the robot); ``occupancy`` the
    localization map, for ``source = "map"``.
    """
    options = config.visibility
    source = options.source
    if source == "auto":
        source = "depth" if config.devices["camera"].type == "sim" else "model"
    if source == "none":
        return None
    spec = config.grid.spec
    extent = (spec.x_min, spec.y_min, spec.x_max, spec.y_max)
    tall = None
    if options.supports == "model":
        from twin.sim.supports import support_levels, tall_map

        supports = support_levels(world, cell_size=config.grid.spec.cell_size)
        tall = tall_map(world, cell_size=config.grid.spec.cell_size)
    else:
        supports = SupportLevels.anywhere(extent, config.grid.spec.cell_size)
    if source == "depth":
        depth_of: DepthSource = frame_depth
    elif source == "model":
        hidden = tuple(world.targets())
        depth_of = ModelDepthSource(config.scene, camera, hidden)
    else:
        if occupancy is None:
            raise TwinError(
                'visibility.source = "map" needs the localization map: use pose_source = "laser" '
                "with a [localization] map, or another source"
            )
        depth_of = MapDepthSource(occupancy)
    return DepthVisibility(
        depth_of,
        supports,
        options.object_height_m,
        default_reach(extent, config.grid.max_range),
        tall=tall,
        # A crate 0.4 m wide hides its own centre from a test that allows 0.2 m, at its true
        # cell: the apartment's crate landed 0.56 m in front of itself.
        tolerance=options.object_radius_m + 0.5 * spec.cell_size,
    )


def planning_visibility(
    config: SurveyConfig, world: World, camera: CameraModel, occupancy: object | None = None
) -> DepthVisibility | None:
    """The visibility model for views not taken yet: the frame's own depth exists only once a
    view is taken, so where the config reads it (``depth``, or ``auto`` with the twin's camera)
    a planner renders the room's model instead; ``map`` and ``none`` stay as they are."""
    from dataclasses import replace

    source = config.visibility.source
    if source in ("auto", "depth"):
        source = "model"
    return build_visibility(
        replace(config, visibility=replace(config.visibility, source=source)),
        world,
        camera,
        occupancy,
    )


def build_height_check(config: SurveyConfig, visibility: object | None) -> HeightCheck | None:
    """``[grid] height_check``'s ``HeightCheck`` on the visibility model's supports (None when
    it is off or there is no model: without surfaces there is nothing to stand on)."""
    supports = getattr(visibility, "supports", None)
    if not config.grid.height_check or supports is None:
        return None
    return HeightCheck(supports, config.visibility.object_height_m)
