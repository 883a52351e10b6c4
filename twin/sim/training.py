"""Training and calibration views for the detector, rendered with exact masks.

Training (``training_views``): the target alone on the training stage.

The views mimic the robot's camera: the same field of view and image size, looking at the target
from a given horizontal range and from ``camera_drop`` metres above its centre (0.4 m: the
robot's 1.0 m camera over a box standing on a 0.45 m coffee table). Masks come from MuJoCo's
segmentation rendering, so they are exact to the pixel.

Calibration (``calibration_views``): the target among the survey scene's clutter, as the robot's
head camera sees it from random free-floor poses: most views miss it, some show it. These give
the detector's score distributions on and off the object (``twin.rfch.calibration``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import mujoco
import numpy as np

from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.sim.placement import place_targets, random_surface_pose
from twin.sim.render import FrameRenderer
from twin.sim.robot import CAMERA_NAME, PAPER_CAMERA, SimRobot
from twin.sim.world import World

DEFAULT_DISTANCES = (1.0, 1.5, 2.0, 3.0)
DEFAULT_ANGLES = tuple(2.0 * math.pi * k / 8 for k in range(8))
# Camera heights over the target's centre (m) that a robot with its camera at 1.0 m sees objects
# from: on the floor (seen from above), on a 0.45 m coffee table (the one-drop default), on a
# 0.9 m counter (level), and on a shelf above the camera (from below). The stage has a floor
# 0.07-0.15 m under each object's centre, so the view from below is taken from just above that
# floor (-0.05 m: 1-3 degrees up; the top face is hidden, as a shelf's edge hides its bottom).
ELEVATION_DROPS = (0.9, 0.4, 0.0, -0.05)
# Placement i of calibration uses np.random.default_rng(CALIBRATION_SEED + i) (by default):
# seeds 900_000 to 900_999 are reserved for calibration, and evaluation runs (random target
# placements in twin.app.run / batch) must use other seeds, or the detector would be scored on
# the very placements it was calibrated on.
CALIBRATION_SEED = 900_000
ROBOT_CLEARANCE = 0.35  # metres from walls and furniture: the Peoplebot's radius and a margin


def training_views(
    distances: Sequence[float] = DEFAULT_DISTANCES,
    angles: Sequence[float] = DEFAULT_ANGLES,
    camera_drop: float | Sequence[float] = 0.4,
    target: str | None = None,
    scene: str = "training_stage",
    width: int = 320,
    height: int = 240,
) -> tuple[np.ndarray, np.ndarray]:
    """Render the target from every (camera drop, distance, angle).

    ``distances`` are horizontal ranges in metres; ``angles`` (radians) place the camera around
    the target, measured in the target's frame from its printed front (+x) counter-clockwise;
    ``camera_drop`` is how far (m) the camera is above the target's centre — one value, or
    several for views from several elevations (negative: from below; ``ELEVATION_DROPS``).
    Returns ``images`` (N, H, W, 3) uint8 RGB and ``masks`` (N, H, W) bool, N = drops x
    distances x angles, drop-major then distance-major.
    """
    drops = (camera_drop,) if isinstance(camera_drop, int | float) else tuple(camera_drop)
    if not distances or not angles or not drops:
        raise InputError("training_views needs at least one distance, angle and camera drop")
    for d in distances:
        if not (math.isfinite(d) and 0.2 <= d <= 10.0):
            raise InputError(f"training distance {d!r} m is outside [0.2, 10] m")
    for drop in drops:
        if not (isinstance(drop, int | float) and math.isfinite(drop) and abs(drop) < 3.0):
            raise InputError(f"camera_drop {drop!r} m must be finite and within 3 m")
    world = World(scene)
    target = target or (world.targets() or (None,))[0]
    if target is None:
        raise InputError(f"scene {world.path.name} declares no target; pass target=")
    body = world.body_id(target)
    geoms = np.flatnonzero(world.model.geom_bodyid == body)
    centre = world.data.xpos[body].copy()
    yaw = world.body_pose(target).yaw

    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = centre
    images, masks = [], []
    with FrameRenderer(world.model, width, height) as renderer:
        for drop in drops:
            for distance in distances:
                camera.distance = math.hypot(distance, drop)
                camera.elevation = -math.degrees(math.atan2(drop, distance))
                for angle in angles:
                    # MuJoCo's azimuth is the direction the camera looks, in degrees
                    camera.azimuth = math.degrees(yaw + angle + math.pi)
                    images.append(renderer.render(world.data, camera))
                    masks.append(np.isin(renderer.segment(world.data, camera), geoms))
    return np.stack(images), np.stack(masks)


class CalibrationViews(NamedTuple):
    """Frames for a score calibration, their target masks and the target's distance (m); and
    for a model of the room's own look, each frame's depth (m along the rays, NaN beyond) and
    the robot's pose (x, y, yaw: m, m, rad) it was taken from."""

    images: np.ndarray
    masks: np.ndarray
    distances: np.ndarray
    depths: np.ndarray | None = None
    poses: np.ndarray | None = None


