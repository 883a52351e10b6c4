"""The reference occupancy map of a scene: the MuJoCo world cut at the laser's height.

``scene_map`` returns a ``twin.nav.maps.OccupancyMap``, the type every map of the project is.

A map built from laser scans is only as good as its agreement with the room, and the room is
known exactly in the twin: every geom whose vertical extent contains the cutting height (the
LMS200's scan plane, 0.30 m) contributes its cross-section, and a cell is occupied if any
cross-section overlaps it (with a positive area: touching a cell's edge does not count), so a
4 cm table leg is never lost between 5 cm cells. Cells inside the room and inside nothing are
free; cells outside the room's floor that nothing occupies are unknown (the space behind the
walls).

Cross-sections are convex polygons: exact for boxes (any rotation) and for a mesh's convex hull
(the hull of the points where segments between its vertices, MuJoCo's hull vertices when it has
computed them, cross the plane); cylinders are cut as prisms on 48-gon caps, spheres and
ellipsoids as 48-gons around their exact elliptic slices, capsules as the hull of 48-gons around
the discs their spheres cut (65 along the axis, and the one centred on the plane). Every
polygon circumscribes its curve, so a map never misses a part of an obstacle. A plane that is
not horizontal is a wall: everything behind it is solid, as MuJoCo's collision treats it. Height
fields and SDF geoms are refused.

Which geoms count is what the sim laser sees: the scene's geom groups 0 (collidable) and 1
(decoration), not the robot's (groups 2 and 3 in models/peoplebot.xml), nothing that moves (the
robot on its free joint), and no fully transparent geom (mj_ray skips those too); the floor
never counts.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace

import mujoco
import numpy as np

from twin.core.errors import InputError
from twin.nav.maps import UNKNOWN, OccupancyMap
from twin.sim.world import World

LASER_HEIGHT = 0.30  # m above the floor: the Peoplebot's LMS200 scan plane
SCENE_GROUPS = (0, 1)  # the geom groups the sim laser casts at
_SIDES = 48  # polygon sides for round cross-sections
_EPS = 1e-9  # m: overlaps thinner than this do not count


def scene_map(
    world: World,
    height: float = LASER_HEIGHT,
    resolution: float = 0.05,
    *,
    margin: float = 0.1,
    groups: Iterable[int] = SCENE_GROUPS,
    exclude_bodies: Iterable[str] = (),
) -> OccupancyMap:
    """The scene's occupancy at ``height`` metres above the floor, over the room's floor
    (``World.room_bounds``) grown by ``margin`` metres on every side (so walls outside the floor
    are in it), in cells of ``resolution`` metres; the origin is the grown bounds' lower-left
    corner. ``groups`` are the geom groups that count; ``exclude_bodies`` names bodies (with
    everything under them) to leave out, e.g. a target the laser should not see."""
    if not (math.isfinite(height) and height > 0):
        raise InputError(f"the cutting height must be a positive number of metres, got {height!r}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(f"map resolution must be positive, got {resolution!r} m")
    if not (math.isfinite(margin) and margin >= 0):
        raise InputError(f"the margin must be a number of metres >= 0, got {margin!r}")
    model, data = world.model, world.data
    xmin, ymin, xmax, ymax = world.room_bounds()
    x0, y0 = xmin - margin, ymin - margin
    nx = math.ceil((xmax - xmin + 2 * margin) / resolution - 1e-9)
    ny = math.ceil((ymax - ymin + 2 * margin) / resolution - 1e-9)
    extent = (x0, y0, x0 + nx * resolution, y0 + ny * resolution)
    occupied = np.zeros((ny, nx), dtype=bool)
    for geom in counted_geoms(world, groups, exclude_bodies):
        polygon = cross_section(model, data, geom, height, extent)
        if polygon is not None:
            _rasterise(polygon, occupied, x0, y0, resolution)
    centres_x = x0 + (np.arange(nx) + 0.5) * resolution
    centres_y = y0 + (np.arange(ny) + 0.5) * resolution
    in_room = ((centres_y >= ymin) & (centres_y <= ymax))[:, None] & (
        (centres_x >= xmin) & (centres_x <= xmax)
    )[None, :]
    grid = np.where(occupied, 1.0, np.where(in_room, 0.0, UNKNOWN))
    return OccupancyMap(grid, float(resolution), (float(x0), float(y0), 0.0))


def counted_geoms(
    world: World, groups: Iterable[int] = SCENE_GROUPS, exclude_bodies: Iterable[str] = ()
) -> list[int]:
    """The geoms a scene map cuts: in ``groups``, on a body fixed to the world and not under
    ``exclude_bodies``, not fully transparent, and not the floor."""
    model = world.model
    wanted = {int(g) for g in groups}
    excluded = {world.body_id(name) for name in exclude_bodies}
    found = []
    for geom in range(model.ngeom):
        body = int(model.geom_bodyid[geom])
        if int(model.geom_group[geom]) not in wanted or model.geom(geom).name == "floor":
            continue
        if int(model.body_weldid[body]) != 0:  # it moves: the robot, or anything loose
            continue
        if _transparent(model, geom) or _under(model, body, excluded):
            continue
        found.append(geom)
    return found


def _transparent(model: mujoco.MjModel, geom: int) -> bool:
    material = int(model.geom_matid[geom])
    alpha = model.mat_rgba[material, 3] if material >= 0 else model.geom_rgba[geom, 3]
    return float(alpha) == 0.0


def _under(model: mujoco.MjModel, body: int, roots: set[int]) -> bool:
    while body > 0:
        if body in roots:
            return True
        body = int(model.body_parentid[body])
    return False


def cross_section(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geom: int,
    height: float,
    extent: tuple[float, float, float, float],
) -> np.ndarray | None:
    """The convex (k, 2) polygon (metres, counter-clockwise) where a geom meets the plane
    z = ``height`` in its current pose, or None if it does not reach it; ``extent`` bounds the
    half-plane of a wall plane."""
    kind = int(model.geom_type[geom])
    centre = data.geom_xpos[geom].copy()
    rotation = data.geom_xmat[geom].reshape(3, 3).copy()
    size = model.geom_size[geom]
    types = mujoco.mjtGeom
    if kind == types.mjGEOM_BOX:
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return _slice_hull(centre + (corners * size) @ rotation.T, height)
    if kind == types.mjGEOM_CYLINDER:
        return _slice_hull(_cylinder_vertices(centre, rotation, size[0], size[1]), height)
    if kind in (types.mjGEOM_SPHERE, types.mjGEOM_ELLIPSOID):
        radii = np.full(3, size[0]) if kind == types.mjGEOM_SPHERE else size[:3]
        return _ellipsoid_slice(centre, rotation, radii, height)
    if kind == types.mjGEOM_CAPSULE:
        return _capsule_slice(centre, rotation[:, 2], size[0], size[1], height)
    if kind == types.mjGEOM_MESH:
        return _slice_hull(_mesh_vertices(model, data, geom), height)
    if kind == types.mjGEOM_PLANE:
        return _plane_slice(centre, rotation[:, 2], height, extent)
    name = model.geom(geom).name or f"geom {geom}"
    raise InputError(
        f"geom {name!r} is a {types(kind).name[7:].lower()}, which a scene map cannot cut; "
        "leave its body out with exclude_bodies"
    )


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain: the hull of (n, 2) points counter-clockwise, no point twice."""
    pts = np.unique(np.round(points, 12), axis=0)
    if len(pts) <= 2:
        return pts

    def half(seq: np.ndarray) -> list[np.ndarray]:
        chain: list[np.ndarray] = []
        for p in seq:
            while len(chain) >= 2:
                (ax, ay), (bx, by) = chain[-2], chain[-1]
                if (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) > 0:
                    break
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _slice_hull(vertices: np.ndarray, height: float) -> np.ndarray | None:
    """The cut at z = height of the convex hull of (n, 3) vertices: the hull of the vertices on
    the plane and of the points where segments between vertices below and above cross it."""
    z = vertices[:, 2]
    below, above = vertices[z < height - _EPS], vertices[z > height + _EPS]
    on = vertices[np.abs(z - height) <= _EPS][:, :2]
    if len(below) == 0 or len(above) == 0:
        return None  # touching the plane at most: no area
    a, b = below[:, None, :], above[None, :, :]
    t = (height - a[..., 2]) / (b[..., 2] - a[..., 2])
    crossings = (a[..., :2] + t[..., None] * (b[..., :2] - a[..., :2])).reshape(-1, 2)
    hull = _convex_hull(np.concatenate([on, crossings]))
    return hull if len(hull) >= 3 else None


