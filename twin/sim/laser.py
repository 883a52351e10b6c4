"""The Peoplebot's SICK LMS200 in the twin: MuJoCo ray casting at the scan rate, with the noise,
dropouts and range limit the data sheet gives.

One ``mujoco.mj_multiRay`` call casts every beam of a scan from the ``laser`` site of
models/peoplebot.xml (0.30 m above the floor, +x the zero beam) at the scene's geom groups 0 and
1 only: the robot's geoms are in groups 2 and 3, so it never sees itself. It sees what stands at
0.30 m (table legs, the sofa's front, walls, the bookcase's lowest books), not what the camera
sees. Scans are cast at the scan rate of simulated time, by a step listener on the ``SimRobot``,
so a drive keeps a fresh ``latest_scan`` without per-step rangefinder sensors.

The noise model (LMS200 technical description, mm mode, ranges up to 8 m): a systematic error of
up to +-15 mm, drawn once per device from the seed (a constant offset: it depends on the unit,
the target and temperature, not on the scan), a statistical error of 5 mm (1 sigma) per beam and
scan, readings in whole millimetres, NaN beyond ``max_range``, and a small seeded share of beams
that drop out (NaN) as dark or glancing targets do. Not modelled: the beam's divergence and the
mixed readings it gives at depth edges, and the 13 ms sweep (a scan is cast from one pose).

Units: metres, radians, seconds of simulated time (the clock ``SimCamera.now`` reads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from twin.core.devices import DeviceTimeoutError, Laser, LaserMount, NotConnectedError, Scan
from twin.core.errors import InputError

if TYPE_CHECKING:
    from twin.sim.robot import SimRobot
    from twin.sim.world import World

LASER_SITE = "laser"
# The scene's groups: 0 collidable, 1 decoration; the robot's 2 (visible) and 3 (wheel spheres).
SCENE_GROUPS = np.array([1, 1, 0, 0, 0, 0], dtype=np.uint8)
# SICK LMS200 technical description, mm mode (range <= 8 m): systematic error +-15 mm,
# statistical error 5 mm (1 sigma), 1 mm resolution of the reading.
LMS200_SIGMA = 0.005  # m
LMS200_SYSTEMATIC = 0.015  # m
LMS200_RESOLUTION = 0.001  # m


@dataclass(frozen=True)
class LaserSpec:
    """What the sim laser does. ``beams`` over ``fov`` (181: 1 degree, 361: 0.5 degree over
    180 degrees), ``max_range`` (m; farther is NaN), ``rate`` (scans per simulated second),
    ``range_sigma`` (m, 1 sigma per beam), ``systematic`` (m: the device's constant offset is
    drawn uniformly from +-this), ``dropout`` (share of beams returning NaN), ``resolution`` (m,
    readings rounded to it; 0 for none), ``seed`` for all of the randomness."""

    beams: int = 181
    fov: float = math.pi
    max_range: float = 8.0
    rate: float = 10.0
    range_sigma: float = LMS200_SIGMA
    systematic: float = LMS200_SYSTEMATIC
    dropout: float = 0.002
    resolution: float = LMS200_RESOLUTION
    seed: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.beams, int) and self.beams >= 2):
            raise InputError(
                f"laser beams must be an integer >= 2 (181 or 361), got {self.beams!r}"
            )
        checks = (
            ("fov", self.fov, 0.0 < self.fov <= 2.0 * math.pi, "in (0, 2 pi] rad"),
            ("max_range", self.max_range, self.max_range > 0.0, "positive, metres"),
            ("rate", self.rate, self.rate > 0.0, "positive, scans per second"),
            ("range_sigma", self.range_sigma, self.range_sigma >= 0.0, ">= 0, metres"),
            ("systematic", self.systematic, self.systematic >= 0.0, ">= 0, metres"),
            ("dropout", self.dropout, 0.0 <= self.dropout < 1.0, "in [0, 1)"),
            ("resolution", self.resolution, self.resolution >= 0.0, ">= 0, metres"),
        )
        for name, value, ok, want in checks:
            if not (math.isfinite(value) and ok):
                raise InputError(f"laser {name} must be {want}, got {value!r}")

    @property
    def angles(self) -> np.ndarray:
        """Beam bearings (rad), counter-clockwise from the zero beam, increasing (right first)."""
        return np.linspace(-0.5 * self.fov, 0.5 * self.fov, self.beams)


class RayCaster:
    """A fan of horizontal rays (in the site's x-y plane) from one site, cast with a single
    ``mj_multiRay`` call at the scene's geoms (``groups``); buffers are reused between casts."""

    def __init__(
        self,
        model: mujoco.MjModel,
        site: int,
        angles: np.ndarray,
        max_range: float,
        groups: np.ndarray = SCENE_GROUPS,
    ) -> None:
        self.model, self.site, self.max_range, self.groups = model, site, max_range, groups
        self.angles = np.asarray(angles, dtype=float)
        self._local = self._directions(self.angles)
        n = self.angles.size
        self._geomid = np.zeros(n, dtype=np.int32)
        self._dist = np.zeros(n, dtype=np.float64)
        self.last_geoms = np.full(n, -1, dtype=np.int32)

    @staticmethod
    def _directions(angles: np.ndarray) -> np.ndarray:
        return np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)

    def cast(self, data: mujoco.MjData, angles: np.ndarray | None = None) -> np.ndarray:
        """True ranges (m) along ``angles`` (rad; default the fan's) from the site's current
        pose: NaN where nothing lies within ``max_range``. ``data`` must be forwarded."""
        if angles is None:
            local, geomid, dist = self._local, self._geomid, self._dist
        else:
            angles = np.asarray(angles, dtype=float).ravel()
            local = self._directions(angles)
            geomid = np.zeros(angles.size, dtype=np.int32)
            dist = np.zeros(angles.size, dtype=np.float64)
        n = local.shape[0]
        if n == 0:
            return np.zeros(0)
        rotation = data.site_xmat[self.site].reshape(3, 3)
        vec = np.ascontiguousarray(local @ rotation.T).ravel()
        mujoco.mj_multiRay(
            self.model,
            data,
            data.site_xpos[self.site],
            vec,
            self.groups,
            1,  # static geoms (walls, furniture) count
            -1,  # no body excluded: the groups keep the robot out
            geomid,
            dist,
            None,
            n,
            self.max_range,
        )
        ranges = dist.copy()
        missed = (geomid < 0) | (dist < 0.0) | (dist > self.max_range)
        ranges[missed] = np.nan
        self.last_geoms = np.where(missed, -1, geomid)  # what each beam hit (-1: nothing)
        return ranges