def calibration_views(
    scene: str = "living_room",
    target: str | None = None,
    n_placements: int = 12,
    views_per_placement: int = 16,
    seed: int = CALIBRATION_SEED,
    aimed_fraction: float = 0.25,
    min_distance: float = 0.6,
    width: int = PAPER_CAMERA.width,
    height: int = PAPER_CAMERA.height,
    lighting: tuple[float, float] = (1.0, 1.0),
    effects: Effects | None = None,
    tilt: float = 0.0,
) -> CalibrationViews:
    """Head-camera frames of ``scene`` with the target at random furniture tops, and its masks.

    For each placement i (``rng = np.random.default_rng(seed + i)``; keep ``seed`` in the
    reserved range, see ``CALIBRATION_SEED``) the target moves to a random level furniture top
    (``random_surface_pose``; or to its own kind of support, if the scene declares one), then
    the robot stands at ``views_per_placement`` random free floor poses (``ROBOT_CLEARANCE`` m
    from walls and furniture, at least ``min_distance`` m from the target) with its head straight
    and at ``tilt`` (radians, up positive: the survey's, so that the room is seen as the
    survey sees it), the camera at its 1 m height. A share ``aimed_fraction`` of the views
    face the target give or take half the field of view (so it lands anywhere across the frame,
    or is hidden behind furniture); the others face a uniformly random direction and mostly
    miss it, as most survey views do.

    Each placement's lights are scaled by a factor drawn uniformly from ``lighting`` (the
    survey's frames will not be lit as the calibration's were).

    ``effects`` passes every frame through a camera: ``effects(image, depth, rng) -> (image,
    depth)`` (its ``rng`` is seeded from the placement's seed, apart from the poses' so that
    they stay the same), or an object with such an ``apply`` (e.g.
    ``twin.sim.camera_effects.CameraEffects``), so that the calibration sees the frames the
    survey sees (default None: clean frames). If it (or the object of a bound ``apply``) has a
    lens (``settings.lens``), frames are rendered at its ``canvas_size`` and ``canvas_fovy``
    and bent to ``width`` x ``height`` by it. The mask follows the depth through it (object
    pixels travel as negated depths), so the effects must move depth pixels without blending
    their values, as a nearest-neighbour lens remap does.

    Returns ``images`` (N, H, W, 3) uint8 RGB, ``masks`` (N, H, W) bool (the target's pixels,
    from segmentation), ``distances`` (N,) metres in the plan from the robot to the target,
    ``depths`` (N, H, W) and ``poses`` (N, 3), N = n_placements x views_per_placement,
    placement-major.
    """
    if n_placements < 1 or views_per_placement < 1:
        raise InputError(
            f"calibration needs at least one placement and view, got {n_placements} "
            f"placements x {views_per_placement} views"
        )
    if not 0.0 <= aimed_fraction <= 1.0:
        raise InputError(f"aimed_fraction must be in [0, 1], got {aimed_fraction!r}")
    world = World(scene)
    target = target or (world.targets() or (None,))[0]
    if target is None:
        raise InputError(f"scene {world.path.name} declares no target; pass target=")
    geoms = np.flatnonzero(world.model.geom_bodyid == world.body_id(target))
    robot = SimRobot(world)
    obstacles = [world.footprint(name).polygon for name in world.furniture()]
    half_fov = 0.5 * PAPER_CAMERA.hfov
    aimed = round(aimed_fraction * views_per_placement)
    images, masks, distances, depths, poses = [], [], [], [], []
    apply, canvas, fovy = _effects_chain(effects, width, height)
    saved_fovy = float(world.model.cam_fovy[robot.camera_id])
    with FrameRenderer(world.model, *canvas, CAMERA_NAME) as renderer:
        for i in range(n_placements):
            rng = np.random.default_rng(seed + i)
            # The camera's own randomness (noise) has its own stream, so that the poses and
            # placements are the same with effects as without.
            camera_rng = np.random.default_rng([seed + i, 1])
            spot = _random_spot(world, target, rng)
            world.scale_lighting(float(rng.uniform(*lighting)))
            for k in range(views_per_placement):
                x, y = _free_floor_point(world, obstacles, (spot.x, spot.y), min_distance, rng)
                if k < aimed:
                    yaw = math.atan2(spot.y - y, spot.x - x) + rng.uniform(-half_fov, half_fov)
                else:
                    yaw = rng.uniform(-math.pi, math.pi)
                # No settling: only the pose matters for a frame, and physics would cost time.
                robot.place(Pose2D(x, y, float(yaw)), tilt=tilt, settle=0.0)
                if fovy is not None:  # the effects' wider canvas, for this render only
                    world.model.cam_fovy[robot.camera_id] = math.degrees(fovy)
                try:
                    image = renderer.render(world.data)
                    mask = np.isin(renderer.segment(world.data), geoms)
                    depth = renderer.depth(world.data)
                finally:
                    world.model.cam_fovy[robot.camera_id] = saved_fovy
                if apply is not None:
                    frame = _through(apply, image, mask, depth, camera_rng, (width, height))
                    image, mask, depth = frame
                images.append(image)
                masks.append(mask)
                depths.append(depth)
                distances.append(math.dist((x, y), (spot.x, spot.y)))
                poses.append((x, y, float(yaw)))
    return CalibrationViews(
        np.stack(images), np.stack(masks), np.array(distances), np.stack(depths), np.array(poses)
    )


