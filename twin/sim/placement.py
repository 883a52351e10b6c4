"""Putting an object on the room's visible surfaces, fairly, for generality runs.

An object stands on the *visible* top under it: whatever geom a camera sees there, decorations
included (a sofa's cushion, not the seat frame under it; a book, not the shelf under the book).
A spot is kept only if the object

* rests level: under every point of its footprint (a grid at most 3 cm apart) the highest
  surface is within 1 cm of the one it stands on, so it neither overhangs an edge nor tilts;
* fits: nothing lies above that surface within the object's height plus ``HEAD_MARGIN`` (it
  fits under the next shelf), and once placed none of its geoms overlaps any room geom, drawn
  or collidable, by more than ``OVERLAP_TOLERANCE`` (MuJoCo's signed geom distance);
* and, for random draws, could be seen: from at least one free spot on the floor around it, a
  camera at 1.0 m sees ``VISIBLE_ENOUGH`` of the object's faces that face it (``best_view``).

Several objects at once (``place_targets``): each on a support of the kind it belongs to
(``SUPPORT_KINDS``: the floor, a table top, a counter, a shelf, by height), as the scene declares
(``World.target_supports``) or the caller says, apart from one another, and each still in view
with the others placed.

The robot is no part of the room: it moves, so it neither supports, blocks nor hides anything.
Surfaces come from ``twin.sim.supports`` (exact for the scenes' primitive geoms).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import mujoco
import numpy as np

from twin.core.errors import InputError, TwinError
from twin.core.geometry import Pose2D
from twin.core.visibility import SUPPORT_KINDS
from twin.sim.supports import RENDERED_GROUPS, room_geoms, subtree_bodies, vertical_spans
from twin.sim.world import World

LEVEL_TOLERANCE = 0.01  # metres: the most the surface may vary under the object's footprint
OVERLAP_TOLERANCE = 0.005  # metres: deeper than this into another geom is inside it
HEAD_MARGIN = 0.03  # metres: free space wanted above the object (a hand must reach in)
FOOTPRINT_STEP = 0.03  # metres: the most between the points the footprint is checked at
VISIBLE_ENOUGH = 0.9  # fraction of the object's camera-facing faces a fair spot shows
CAMERA_HEIGHT = 1.0  # metres: the robot's camera above the floor
VIEW_RADII = (1.0, 1.5, 2.0, 2.5)  # metres from the object where a camera may stand
VIEW_BEARINGS = 16  # directions per radius
VIEW_CLEARANCE = 0.25  # metres: a camera spot keeps this far from walls and furniture
STANDING_FACE = 0.99  # a face whose normal points this straight down is the one it stands on
SPOT_STEP = 0.05  # metres: the grid on which place_targets finds where each kind of support is
PARK = -1000.0  # metres: where targets wait, far outside any room, while others are placed


def visible_fraction(world: World, body: str, camera: Sequence[float], per_side: int = 4) -> float:
    """Fraction (0-1) of the object's surface facing ``camera`` (x, y, z metres) that a camera
    there sees: is this placement fair, could it have been found from there?

    The faces of each of the body's geoms (their bounding boxes: the faces themselves for a
    box) that face the camera, except a face turned straight down (what it stands on covers
    that one: a camera below a shelf would otherwise never see enough of a box on it), are
    sampled on a ``per_side`` x ``per_side`` grid; a sample
    counts as seen when the ray from the camera to it meets the object before anything drawn
    (groups 0-2) in the room. Only rays that would meet the object were the room empty are
    counted, so a round geom's box corners do not count against it. The robot is ignored: a
    ray passes through it, as if the camera stood where the robot is not in the way.
    """
    model, data = world.model, world.data
    if per_side < 1:
        raise InputError(f"visible_fraction needs per_side >= 1 samples, got {per_side}")
    eye = np.asarray(camera, dtype=float).reshape(3)
    mine = subtree_bodies(world, [body])
    geoms = [g for g in range(model.ngeom) if int(model.geom_bodyid[g]) in mine]
    targets: list[np.ndarray] = []
    for geom in geoms:
        points = _facing_samples(world, geom, eye, per_side)
        if len(points):
            keep = [_meets(world, geom, eye, p - eye) for p in points]
            targets.append(points[np.asarray(keep, dtype=bool)])
    points = np.concatenate(targets) if targets else np.zeros((0, 3))
    if len(points) == 0:
        return 0.0
    rays = points - eye
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    hit = np.zeros(len(rays), dtype=np.int32)
    dist = np.zeros(len(rays))
    mujoco.mj_multiRay(
        model, data, eye, rays.ravel(), RENDERED_GROUPS, 1, -1, hit, dist, None, len(rays), 1e3
    )
    seen = 0
    for ray, geom, length in zip(rays, hit, dist, strict=True):
        seen += int(_first_room_geom(world, eye, ray, int(geom), float(length)) in mine)
    return seen / len(points)


def viewpoints(
    world: World,
    x: float,
    y: float,
    radii: Sequence[float] = VIEW_RADII,
    bearings: int = VIEW_BEARINGS,
    height: float = CAMERA_HEIGHT,
    clearance: float = VIEW_CLEARANCE,
) -> np.ndarray:
    """(M, 3) camera spots on rings of ``radii`` metres around (x, y), ``bearings`` per ring,
    ``height`` metres up, each on free floor: ``clearance`` metres inside the room and outside
    every piece of furniture (targets are not furniture). Nearest ring first."""
    return _FreeFloor(world, clearance).ring(x, y, radii, bearings, height)


def best_view(
    world: World,
    body: str,
    enough: float = 1.0,
    radii: Sequence[float] = VIEW_RADII,
    bearings: int = VIEW_BEARINGS,
    height: float = CAMERA_HEIGHT,
    clearance: float = VIEW_CLEARANCE,
) -> tuple[float, np.ndarray | None]:
    """The best ``visible_fraction`` of ``body`` from its ``viewpoints``, and the camera spot
    (x, y, z metres) it is seen from (None if no free spot); the search stops at the first spot
    showing at least ``enough``. A placement is fair when the fraction is >= VISIBLE_ENOUGH."""
    x, y, _ = world.body_position(body)
    spots = viewpoints(world, float(x), float(y), radii, bearings, height, clearance)
    return _best_of(world, body, spots, enough)


def place_on_surface(
    world: World, body: str, x: float, y: float, yaw: float, level: float | None = None
) -> Pose2D:
    """Stand ``body`` at (x, y) metres, heading ``yaw`` radians, on the visible surface under
    it: the topmost level, or the one within 2 cm of ``level`` metres (a lower shelf).

    Raises ``InputError`` (leaving the body where it was) when the spot is unfair: no level
    there, the surface not level under the footprint, no room above, or an overlap.
    """
    placer = _Placer(world, body)
    levels = placer.levels_at(x, y)
    if level is None:
        chosen = levels[-1] if len(levels) else None
    else:
        near = [h for h in levels if abs(h - level) <= 0.02]
        chosen = near[0] if near else None
    if chosen is None:
        found = ", ".join(f"{h:.3f}" for h in levels) or "none"
        raise InputError(
            f"no surface to stand {body!r} on at ({x:.2f}, {y:.2f}) m"
            + ("" if level is None else f" at {level:.3f} m")
            + f" (levels there: {found}); choose another spot"
        )
    problem = placer.try_place(x, y, yaw, chosen)
    if problem is not None:
        placer.restore()
        raise InputError(f"cannot stand {body!r} at ({x:.2f}, {y:.2f}) m: {problem}")
    return world.body_pose(body)


def random_surface_pose(
    world: World,
    body: str,
    rng: np.random.Generator,
    min_height: float = 0.3,
    max_height: float = 1.3,
    tries: int = 2000,
) -> Pose2D:
    """Move ``body`` to a random fair spot on a furniture surface between ``min_height`` and
    ``max_height`` metres (what a 1 m-high camera looking level can see); returns its pose.

    Spots are drawn uniformly over the furniture's footprints (weighted by area) with a random
    yaw and a random one of the levels there in range (a shelf as likely as the top); each is
    kept only if it is fair (see the module) and ``VISIBLE_ENOUGH`` of the object shows from
    some free floor spot. The same ``rng`` state and world give the same spot.
    """
    placer = _Placer(world, body)
    tops = [world.footprint(name) for name in world.furniture()]
    areas = np.array([max(f.aabb[2] - f.aabb[0], 0) * max(f.aabb[3] - f.aabb[1], 0) for f in tops])
    floor = None
    for _ in range(tries):
        top = tops[rng.choice(len(tops), p=areas / areas.sum())]
        xmin, ymin, xmax, ymax = top.aabb
        x, y = float(rng.uniform(xmin, xmax)), float(rng.uniform(ymin, ymax))
        yaw = float(rng.uniform(-math.pi, math.pi))
        levels = [h for h in placer.levels_at(x, y) if min_height <= h <= max_height]
        if not levels:
            continue
        level = levels[int(rng.integers(len(levels)))]
        if placer.try_place(x, y, yaw, level) is not None:
            continue
        floor = floor or _FreeFloor(world, VIEW_CLEARANCE)
        spots = floor.ring(x, y, VIEW_RADII, VIEW_BEARINGS, CAMERA_HEIGHT)
        if _best_of(world, body, spots, VISIBLE_ENOUGH)[0] >= VISIBLE_ENOUGH:
            return world.body_pose(body)
    placer.restore()
    raise TwinError(
        f"found no fair spot for {body!r} ({placer.height:.2f} m tall) on the furniture "
        f"between {min_height} and {max_height} m in {tries} tries"
    )


def place_targets(
    world: World,
    rng: np.random.Generator,
    supports: Mapping[str, Sequence[str]] | None = None,
    separation: float = 0.5,
    tries: int = 2000,
    rounds: int = 5,
) -> dict[str, Pose2D]:
    """Move several targets at once to random fair spots, each on a support of its kind; returns
    each one's pose (name -> Pose2D), in the order placed.

    ``supports`` maps each target body to the kinds it may stand on (keys of ``SUPPORT_KINDS``);
    by default the scene's ``World.target_supports()``, and any scene target it does not name
    stays where it is. Each target in turn takes the first fair spot drawn: a kind at random
    among its own, a point where that kind has a level the target fits on (a ``SPOT_STEP`` grid
    over the floor for "floor", over the furniture's footprints otherwise, jittered within its
    cell), a random yaw and a random one of the levels there within the kind's heights; it must
    be ``separation`` metres (plan distance between centres) from the targets placed before it,
    and none of their geoms may overlap. Once all stand,
    each must still show ``VISIBLE_ENOUGH`` of itself from some free floor spot (another target
    may hide it), or the whole placement is drawn again, up to ``rounds`` times. The same
    ``rng`` state and world give the same spots. Raises ``TwinError`` (every target back where
    it was) when no placement is found, ``InputError`` for an unknown target or kind.
    """
    wanted = dict(world.target_supports() if supports is None else supports)
    if not wanted:
        raise InputError(
            f"{world.path.name}: no target has support kinds; give supports= or the scene's "
            '"twin_target_supports" custom text (e.g. "rice_box:table")'
        )
    for name, kinds in wanted.items():
        world.body_id(name)
        unknown = [k for k in kinds if k not in SUPPORT_KINDS] or ([] if kinds else ["(none)"])
        if unknown:
            raise InputError(
                f"target {name!r}: unknown support kind {unknown[0]!r}; use "
                f"{', '.join(SUPPORT_KINDS)}"
            )
    if not (math.isfinite(separation) and separation >= 0):
        raise InputError(f"separation must be a distance >= 0 m, got {separation!r}")
    model = world.model
    ids = {name: world.body_id(name) for name in wanted}
    saved = {name: (model.body_pos[b].copy(), model.body_quat[b].copy()) for name, b in ids.items()}
    floor = _FreeFloor(world, VIEW_CLEARANCE)
    spots: dict[str, dict[str, np.ndarray]] = {}
    for _ in range(rounds):
        for k, body in enumerate(ids.values()):  # out of the way of one another
            model.body_pos[body] = (PARK - 10.0 * k, PARK, 0.0)
        world.forward()
        if not spots:
            spots = {n: {k: _kind_spots(world, n, k) for k in set(ks)} for n, ks in wanted.items()}
        placed: dict[str, Pose2D] = {}
        for name, kinds in wanted.items():
            pose = _place_one(
                world, name, kinds, rng, spots[name], placed, separation, tries, floor
            )
            if pose is None:
                break
            placed[name] = pose
        else:
            if all(_seen(world, name, floor) for name in placed):
                return placed
    for name, body in ids.items():
        model.body_pos[body], model.body_quat[body] = saved[name]
    world.forward()
    raise TwinError(
        f"found no fair placement of {', '.join(wanted)} on their supports in {rounds} rounds of "
        f"{tries} tries each; allow more kinds, a smaller separation, or more tries"
    )


# -- internals -------------------------------------------------------------------------------


def _place_one(
    world: World,
    name: str,
    kinds: Sequence[str],
    rng: np.random.Generator,
    spots: Mapping[str, np.ndarray],
    placed: Mapping[str, Pose2D],
    separation: float,
    tries: int,
    floor: _FreeFloor,
) -> Pose2D | None:
    """One target on a fair spot of one of its kinds, away from ``placed``; None if none.
    ``spots`` holds, per kind, the (M, 2) grid points where the kind has a level the target
    fits on (``_kind_spots``); a draw is one of them jittered within its cell."""
    placer = _Placer(world, name)  # built now: the room holds the targets placed so far
    usable = [k for k in kinds if len(spots[k])]
    for _ in range(tries if usable else 0):
        kind = usable[int(rng.integers(len(usable)))]
        low, high = SUPPORT_KINDS[kind]
        x, y = spots[kind][int(rng.integers(len(spots[kind])))] + rng.uniform(
            -SPOT_STEP / 2, SPOT_STEP / 2, 2
        )
        x, y = float(x), float(y)
        yaw = float(rng.uniform(-math.pi, math.pi))
        if any(math.hypot(x - p.x, y - p.y) < separation for p in placed.values()):
            continue
        levels = [h for h in placer.levels_at(x, y) if low <= h <= high]
        if not levels:
            continue
        level = levels[int(rng.integers(len(levels)))]
        if placer.try_place(x, y, yaw, level) is not None:
            continue
        if _seen(world, name, floor):
            return world.body_pose(name)
    placer.restore()
    return None


def _kind_spots(world: World, name: str, kind: str) -> np.ndarray:
    """(M, 2) points, ``SPOT_STEP`` metres apart, where a surface of ``kind`` has room above it
    for the target ``name`` (the other targets out of the way), over the furniture's
    footprints; for "floor", every point of the floor. Drawing among these instead of over
    every footprint keeps a shelf-sized kind from wasting its tries on walls and table tops."""
    placer = _Placer(world, name)
    low, high = SUPPORT_KINDS[kind]
    xmin, ymin, xmax, ymax = world.room_bounds()
    if kind == "floor":  # most of it is free: every point, the levels checked at the draw
        gx, gy = np.meshgrid(
            np.arange(xmin + SPOT_STEP / 2, xmax, SPOT_STEP),
            np.arange(ymin + SPOT_STEP / 2, ymax, SPOT_STEP),
        )
        return np.column_stack([gx.ravel(), gy.ravel()])
    boxes = [f.aabb for f in (world.footprint(n) for n in world.furniture()) if f.top >= low]
    found = [np.zeros((0, 2))]
    for bx0, by0, bx1, by1 in boxes:
        xs = np.arange(bx0 + SPOT_STEP / 2, bx1, SPOT_STEP)
        ys = np.arange(by0 + SPOT_STEP / 2, by1, SPOT_STEP)
        if len(xs) == 0 or len(ys) == 0:
            continue
        gx, gy = np.meshgrid(xs, ys)
        points = np.column_stack([gx.ravel(), gy.ravel()])
        lo, hi = placer.room_xy
        near = (lo[:, 0] <= bx1) & (hi[:, 0] >= bx0) & (lo[:, 1] <= by1) & (hi[:, 1] >= by0)
        spans = vertical_spans(world, placer.room[near], points)
        levels = spans.levels(headroom=placer.height + HEAD_MARGIN)
        with np.errstate(invalid="ignore"):
            fits = ((levels >= low) & (levels <= high)).any(axis=0)
        found.append(points[fits])
    return np.concatenate(found)


def _seen(world: World, name: str, floor: _FreeFloor) -> bool:
    """Whether ``VISIBLE_ENOUGH`` of the body shows from a free floor spot around it."""
    x, y, _ = world.body_position(name)
    spots = floor.ring(float(x), float(y), VIEW_RADII, VIEW_BEARINGS, CAMERA_HEIGHT)
    return _best_of(world, name, spots, VISIBLE_ENOUGH)[0] >= VISIBLE_ENOUGH


class _Placer:
    """One object and the room it is placed in, worked out once for many candidate spots."""

    def __init__(self, world: World, body: str) -> None:
        model, data = world.model, world.data
        self.world, self.name = world, body
        self.body = world.body_id(body)
        if model.body_weldid[self.body] != 0 or model.body_parentid[self.body] != 0:
            raise InputError(f"{body!r} is not a static body under the world; it cannot be placed")
        self.saved = (model.body_pos[self.body].copy(), model.body_quat[self.body].copy())
        mine = list(subtree_bodies(world, [body]))
        self.geoms = np.flatnonzero(np.isin(model.geom_bodyid, mine))
        if len(self.geoms) == 0:
            raise InputError(f"{body!r} has no geoms, so nothing to place")
        self.room = room_geoms(world, [body])
        # the object's box in its own frame (upright: placing sets a yaw-only orientation)
        frame_pos, frame_rot = data.xpos[self.body], data.xmat[self.body].reshape(3, 3)
        corners = np.concatenate([_geom_corners(world, g) for g in self.geoms])
        local = (corners - frame_pos) @ frame_rot
        self.low, self.high = local.min(axis=0), local.max(axis=0)
        self.height = float(self.high[2] - self.low[2])
        counts = [
            max(2, math.ceil((self.high[i] - self.low[i]) / FOOTPRINT_STEP) + 1) for i in (0, 1)
        ]
        gx, gy = np.meshgrid(*(np.linspace(self.low[i], self.high[i], counts[i]) for i in (0, 1)))
        self.footprint = np.vstack([[0.0, 0.0], np.column_stack([gx.ravel(), gy.ravel()])])
        self.reach = float(np.hypot(*np.abs(np.vstack([self.low[:2], self.high[:2]])).max(axis=0)))
        self.room_xy = _xy_boxes(world, self.room)

    def restore(self) -> None:
        self.world.model.body_pos[self.body], self.world.model.body_quat[self.body] = self.saved
        self.world.forward()

    def _near(self, x: float, y: float) -> np.ndarray:
        """Room geoms whose plan bounding box comes within the object's reach of (x, y)."""
        lo, hi = self.room_xy
        r = self.reach + 0.01
        near = (lo[:, 0] <= x + r) & (hi[:, 0] >= x - r) & (lo[:, 1] <= y + r) & (hi[:, 1] >= y - r)
        return self.room[near]

    def levels_at(self, x: float, y: float) -> list[float]:
        """Heights (m) of the surfaces an object could stand on at (x, y), ascending."""
        spans = vertical_spans(self.world, self._near(x, y), np.array([[x, y]]))
        levels = spans.levels(headroom=self.height + HEAD_MARGIN)[:, 0]
        return sorted(float(h) for h in levels[np.isfinite(levels)])

    def try_place(self, x: float, y: float, yaw: float, level: float) -> str | None:
        """Stand the object on ``level`` at (x, y, yaw); None if fair, else what is wrong."""
        c, s = math.cos(yaw), math.sin(yaw)
        points = self.footprint @ np.array([[c, s], [-s, c]]) + (x, y)
        spans = vertical_spans(self.world, self._near(x, y), points)
        with np.errstate(invalid="ignore"):
            below = np.where(spans.top <= level + OVERLAP_TOLERANCE, spans.top, -np.inf)
        under = below.max(axis=0)  # the highest surface under each footprint point
        if np.any(under < level - LEVEL_TOLERANCE):
            gap = float(level - under.min())
            return f"not level: the surface under its footprint drops {min(gap, level):.3f} m"
        bottom = float(under.max())
        if np.any(
            spans.occupied(
                np.full(len(points), bottom + OVERLAP_TOLERANCE),
                np.full(len(points), bottom + self.height + HEAD_MARGIN),
            )
        ):
            return f"no room above the {bottom:.3f} m surface for {self.height + HEAD_MARGIN:.2f} m"
        model = self.world.model
        model.body_pos[self.body] = (x, y, bottom - self.low[2])
        model.body_quat[self.body] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        self.world.forward()
        return self._overlap(self._near(x, y))

    def _overlap(self, near: np.ndarray) -> str | None:
        model, data = self.world.model, self.world.data
        for mine in self.geoms:
            for other in near:
                depth = mujoco.mj_geomDistance(model, data, int(mine), int(other), 0.01, None)
                if depth < -OVERLAP_TOLERANCE:
                    what = model.geom(int(other)).name or self.world.geom_owner(int(other))
                    return f"it would be {-depth:.3f} m inside {what}"
        return None