def laser_site(model: mujoco.MjModel, name: str = LASER_SITE) -> int:
    """The id of the laser's site; ``InputError`` if the model has none."""
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if site < 0:
        raise InputError(f"the model has no site named {name!r}; does it include peoplebot.xml?")
    return site


def cast(world: World, spec: LaserSpec | None = None, site: str = LASER_SITE) -> np.ndarray:
    """True ranges (m, NaN for no return within range) of one noiseless scan from the laser site
    at the world's current state, beams as ``spec.angles`` (for tests and tools; a ``SimLaser``
    keeps its own caster)."""
    spec = spec or LaserSpec()
    caster = RayCaster(world.model, laser_site(world.model, site), spec.angles, spec.max_range)
    return caster.cast(world.data)


class SimLaser(Laser):
    """The LMS200 on the sim robot: scans of simulated time with the data sheet's noise.

    While connected it casts a scan whenever simulated time crosses a multiple of
    ``1 / spec.rate`` (a ``SimRobot`` step listener), whoever steps the world: a drive, the
    head, ``scan`` itself, or the serial twins' runner thread. ``latest_scan`` is the newest of
    them (for a guard that checks the path ahead during a drive); ``scan`` steps the world to
    the next one. ``ranges_at`` casts any bearings at once (a wire emulator's range source).
    """

    name = "sim laser"

    def __init__(self, robot: SimRobot, spec: LaserSpec | None = None) -> None:
        self.robot = robot
        self.spec = spec or LaserSpec()
        model = robot.world.model
        self.site = laser_site(model)
        self._angles = self.spec.angles
        self._angles.setflags(write=False)
        self._caster = RayCaster(model, self.site, self._angles, self.spec.max_range)
        self._rng = np.random.default_rng(self.spec.seed)
        # the unit's systematic error: one constant offset, drawn first from the seed
        self.offset = float(self._rng.uniform(-self.spec.systematic, self.spec.systematic))
        x, y, z = (float(v) for v in model.site_pos[self.site])
        w, _, _, qz = (float(v) for v in model.site_quat[self.site])
        self._mount = LaserMount(x, y, z, 2.0 * math.atan2(qz, w))
        self._half_step = 0.5 * robot.world.timestep
        self._slot: int | None = None
        self._latest: Scan | None = None
        self._connected = False

    def restart(self) -> None:
        """As after power-on in a world that was reset (``World.reset``, ``SimRobot.place``):
        the noise restarts from the seed (the same unit offset) and no earlier scan is kept, so
        a mission in a reused world sees what it would in a fresh one."""
        with self.robot.lock:
            self._rng = np.random.default_rng(self.spec.seed)
            self.offset = float(self._rng.uniform(-self.spec.systematic, self.spec.systematic))
            self._latest = None
            self._slot = self._slot_now() if self._connected else None

    # -- device ---------------------------------------------------------------------------------
    @property
    def mount(self) -> LaserMount:
        return self._mount

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        with self.robot.lock:
            if not self._connected:
                self._slot = self._slot_now()  # the scan under way began before: not ours
                self._latest = None
                self.robot.listeners.append(self._on_step)
            self._connected = True

    def close(self) -> None:
        with self.robot.lock:
            if self._on_step in self.robot.listeners:
                self.robot.listeners.remove(self._on_step)
            self._connected = False

    def scan(self, timeout: float = 2.0) -> Scan:
        """The first scan that begins after this call: steps the world (under the robot's lock)
        to the next multiple of ``1 / rate`` seconds; ``DeviceTimeoutError`` if that is more than
        ``timeout`` simulated seconds away."""
        self.require_connected("scan")
        robot = self.robot
        with robot.lock:
            start = robot.world.time
            while self._latest is None or self._latest.timestamp <= start:
                if robot.world.time - start > timeout:
                    raise DeviceTimeoutError(
                        self.name,
                        f"scan within {timeout:g} s",
                        f"no scan began in {timeout:g} s simulated at {self.spec.rate:g} scans/s",
                        "allow at least one scan period",
                    )
                robot.step()
            return self._latest

    def latest_scan(self) -> Scan | None:
        """The newest scan cast so far while connected (None before the first), without
        stepping: what the laser last saw, e.g. during a drive."""
        if not self._connected:
            raise NotConnectedError(
                self.name, "read the latest scan", "the device is not connected", "connect it first"
            )
        return self._latest

    def ranges_at(self, angles: np.ndarray) -> np.ndarray:
        """Ranges (m) the laser reads now along ``angles`` (rad, in its frame), with the same
        noise, dropouts and NaN beyond range as its scans; steps nothing. The range source for a
        wire-protocol emulator of the LMS200."""
        with self.robot.lock:
            true = self._caster.cast(self.robot.world.data, np.asarray(angles, dtype=float))
            return self._noisy(true)

    # -- scanning -------------------------------------------------------------------------------
    def _slot_now(self) -> int:
        return math.floor((self.robot.world.time + self._half_step) * self.spec.rate)

    def _on_step(self, robot: SimRobot) -> None:
        slot = self._slot_now()
        if self._slot is not None and slot > self._slot:
            self._latest = self._cast_scan()
        elif self._slot is not None and slot < self._slot:
            self._latest = None  # the world was reset: its clock restarted
        self._slot = slot

    def _cast_scan(self) -> Scan:
        world = self.robot.world
        ranges = self._noisy(self._caster.cast(world.data))
        return Scan(self._angles, ranges, world.time, self.spec.max_range)

    def _noisy(self, true: np.ndarray) -> np.ndarray:
        """Apply the device's offset, statistical noise, rounding, range limit and dropouts."""
        spec, n = self.spec, true.size
        ranges = true + self.offset + spec.range_sigma * self._rng.standard_normal(n)
        if spec.resolution > 0.0:
            ranges = np.round(ranges / spec.resolution) * spec.resolution
        ranges = np.maximum(ranges, 0.0)
        ranges[~(ranges <= spec.max_range)] = np.nan  # also keeps NaN (no return) NaN
        ranges[self._rng.random(n) < spec.dropout] = np.nan
        return ranges