Effects = Callable[..., tuple[np.ndarray, np.ndarray | None]] | Any
"""``effects(image, depth, rng) -> (image, depth)``, or an object with such an ``apply``."""


def _effects_chain(
    effects: Effects | None, width: int, height: int
) -> tuple[Callable[..., Any] | None, tuple[int, int], float | None]:
    """(the callable, the canvas (width, height) px to render at, its fovy in rad or None)."""
    if effects is None:
        return None, (width, height), None
    apply = effects.apply if hasattr(effects, "apply") else effects
    if not callable(apply):
        raise InputError(
            f"effects must be callable as effects(image, depth, rng) or have such an apply, "
            f"got {type(effects).__name__}"
        )
    owner = effects if hasattr(effects, "apply") else getattr(effects, "__self__", None)
    settings = getattr(owner, "settings", None)
    if settings is not None and getattr(settings, "lens", None) is not None:
        return apply, tuple(owner.canvas_size), float(owner.canvas_fovy)
    return apply, (width, height), None


def _through(
    apply: Callable[..., Any],
    image: np.ndarray,
    mask: np.ndarray,
    depth: np.ndarray,
    rng: np.random.Generator,
    size: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One frame, its mask and depth through the camera effects (see ``calibration_views``)."""
    signed = np.where(mask, -depth, depth)  # object pixels always have a finite depth
    image, signed = apply(image, signed, rng)
    width, height = size
    if image.shape != (height, width, 3) or signed is None or signed.shape != (height, width):
        raise InputError(
            f"camera effects returned a {image.shape} frame and a "
            f"{None if signed is None else signed.shape} depth; expected {height}x{width}"
        )
    mask = signed < 0.0
    return image, mask, np.where(mask, -signed, signed)


def _random_spot(world: World, target: str, rng: np.random.Generator) -> Pose2D:
    """Where the target goes for one calibration placement: on its own kind of support when
    the scene declares one (the apartment's floor crate, its shelf box: a random furniture top
    is where they never stand), else on a random level furniture top."""
    kinds = world.target_supports().get(target)
    if kinds:
        return place_targets(world, rng, {target: kinds})[target]
    return random_surface_pose(world, target, rng)


def _free_floor_point(
    world: World,
    obstacles: list[np.ndarray],
    target: tuple[float, float],
    min_distance: float,
    rng: np.random.Generator,
) -> tuple[float, float]:
    """A uniformly random (x, y) in metres where the robot can stand, away from the target.

    ``obstacles`` are the furniture footprints (convex, counter-clockwise), computed once: the
    same test as ``World.check_free``, which recomputes them at every call (half the time of
    rendering the views).
    """
    xmin, ymin, xmax, ymax = world.room_bounds()
    c = ROBOT_CLEARANCE
    for _ in range(2000):
        x, y = float(rng.uniform(xmin + c, xmax - c)), float(rng.uniform(ymin + c, ymax - c))
        if math.dist((x, y), target) < min_distance:
            continue
        if all(_clear_of(np.array([x, y]), polygon, c) for polygon in obstacles):
            return x, y
    raise InputError(
        f"found no free floor point {c} m from the furniture and {min_distance} m "
        f"from the target in {world.path.name}; lower min_distance"
    )


def _clear_of(point: np.ndarray, polygon: np.ndarray, clearance: float) -> bool:
    """Whether ``point`` lies outside the convex CCW ``polygon`` by at least ``clearance`` m."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    edge, rel = b - a, point - a
    if np.all(edge[:, 0] * rel[:, 1] - edge[:, 1] * rel[:, 0] >= 0.0):
        return False  # inside
    t = np.clip(np.einsum("ij,ij->i", rel, edge) / np.einsum("ij,ij->i", edge, edge), 0.0, 1.0)
    return bool(np.min(np.linalg.norm(rel - t[:, None] * edge, axis=1)) >= clearance)