def _circle(sides: int = _SIDES) -> np.ndarray:
    """(sides, 2) unit-circle directions, scaled to circumscribe the unit circle."""
    phi = (np.arange(sides) + 0.5) * (2.0 * math.pi / sides)
    return np.stack([np.cos(phi), np.sin(phi)], axis=1) / math.cos(math.pi / sides)


def _cylinder_vertices(centre, rotation, radius, half_length) -> np.ndarray:
    ring = _circle() * radius
    rim = ring[:, :1] * rotation[:, 0] + ring[:, 1:] * rotation[:, 1]
    axis = rotation[:, 2] * half_length
    return np.concatenate([centre + axis + rim, centre - axis + rim])


def _ellipsoid_slice(centre, rotation, radii, height) -> np.ndarray | None:
    """The exact ellipse where (p - c)^T M (p - c) <= 1 meets z = height, as a 48-gon around it.
    With p - c = (u, w): u^T A u + 2 w b^T u + w^2 m <= 1, i.e. (u - u0)^T A (u - u0) <= k."""
    shape = rotation @ np.diag(1.0 / np.asarray(radii, dtype=float) ** 2) @ rotation.T
    a, b, m = shape[:2, :2], shape[:2, 2], shape[2, 2]
    w = height - centre[2]
    u0 = -w * np.linalg.solve(a, b)
    k = 1.0 - w * w * m + w * w * float(b @ np.linalg.solve(a, b))
    if k <= _EPS:
        return None
    lower = np.linalg.cholesky(a)  # a = L L^T, so u = u0 + sqrt(k) L^-T v for |v| = 1
    ring = np.linalg.solve(lower.T, _circle().T).T * math.sqrt(k)
    return centre[:2] + u0 + ring