class _FreeFloor:
    """The room's floor and furniture outlines, for finding where a camera may stand."""

    def __init__(self, world: World, clearance: float) -> None:
        self.bounds = world.room_bounds()
        self.clearance = clearance
        self.polygons = [world.footprint(name).polygon for name in world.furniture()]

    def ring(
        self, x: float, y: float, radii: Sequence[float], bearings: int, height: float
    ) -> np.ndarray:
        angles = np.arange(bearings) * (2 * math.pi / bearings)
        spots = np.array(
            [[x + r * math.cos(a), y + r * math.sin(a)] for r in radii for a in angles]
        ).reshape(-1, 2)
        xmin, ymin, xmax, ymax = self.bounds
        c = self.clearance
        free = (
            (spots[:, 0] >= xmin + c)
            & (spots[:, 0] <= xmax - c)
            & (spots[:, 1] >= ymin + c)
            & (spots[:, 1] <= ymax - c)
        )
        for polygon in self.polygons:
            free &= _distance_to_polygon(spots, polygon) >= c
        spots = spots[free]
        return np.column_stack([spots, np.full(len(spots), height)])


def _best_of(
    world: World, body: str, spots: np.ndarray, enough: float
) -> tuple[float, np.ndarray | None]:
    best, where = 0.0, None
    for spot in spots:
        fraction = visible_fraction(world, body, spot)
        if where is None or fraction > best:
            best, where = fraction, spot.copy()
        if best >= enough:
            break
    return best, where


