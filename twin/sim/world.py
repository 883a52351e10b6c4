"""One MuJoCo world: a scene loaded from ``scenes/``, its clock, and its ground truth.

The scene's world frame is the map frame (x right, y up, metres, origin at the room's lower-left
corner, z up from the floor), so poses read here need no conversion. Furniture is every named,
jointless body directly under the world that is not a target; targets are listed by the scene in
its custom text ``twin_targets``.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from twin.core.errors import InputError, TwinError
from twin.core.geometry import Footprint, Pose2D
from twin.resources import scenes_dir

DEFAULT_SCENE = "living_room"


def scene_path(scene: str | Path) -> Path:
    """Resolve a scene name (``living_room``) or an MJCF path to an existing file."""
    text = str(scene)
    is_path = text.endswith(".xml") or "/" in text
    path = Path(text) if is_path else scenes_dir() / f"{text}.xml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in scenes_dir().glob("*.xml")))
        raise InputError(f"scene {text!r}: no such file {path}; use one of: {known}, or a path")
    return path


def load_model(path: str | Path) -> mujoco.MjModel:
    """Compile an MJCF file; a compile error becomes one line naming the file."""
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else "compile error"
        raise TwinError(f"{path}: MuJoCo cannot compile it ({first}); fix the MJCF") from exc


def _convex_hull(points: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain; returns the hull counter-clockwise without repeating a point."""
    pts = sorted({(round(float(x), 6), round(float(y), 6)) for x, y in points})
    if len(pts) <= 2:
        return np.array(pts, dtype=float)

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    upper: list[tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1], dtype=float)


