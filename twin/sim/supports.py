"""Where an object could stand in a scene: the horizontal tops of the room's geoms, shelves
under shelves included, worked out analytically from the geoms' shapes.

The room is every geom on a body welded to the world (walls, furniture, decorations, jointless
targets) that is either drawn (groups 0-2, what the renderer shows) or collidable: the robot's
bodies move, so they are never part of it. A camera sees the visual-only geoms (the sofa's
cushions, the books on the shelves) as well as the collidable ones, so an object must stand on
whichever is on top.

Every geom type the scenes use is convex (box, sphere, ellipsoid, cylinder, capsule, and the
floor's half-space plane), so a vertical line meets it in one interval [bottom, top], computed
exactly from the geom's pose and size (``vertical_spans``). The top is a *level* where its
surface normal is within 10 degrees of straight up and nothing occupies the space just above
it (a seat under a cushion, a shelf under a book, the floor under the sofa are covered).
Meshes, height fields and SDFs are bounded by their oriented bounding box (``geom_aabb``): a
stand-in, exact for none of them, which no scene here needs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.core.errors import InputError
from twin.core.visibility import SupportLevels, TallMap
from twin.sim.world import World

LEVEL_SLOPE = math.radians(10.0)  # radians: the most a standing surface's normal may tilt
COVER_TOLERANCE = 0.005  # metres: a geom starting this close above a top merely rests on it
MERGE_TOLERANCE = 0.01  # metres: tops this close (a rug on the floor) are one level, the higher
RENDERED_GROUPS = np.array([1, 1, 1, 0, 0, 0], dtype=np.uint8)  # what the renderer draws

_G = mujoco.mjtGeom
_ROUND = (int(_G.mjGEOM_SPHERE), int(_G.mjGEOM_ELLIPSOID))
_BOXED = (int(_G.mjGEOM_BOX), int(_G.mjGEOM_MESH), int(_G.mjGEOM_HFIELD), int(_G.mjGEOM_SDF))


def subtree_bodies(world: World, names: Iterable[str]) -> set[int]:
    """Ids of the named bodies and every body below them."""
    roots = {world.body_id(name) for name in names}
    found = set()
    for body in range(world.model.nbody):
        walk = body
        while walk != 0 and walk not in roots:
            walk = int(world.model.body_parentid[walk])
        if walk in roots:
            found.add(body)
    return found


def room_geoms(world: World, exclude: Iterable[str] = ()) -> np.ndarray:
    """Ids of the room's geoms: on a body welded to the world (so not the robot), drawn
    (groups 0-2) or collidable, and not on the bodies named in ``exclude`` or below them."""
    model = world.model
    skip = subtree_bodies(world, exclude)
    body = model.geom_bodyid
    static = model.body_weldid[body] == 0
    drawn = (model.geom_group <= 2) & (model.geom_rgba[:, 3] > 0)
    solid = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    keep = static & (drawn | solid) & ~np.isin(body, list(skip))
    return np.flatnonzero(keep)


@dataclass(frozen=True)
class Spans:
    """Where vertical lines meet geoms: ``bottom``, ``top`` (G, N) heights in metres (NaN where
    line n misses geom g; -inf/+inf for half-spaces) and ``top_up`` (G, N), the vertical
    component of the surface normal at the top (1 for a level top, NaN where there is none)."""

    geoms: np.ndarray
    bottom: np.ndarray
    top: np.ndarray
    top_up: np.ndarray

    def levels(self, headroom: float = 0.0) -> np.ndarray:
        """(G, N) heights of the tops an object could stand on, NaN elsewhere: level within
        ``LEVEL_SLOPE``, and no geom within ``headroom`` metres above (nor just above: a seat
        under its cushion is no support, a cushion resting on it does not cover the cushion)."""
        with np.errstate(invalid="ignore"):
            g, n = np.nonzero(np.isfinite(self.top) & (self.top_up >= math.cos(LEVEL_SLOPE)))
        z = self.top[g, n]
        low = z + COVER_TOLERANCE
        high = z + max(headroom, 2 * COVER_TOLERANCE)
        # every geom on the candidate's line against the segment above it: (G, candidates)
        covered = ((self.bottom[:, n] < high) & (self.top[:, n] > low)).any(axis=0)
        out = np.full(self.top.shape, np.nan)
        out[g[~covered], n[~covered]] = z[~covered]
        return out

    def occupied(self, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """(N,) whether any geom meets the vertical segment [``low``, ``high``] (N,) metres of
        each line; geoms merely touching an end do not count."""
        hit = (self.bottom < np.asarray(high, float)) & (self.top > np.asarray(low, float))
        return hit.any(axis=0)  # NaN compares False: a line that misses a geom


def vertical_spans(world: World, geoms: np.ndarray, xy: np.ndarray) -> Spans:
    """Intersect the vertical lines through ``xy`` (N, 2) metres with ``geoms`` (G,), exactly
    for the convex primitive types (see the module's note for meshes)."""
    model, data = world.model, world.data
    geoms = np.asarray(geoms, dtype=int)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    shape = (len(geoms), len(xy))
    bottom, top, up = (np.full(shape, np.nan) for _ in range(3))
    points = np.column_stack([xy, np.zeros(len(xy))])
    types = model.geom_type[geoms]
    for kind in np.unique(types):
        rows = np.flatnonzero(types == kind)
        ids = geoms[rows]
        centre = data.geom_xpos[ids].copy()
        rot = data.geom_xmat[ids].reshape(-1, 3, 3)
        size = model.geom_size[ids].copy()
        if kind in _BOXED[1:]:  # bounding box: offset centre, half sizes
            aabb = model.geom_aabb[ids]
            centre += np.einsum("gij,gj->gi", rot, aabb[:, :3])
            size = aabb[:, 3:].copy()
        # the line through point p is p + z e_z; in the geom's frame, a + z b
        a = np.einsum("gji,gnj->gni", rot, points[None, :, :] - centre[:, None, :])
        b = rot[:, 2, :]  # (G, 3): e_z in the geom's frame
        if kind in _BOXED:
            lo, hi, nz = _box(a, b, size)
        elif kind in _ROUND:
            if kind == int(_G.mjGEOM_SPHERE):
                size = np.repeat(size[:, :1], 3, axis=1)
            lo, hi, nz = _ellipsoid(a, b, size)
        elif kind == int(_G.mjGEOM_CYLINDER):
            lo, hi, nz = _cylinder(a, b, size[:, 0], size[:, 1])
        elif kind == int(_G.mjGEOM_CAPSULE):
            lo, hi, nz = _capsule(a, b, size[:, 0], size[:, 1])
        elif kind == int(_G.mjGEOM_PLANE):
            lo, hi, nz = _plane(a, b, size)
        else:
            raise InputError(
                f"{world.path.name}: geom {int(ids[0])} has type {int(kind)}, which support "
                "geometry cannot handle; give it a primitive shape"
            )
        bottom[rows], top[rows], up[rows] = lo, hi, nz
    return Spans(geoms, bottom, top, up)


def _slabs(a: np.ndarray, b: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per axis, the z interval where |a + z b| <= half; (-inf, inf) or empty if b is 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - a) / b
        t2 = (half - a) / b
    flat = np.abs(b) < 1e-12
    inside = np.abs(a) <= half
    lo = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    return lo, hi


def _box(a: np.ndarray, b: np.ndarray, size: np.ndarray):
    lo, hi = _slabs(a, np.broadcast_to(b[:, None, :], a.shape), size[:, None, :])
    low, high = lo.max(axis=2), hi.min(axis=2)
    face = hi.argmin(axis=2)  # the axis whose face the line leaves through, at the top
    nz = np.abs(np.take_along_axis(np.broadcast_to(b[:, None, :], a.shape), face[..., None], 2))
    return _missed(low, high, nz[..., 0])


def _missed(low: np.ndarray, high: np.ndarray, nz: np.ndarray):
    miss = ~(low <= high)
    return (
        np.where(miss, np.nan, low),
        np.where(miss, np.nan, high),
        np.where(miss | ~np.isfinite(high), np.nan, nz),
    )


def _roots(qa: np.ndarray, qb: np.ndarray, qc: np.ndarray):
    """Roots of qa z^2 + qb z + qc = 0 (qa > 0), NaN where there are none."""
    disc = qb * qb - 4 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(np.where(disc >= 0, disc, np.nan))
        return (-qb - root) / (2 * qa), (-qb + root) / (2 * qa)


def _ellipsoid(a: np.ndarray, b: np.ndarray, size: np.ndarray):
    an, bn = a / size[:, None, :], (b / size)[:, None, :]
    low, high = _roots(
        np.broadcast_to((bn * bn).sum(axis=2), an.shape[:2]),
        2 * (an * bn).sum(axis=2),
        (an * an).sum(axis=2) - 1,
    )
    # normal: the gradient of sum((u / size)^2) at the top, u = a + z b in the geom's frame
    grad = (an + high[..., None] * bn) / size[:, None, :]
    with np.errstate(invalid="ignore"):
        nz = (grad * b[:, None, :]).sum(axis=2) / np.linalg.norm(grad, axis=2)
    return _missed(low, high, nz)


def _cylinder(a: np.ndarray, b: np.ndarray, radius: np.ndarray, half: np.ndarray):
    bx, by, bz = (np.broadcast_to(b[:, None, i], a.shape[:2]) for i in range(3))
    r = radius[:, None]
    qa = bx * bx + by * by
    qb = 2 * (a[..., 0] * bx + a[..., 1] * by)
    qc = a[..., 0] ** 2 + a[..., 1] ** 2 - r * r
    upright = qa < 1e-12  # the axis is vertical: the round wall holds at every height or none
    safe = np.where(upright, 1.0, qa)
    r_lo, r_hi = _roots(safe, qb, qc)
    r_lo = np.where(upright, np.where(qc <= 0, -np.inf, np.nan), r_lo)
    r_hi = np.where(upright, np.where(qc <= 0, np.inf, np.nan), r_hi)
    s_lo, s_hi = _slabs(a[..., 2], bz, half[:, None])
    low, high = np.fmax(r_lo, s_lo), np.fmin(r_hi, s_hi)
    low = np.where(np.isnan(r_lo), np.nan, low)
    high = np.where(np.isnan(r_hi), np.nan, high)
    # the top is on the cap unless the round wall ends lower (a lying cylinder)
    with np.errstate(invalid="ignore"):
        wall_top = r_hi < s_hi
        ux, uy = a[..., 0] + high * bx, a[..., 1] + high * by
        nz = np.where(wall_top, (ux * bx + uy * by) / r, np.abs(bz))
    return _missed(low, high, nz)


def _capsule(a: np.ndarray, b: np.ndarray, radius: np.ndarray, half: np.ndarray):
    """A capsule is convex: the union of its cylinder's and end spheres' intervals."""
    parts = [_cylinder(a, b, radius, half)]
    ball = np.repeat(radius[:, None], 3, axis=1)
    for sign in (-1.0, 1.0):
        end = np.zeros_like(ball)
        end[:, 2] = sign * half
        parts.append(_ellipsoid(a - end[:, None, :], b, ball))
    lows = np.stack([p[0] for p in parts])
    highs = np.stack([p[1] for p in parts])
    nzs = np.stack([p[2] for p in parts])
    hit = ~np.isnan(highs).all(axis=0)
    which = np.argmax(np.where(np.isnan(highs), -np.inf, highs), axis=0)
    low = np.where(hit, np.nanmin(np.where(hit, lows, 0.0), axis=0), np.nan)
    high = np.take_along_axis(highs, which[None], 0)[0]
    nz = np.take_along_axis(nzs, which[None], 0)[0]
    return low, high, nz


def _plane(a: np.ndarray, b: np.ndarray, size: np.ndarray):
    """A plane is the half-space below its local z = 0, within its size (0: unbounded)."""
    bz = np.broadcast_to(b[:, None, 2], a.shape[:2])
    tilted = np.abs(bz) > 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        z0 = np.where(tilted, -a[..., 2] / np.where(tilted, bz, 1.0), 0.0)
    inside = np.ones(a.shape[:2], dtype=bool)
    for axis in (0, 1):
        extent = size[:, None, axis]
        at = a[..., axis] + z0 * b[:, None, axis]
        inside &= (extent <= 0) | (np.abs(at) <= extent)
    below = a[..., 2] <= 0  # for a vertical plane: the line is wholly behind it or not at all
    low = np.where(tilted, np.where(bz > 0, -np.inf, z0), np.where(below, -np.inf, np.nan))
    high = np.where(tilted, np.where(bz > 0, z0, np.inf), np.where(below, np.inf, np.nan))
    low, high = np.where(inside, low, np.nan), np.where(inside, high, np.nan)
    nz = np.where(tilted & (bz > 0) & inside, bz, np.nan)
    return low, high, nz


def support_levels(
    world: World, cell_size: float = 0.1, max_height: float = 2.0, *, headroom: float = 0.05
) -> SupportLevels:
    """The heights (m) at which an object could stand in each plan cell of the room.

    The grid covers ``world.room_bounds()`` in cells of ``cell_size`` metres (row 0 at y_min);
    each cell's levels are those at its centre, ascending and NaN-padded: the floor where it is
    free, seat cushions (not the seat frame under them), table tops and what stands on them,
    every bookcase shelf free at that point and the top of each book on it, up to
    ``max_height``, each with at least ``headroom`` metres free above it (the 3 cm under a
    bookcase's bottom shelf holds nothing). The robot and the scene's targets are left out:
    this is the room without the things sought. A cell inside a wall or a solid piece of
    furniture keeps only its tops at or below ``max_height`` (the floor there is covered); the
    scenes' walls stand outside the floor, so the grid holds none of them. Levels closer than
    1 cm merge into the higher one (a rug on the floor, a magazine on a table).
    """
    if not (math.isfinite(cell_size) and cell_size > 0):
        raise InputError(f"support cell size must be a positive distance, got {cell_size!r} m")
    if not (math.isfinite(max_height) and max_height >= 0):
        raise InputError(f"support max height must be a height >= 0 m, got {max_height!r}")
    if not (math.isfinite(headroom) and headroom >= 0):
        raise InputError(f"support headroom must be a distance >= 0 m, got {headroom!r}")
    x_min, y_min, ny, nx, centres = _cell_centres(world, cell_size)
    levels = vertical_spans(world, room_geoms(world, world.targets()), centres).levels(headroom)
    with np.errstate(invalid="ignore"):
        levels = np.where(levels <= max_height + 1e-9, np.maximum(levels, 0.0), np.nan)
    per_cell = np.sort(levels, axis=0).T  # (N, G) ascending, NaN last
    rows = [_merge(row[np.isfinite(row)]) for row in per_cell]
    k = max(1, max(len(row) for row in rows))
    out = np.full((len(rows), k), np.nan)
    for n, row in enumerate(rows):
        out[n, : len(row)] = row
    return SupportLevels(x_min, y_min, cell_size, out.reshape(ny, nx, k))


def _cell_centres(world: World, cell_size: float) -> tuple[float, float, int, int, np.ndarray]:
    """The plan grid over ``world.room_bounds()``: its lower-left corner, its rows and columns,
    and its (rows x columns, 2) cell centres in metres, row by row from y_min."""
    x_min, y_min, x_max, y_max = world.room_bounds()
    nx = max(1, math.ceil((x_max - x_min) / cell_size - 1e-9))
    ny = max(1, math.ceil((y_max - y_min) / cell_size - 1e-9))
    gx, gy = np.meshgrid(
        x_min + (np.arange(nx) + 0.5) * cell_size, y_min + (np.arange(ny) + 0.5) * cell_size
    )
    return x_min, y_min, ny, nx, np.column_stack([gx.ravel(), gy.ravel()])


def _merge(heights: np.ndarray) -> list[float]:
    """Ascending heights, each run closer than ``MERGE_TOLERANCE`` kept as its highest."""
    merged: list[float] = []
    for h in heights:
        if merged and h - merged[-1] < MERGE_TOLERANCE:
            merged[-1] = float(h)
        else:
            merged.append(float(h))
    return merged


# A wall or a solid piece of furniture: one geom standing from below the laser's plane to above
# what the camera sees over (a wall, a wardrobe's door, a bookcase's side, the fridge).
TALL_BAND = (0.3, 1.5)


def tall_map(
    world: World, cell_size: float = 0.1, band: tuple[float, float] = TALL_BAND
) -> TallMap:
    """The room's cells where one geom spans the whole ``band`` of heights (metres) at the
    cell's centre: visibility sees nothing past them (``twin.core.visibility.TallMap``). A
    floor lamp's pole or a wall cabinet over a counter does not count; the grid covers
    ``world.room_bounds()``, as ``support_levels`` does."""
    if not (math.isfinite(cell_size) and cell_size > 0):
        raise InputError(f"tall map cell size must be a positive distance, got {cell_size!r} m")
    x_min, y_min, ny, nx, centres = _cell_centres(world, cell_size)
    spans = vertical_spans(world, room_geoms(world, world.targets()), centres)
    with np.errstate(invalid="ignore"):
        solid = (spans.bottom <= band[0]) & (spans.top >= band[1])
    return TallMap(x_min, y_min, cell_size, solid.any(axis=0).reshape(ny, nx))