def _geom_corners(world: World, geom: int) -> np.ndarray:
    """(8, 3) world corners of a geom's bounding box (its own frame's ``geom_aabb``)."""
    aabb = world.model.geom_aabb[geom]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    local = aabb[:3] + signs * aabb[3:]
    return world.data.geom_xpos[geom] + local @ world.data.geom_xmat[geom].reshape(3, 3).T


def _xy_boxes(world: World, geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plan bounding boxes (lo (G, 2), hi (G, 2)) of geoms; unbounded for planes."""
    lo, hi = np.empty((len(geoms), 2)), np.empty((len(geoms), 2))
    for i, geom in enumerate(geoms):
        if int(world.model.geom_type[geom]) == int(mujoco.mjtGeom.mjGEOM_PLANE):
            lo[i], hi[i] = -np.inf, np.inf
        else:
            corners = _geom_corners(world, int(geom))[:, :2]
            lo[i], hi[i] = corners.min(axis=0), corners.max(axis=0)
    return lo, hi


def _facing_samples(world: World, geom: int, eye: np.ndarray, per_side: int) -> np.ndarray:
    """Points on the faces of a geom's bounding box that face ``eye``, per_side^2 per face."""
    aabb = world.model.geom_aabb[geom]
    centre = world.data.geom_xpos[geom] + world.data.geom_xmat[geom].reshape(3, 3) @ aabb[:3]
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    half = aabb[3:]
    grid = (np.arange(per_side) + 0.5) / per_side * 2 - 1  # cell centres in (-1, 1)
    u, v = (a.ravel() for a in np.meshgrid(grid, grid))
    out = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = sign * rot[:, axis]
            face = centre + normal * half[axis]
            if np.dot(eye - face, normal) <= 1e-9 or half[axis] <= 0:
                continue
            if normal[2] < -STANDING_FACE:  # what it stands on covers it: no camera sees it
                continue
            a, b = [i for i in range(3) if i != axis]
            out.append(face + np.outer(u * half[a], rot[:, a]) + np.outer(v * half[b], rot[:, b]))
    return np.concatenate(out) if out else np.zeros((0, 3))


def _meets(world: World, geom: int, eye: np.ndarray, ray: np.ndarray) -> bool:
    """Whether the ray from ``eye`` along ``ray`` meets the geom itself, nothing else there."""
    model, data = world.model, world.data
    kind = int(model.geom_type[geom])
    if kind == int(mujoco.mjtGeom.mjGEOM_MESH):
        return mujoco.mj_rayMesh(model, data, geom, eye, ray) >= 0
    if kind in (int(mujoco.mjtGeom.mjGEOM_HFIELD), int(mujoco.mjtGeom.mjGEOM_SDF)):
        return True
    return (
        mujoco.mju_rayGeom(
            data.geom_xpos[geom], data.geom_xmat[geom], model.geom_size[geom], eye, ray, kind
        )
        >= 0
    )


def _first_room_geom(world: World, eye: np.ndarray, ray: np.ndarray, geom: int, dist: float) -> int:
    """The body of the first non-robot geom along a unit ray, given mj_ray's first hit; -1 if
    none. A hit on a moving body (the robot) is passed through and the cast continues."""
    model, data = world.model, world.data
    start = eye.copy()
    found = np.zeros(1, dtype=np.int32)
    for _ in range(64):  # the robot is a few geoms deep at most
        if geom < 0:
            return -1
        body = int(model.geom_bodyid[geom])
        if model.body_weldid[body] == 0:
            return body
        start = start + (dist + 1e-4) * ray
        dist = mujoco.mj_ray(model, data, start, ray, RENDERED_GROUPS, 1, -1, found)
        geom = int(found[0])
    return -1


def _distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance (m) from each point (M, 2) to a convex CCW polygon; negative inside."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    edge = b - a  # (K, 2)
    rel = points[:, None, :] - a[None]  # (M, K, 2)
    t = np.clip((rel * edge).sum(axis=2) / (edge * edge).sum(axis=1), 0.0, 1.0)
    dist = np.linalg.norm(rel - t[..., None] * edge, axis=2).min(axis=1)
    inside = np.all(edge[:, 0] * rel[..., 1] - edge[:, 1] * rel[..., 0] >= 0.0, axis=1)
    return np.where(inside, -dist, dist)