def _capsule_slice(centre, axis, radius, half_length, height) -> np.ndarray | None:
    """The slice of the points within ``radius`` of the axis segment: the hull of the discs
    the spheres along the segment cut (densely sampled, plus the sphere centred on the plane)."""
    t = np.linspace(-1.0, 1.0, 65)
    if abs(axis[2]) > _EPS:
        crossing = (height - centre[2]) / (axis[2] * half_length)
        if -1.0 < crossing < 1.0:
            t = np.append(t, crossing)
    points = centre + t[:, None] * half_length * axis
    depth = radius**2 - (height - points[:, 2]) ** 2
    keep = depth > _EPS
    if not keep.any():
        return None
    discs = points[keep, None, :2] + np.sqrt(depth[keep])[:, None, None] * _circle()[None]
    return _convex_hull(discs.reshape(-1, 2))


def _mesh_vertices(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> np.ndarray:
    """World positions of the mesh's convex hull vertices (all vertices without a hull)."""
    mesh = int(model.geom_dataid[geom])
    start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    local = model.mesh_vert[start : start + count].astype(float)
    graph = int(model.mesh_graphadr[mesh])
    if graph >= 0:  # MuJoCo's hull: numvert, numface, vert_edgeadr[numvert], vert_globalid...
        numvert = int(model.mesh_graph[graph])
        ids = model.mesh_graph[graph + 2 + numvert : graph + 2 + 2 * numvert]
        local = local[np.asarray(ids, dtype=int)]
    rotation = data.geom_xmat[geom].reshape(3, 3)
    return data.geom_xpos[geom] + local @ rotation.T


def _plane_slice(centre, normal, height, extent) -> np.ndarray | None:
    """A plane's solid side (n . (p - c) <= 0) at z = height, clipped to ``extent``: the
    half-plane behind a wall. Horizontal planes (floor, ceiling) cut nothing."""
    if math.hypot(normal[0], normal[1]) < 1e-6:
        return None
    x0, y0, x1, y1 = extent
    polygon = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)
    offset = float(normal @ centre) - normal[2] * height
    clipped = _clip(polygon, normal[:2], offset)
    return clipped if len(clipped) >= 3 else None