def _distance_to_polygon(point: np.ndarray, polygon: np.ndarray) -> float:
    """Distance (m) from a point to a convex CCW polygon; negative inside."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    edge, rel = b - a, point - a
    t = np.clip(np.einsum("ij,ij->i", rel, edge) / np.einsum("ij,ij->i", edge, edge), 0.0, 1.0)
    dist = float(np.min(np.linalg.norm(rel - t[:, None] * edge, axis=1)))
    inside = bool(np.all(edge[:, 0] * rel[:, 1] - edge[:, 1] * rel[:, 0] >= 0.0))
    return -dist if inside else dist


_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


class World:
    """A compiled scene with its state. Physics advances only through ``step``."""

    def __init__(self, scene: str | Path = DEFAULT_SCENE) -> None:
        self.path = scene_path(scene)
        self.model = load_model(self.path)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        # As loaded, so that a reused world can be put back: what placing and lighting edit.
        self._loaded_bodies = (self.model.body_pos.copy(), self.model.body_quat.copy())
        self._loaded_lights = (
            self.model.light_diffuse.copy(),
            self.model.vis.headlight.diffuse.copy(),
            self.model.vis.headlight.ambient.copy(),
        )
        # Geom shapes as the files define them: what run-time changes (the sim robot's wheel
        # errors) are measured from, so that applying them twice does not compound.
        self._loaded_geoms = (self.model.geom_size.copy(), self.model.geom_pos.copy())

    def reset(self) -> None:
        """Put the world back as it was loaded: bodies moved by ``place_static_body`` return,
        the lights take their scene intensities, and the physics restarts at time 0 (MuJoCo's
        reset state, no warm start). A mission in a reset world runs as in a fresh one."""
        self.model.body_pos[:], self.model.body_quat[:] = self._loaded_bodies
        self.scale_lighting(1.0)
        mujoco.mj_resetData(self.model, self.data)
        self.forward()

    def scale_lighting(self, factor: float) -> None:
        """Scale the diffuse intensity of every scene light, and the headlight's diffuse and
        ambient, by ``factor`` relative to the scene's own (1 is the scene as written)."""
        if not (math.isfinite(factor) and factor >= 0.0):
            raise InputError(f"a lighting scale must be a finite number >= 0, got {factor!r}")
        diffuse, head_diffuse, head_ambient = self._loaded_lights
        self.model.light_diffuse[:] = diffuse * factor
        self.model.vis.headlight.diffuse[:] = head_diffuse * factor
        self.model.vis.headlight.ambient[:] = head_ambient * factor

    # -- clock and stepping -------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated seconds since the world was loaded."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def step(self, n: int = 1) -> None:
        mujoco.mj_step(self.model, self.data, nstep=n)

    def forward(self) -> None:
        mujoco.mj_forward(self.model, self.data)

    def warnings(self) -> dict[str, int]:
        """MuJoCo warnings raised so far (name -> count); empty when the physics is healthy."""
        found = {}
        for warning in mujoco.mjtWarning.__members__.values():
            if warning.name == "mjNWARNING":
                continue
            count = int(self.data.warning[int(warning)].number)
            if count:
                found[warning.name] = count
        return found

    # -- names and ground truth -----------------------------------------------------------------
    def body_id(self, name: str) -> int:
        body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        if body < 0:
            raise InputError(
                f"{self.path.name}: no body named {name!r}; known: {', '.join(self.body_names())}"
            )
        return body

    def body_names(self) -> list[str]:
        names = (self.model.body(i).name for i in range(1, self.model.nbody))
        return [name for name in names if name]

    def loaded_geom(self, geom: int) -> tuple[np.ndarray, np.ndarray]:
        """(size (3,), position (3,) in its body) of a geom as the scene files define it, metres,
        whatever was changed at run time since."""
        size, pos = self._loaded_geoms
        return size[geom].copy(), pos[geom].copy()

    def geom_owner(self, geom: int) -> str:
        """What a geom belongs to, for messages: the name of its top-level body (the furniture,
        e.g. "coffee_table"), or the geom's own name if it hangs on the world (a wall)."""
        body = int(self.model.geom_bodyid[geom])
        if body == 0:
            return self.model.geom(geom).name or f"geom {geom}"
        root = int(self.model.body_rootid[body])
        return self.model.body(root).name or f"body {root}"

    def is_ground(self, geom: int) -> bool:
        """True for the floor: the geom named "floor", or an upward-facing plane on the world."""
        model = self.model
        if model.geom(geom).name == "floor":
            return True
        return (
            int(model.geom_type[geom]) == int(mujoco.mjtGeom.mjGEOM_PLANE)
            and int(model.geom_bodyid[geom]) == 0
            and float(self.data.geom_xmat[geom, 8]) > 0.99
        )

    def body_position(self, name: str) -> np.ndarray:
        """World position (3,) of a body's frame, metres (ground truth)."""
        return self.data.xpos[self.body_id(name)].copy()

    def body_pose(self, name: str) -> Pose2D:
        """Planar pose of a body's frame: x, y in metres, yaw of its +x axis in radians."""
        body = self.body_id(name)
        xmat = self.data.xmat[body].reshape(3, 3)
        x, y, _ = self.data.xpos[body]
        return Pose2D(float(x), float(y), math.atan2(xmat[1, 0], xmat[0, 0]))

    def _custom_text(self, name: str) -> str | None:
        idx = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_TEXT, name)
        if idx < 0:
            return None
        start, size = int(self.model.text_adr[idx]), int(self.model.text_size[idx])
        return bytes(self.model.text_data[start : start + size]).rstrip(b"\0").decode("utf-8")

    def _custom_numeric(self, name: str) -> np.ndarray | None:
        idx = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
        if idx < 0:
            return None
        start, size = int(self.model.numeric_adr[idx]), int(self.model.numeric_size[idx])
        return np.array(self.model.numeric_data[start : start + size], dtype=float)

    def targets(self) -> tuple[str, ...]:
        """Names of the bodies the scene declares as targets (custom text ``twin_targets``)."""
        text = self._custom_text("twin_targets") or ""
        return tuple(text.replace(",", " ").split())

    def target_supports(self) -> dict[str, tuple[str, ...]]:
        """Each target's kinds of support (custom text ``twin_target_supports``: entries
        "name:kind" or "name:kind|kind" separated by spaces, kinds as in
        ``twin.core.visibility.SUPPORT_KINDS``); targets it does not name are left out."""
        text = self._custom_text("twin_target_supports") or ""
        found: dict[str, tuple[str, ...]] = {}
        targets = self.targets()
        for entry in text.split():
            name, _, kinds = entry.partition(":")
            if name not in targets or not kinds:
                raise InputError(
                    f"{self.path.name}: twin_target_supports entry {entry!r} must be "
                    f'"target:kind" for one of the targets {", ".join(targets)}'
                )
            found[name] = tuple(kinds.split("|"))
        return found

    def robot_start(self) -> Pose2D | None:
        """The scene's suggested robot start (custom numeric ``twin_robot_start``), or None."""
        values = self._custom_numeric("twin_robot_start")
        return None if values is None or values.size != 3 else Pose2D(*map(float, values))

    def room_bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the floor geom named ``floor``, metres."""
        geom = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        if geom < 0:
            raise InputError(f"{self.path.name}: has no geom named 'floor' to bound the room")
        cx, cy, _ = self.model.geom_pos[geom]
        sx, sy, _ = self.model.geom_size[geom]
        return float(cx - sx), float(cy - sy), float(cx + sx), float(cy + sy)

    def furniture(self) -> list[str]:
        """Static bodies under the world that are not targets: what the robot must drive round."""
        targets = set(self.targets())
        names = []
        for body in range(1, self.model.nbody):
            name = self.model.body(body).name
            if (
                name
                and self.model.body_parentid[body] == 0
                and self.model.body_weldid[body] == 0
                and name not in targets
            ):
                names.append(name)
        return names

    def footprint(self, name: str) -> Footprint:
        """Convex outline on the floor of every geom of a body and its descendants (metres)."""
        root = self.body_id(name)
        corners = []
        top = 0.0
        for geom in range(self.model.ngeom):
            body = int(self.model.geom_bodyid[geom])
            while body not in (0, root):
                body = int(self.model.body_parentid[body])
            if body != root:
                continue
            centre, half = self.model.geom_aabb[geom, :3], self.model.geom_aabb[geom, 3:]
            local = centre + _CORNERS * half
            world = self.data.geom_xpos[geom] + local @ self.data.geom_xmat[geom].reshape(3, 3).T
            corners.append(world)
            top = max(top, float(world[:, 2].max()))
        if not corners:
            raise InputError(f"{self.path.name}: body {name!r} has no geoms, so no footprint")
        return Footprint(name, _convex_hull(np.concatenate(corners)[:, :2]), top)

    def footprints(self) -> dict[str, Footprint]:
        """Footprints of all furniture and targets, by body name (for drawing grid maps)."""
        return {name: self.footprint(name) for name in (*self.furniture(), *self.targets())}

    def check_free(self, x: float, y: float, clearance: float, what: str) -> None:
        """Raise ``InputError`` unless (x, y) is in the room and ``clearance`` metres from every
        wall and piece of furniture (e.g. the robot's radius, for a pose it should stand at)."""
        xmin, ymin, xmax, ymax = self.room_bounds()
        if not (
            xmin + clearance <= x <= xmax - clearance and ymin + clearance <= y <= ymax - clearance
        ):
            raise InputError(
                f"{what} ({x:.2f}, {y:.2f}) m is not {clearance:.2f} m inside the "
                f"room [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}]; choose another"
            )
        for name in self.furniture():
            gap = _distance_to_polygon(np.array([x, y]), self.footprint(name).polygon)
            if gap < clearance:
                where = f"inside the {name}" if gap <= 0 else f"{gap:.2f} m from the {name}"
                raise InputError(
                    f"{what} ({x:.2f}, {y:.2f}) m is {where}, closer than "
                    f"{clearance:.2f} m; choose another"
                )

    def path_clearance(self, start: tuple[float, float], end: tuple[float, float]) -> float:
        """Smallest distance (m) from the straight segment start-end to any furniture (negative
        if it passes through one): a straight drive needs more than the robot's half-width."""
        length = math.dist(start, end)
        points = np.linspace(start, end, max(2, int(length / 0.02) + 1))
        polygons = [self.footprint(name).polygon for name in self.furniture()]
        return min(_distance_to_polygon(point, polygon) for polygon in polygons for point in points)

    # -- placing static objects -----------------------------------------------------------------
    def surface_height(self, x: float, y: float, exclude: str | None = None) -> float:
        """Height (m) of the first visible surface below (x, y), cast down from 3 m: the scene's
        collidable geoms and its decorations (a cushion on a seat, a book on a shelf), so that
        what is placed there stands on what a camera sees, not inside it."""
        geomid = np.zeros(1, dtype=np.int32)
        body_exclude = -1 if exclude is None else self.body_id(exclude)
        # groups 0 (collidable) and 1 (decoration) are the scene; the robot's are 2 and 3
        groups = np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8)
        dist = mujoco.mj_ray(
            self.model,
            self.data,
            np.array([x, y, 3.0]),
            np.array([0, 0, -1.0]),
            groups,
            True,
            body_exclude,
            geomid,
        )
        return 0.0 if dist < 0 else 3.0 - float(dist)

    def support_of(self, name: str) -> str:
        """The furniture whose footprint holds the body's (x, y) position, or "floor"."""
        x, y = (float(v) for v in self.body_position(name)[:2])
        for other in self.furniture():
            if other == name:
                continue
            xmin, ymin, xmax, ymax = self.footprint(other).aabb
            if xmin <= x <= xmax and ymin <= y <= ymax:
                return other
        return "floor"

    def place_static_body(self, name: str, x: float, y: float, yaw: float) -> Pose2D:
        """Move a jointless body (e.g. a target) to stand on whatever surface is below (x, y).

        This edits the model, so it is meant for setting a scene up before a run, not for moving
        things during one. Returns the body's new planar pose.
        """
        body = self.body_id(name)
        if self.model.body_weldid[body] != 0 or self.model.body_parentid[body] != 0:
            raise InputError(f"{name!r} is not a static body under the world; it cannot be placed")
        xmin, ymin, xmax, ymax = self.room_bounds()
        if not (xmin <= x <= xmax and ymin <= y <= ymax):
            raise InputError(
                f"cannot place {name!r} at ({x:.2f}, {y:.2f}) m: outside the room "
                f"[{xmin}, {xmax}] x [{ymin}, {ymax}]"
            )
        # lowest point of the body's geoms below its frame (geoms assumed upright in it)
        aabb, pos = self.model.geom_aabb, self.model.geom_pos
        bottom = min(
            float(pos[g, 2] + aabb[g, 2] - aabb[g, 5])
            for g in range(self.model.ngeom)
            if self.model.geom_bodyid[g] == body
        )
        z = self.surface_height(x, y, exclude=name) - bottom
        self.model.body_pos[body] = (x, y, z)
        self.model.body_quat[body] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        self.forward()
        return self.body_pose(name)