def _clip(polygon: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon with normal . q <= offset."""
    out = []
    values = polygon @ normal - offset
    for i in range(len(polygon)):
        p, q, vp, vq = (
            polygon[i],
            polygon[(i + 1) % len(polygon)],
            values[i],
            values[(i + 1) % len(polygon)],
        )
        if vp <= 0:
            out.append(p)
        if (vp < 0 < vq) or (vq < 0 < vp):
            out.append(p + (q - p) * (vp / (vp - vq)))
    return np.array(out).reshape(-1, 2)


def _rasterise(polygon: np.ndarray, occupied: np.ndarray, x0: float, y0: float, res: float):
    """Mark the cells a convex polygon overlaps with positive area (separating axis test on the
    cells of its bounding box)."""
    ny, nx = occupied.shape
    lo, hi = polygon.min(axis=0), polygon.max(axis=0)
    c0 = max(math.floor((lo[0] - x0) / res + 1e-9), 0)
    c1 = min(math.ceil((hi[0] - x0) / res - 1e-9), nx)
    r0 = max(math.floor((lo[1] - y0) / res + 1e-9), 0)
    r1 = min(math.ceil((hi[1] - y0) / res - 1e-9), ny)
    if c0 >= c1 or r0 >= r1:
        return
    cx = x0 + (np.arange(c0, c1) + 0.5) * res
    cy = y0 + (np.arange(r0, r1) + 0.5) * res
    gx, gy = np.meshgrid(cx, cy)
    overlap = np.ones(gx.shape, dtype=bool)
    edges = np.roll(polygon, -1, axis=0) - polygon
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    for n in normals:
        length = math.hypot(n[0], n[1])
        if length < 1e-15:
            continue
        n = n / length
        projected = polygon @ n
        centre = gx * n[0] + gy * n[1]
        half = 0.5 * res * (abs(n[0]) + abs(n[1]))
        overlap &= (centre - half < projected.max() - _EPS) & (
            centre + half > projected.min() + _EPS
        )
    occupied[r0:r1, c0:c1] |= overlap


FLAT = 0.05  # m: furniture no taller than this (a rug) is driven over


def drive_map(world: World, occupancy: OccupancyMap) -> OccupancyMap:
    """``occupancy`` (the laser's map) with every piece of furniture's and every target's whole
    floor outline marked occupied: what the robot must plan its drives around.

    The laser sees a table's legs at its height, not the top that overhangs them at 0.7 m, and
    the robot's 1.2 m column would hit that top; so the planner keeps clear of each furniture
    body's convex outline over all its geoms (``World.footprint``), whatever their height. A
    target standing on the floor lower than the laser's plane (a toy crate in the hall) is
    as much in the way, and invisible to the laser too. The localizer keeps the laser's own
    map."""
    cells = np.array(occupancy.occupancy, dtype=float, copy=True)
    blocked = np.zeros(occupancy.shape, dtype=bool)
    x0, y0 = occupancy.origin[0], occupancy.origin[1]
    for name in (*world.furniture(), *world.targets()):
        outline = world.footprint(name)
        if outline.top > FLAT:
            _rasterise(outline.polygon, blocked, x0, y0, occupancy.resolution)
    cells[blocked] = 1.0
    return replace(occupancy, occupancy=cells)
