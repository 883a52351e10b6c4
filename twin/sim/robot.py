"""The simulated Peoplebot: wheel and head servos driven through the physics, wheel odometry,
and the sim implementations of ``twin.core.devices`` that share one ``World``.

Nothing here moves the robot by writing its pose except ``SimRobot.place``, which sets the
start of a run (like lifting the robot onto its start mark). Driving and panning go through the
actuators: the base by wheel speeds, the head by speed commands that the VC-C4-limited servos
integrate (see models/peoplebot.xml).

The twin is never kinder than the real base: its wheels may differ from what odometry assumes
(``OdometryErrors``, made physically true in the MuJoCo model), a motor that strains stalls
(``StallMonitor``), and any touch of the robot on anything but the floor while driving stops the
base with a ``DeviceFaultError`` naming what was touched and where.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.core.devices import (
    PIONEER_LIMITS,
    Base,
    BaseLimits,
    BumpedError,
    Camera,
    DeviceFaultError,
    DeviceTimeoutError,
    Frame,
    OutOfRangeError,
    PanTilt,
    PanTiltLimits,
    Robot,
)
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D, wrap_angle
from twin.sim.camera_effects import CameraEffects
from twin.sim.drive import (
    DiffDriveGeometry,
    GoToController,
    Odometry,
    OdometryErrors,
    StallMonitor,
)
from twin.sim.laser import LaserSpec, SimLaser
from twin.sim.render import FrameRenderer
from twin.sim.world import DEFAULT_SCENE, World

CAMERA_NAME = "head_camera"
ROBOT_CLEARANCE = 0.3  # m: the base's half-diagonal; a pose this far from furniture is free
PAPER_CAMERA = CameraModel()  # 320x240, 45 degrees horizontal: the paper's camera
HEAD_TOLERANCE = math.radians(0.2)  # a pan-tilt move is over when the joint is this close
# Driving needs under 1 N m per wheel; pushing against furniture takes the friction limit
# (8-12 N m in stick-slip). A wheel stalls when it strains above STALL_TORQUE for at least
# STALL_DUTY of the last STALL_TIME seconds (see drive.StallMonitor).
STALL_TORQUE = 3.0  # N m
STALL_TIME = 0.5  # s
STALL_DUTY = 0.5


@dataclass(frozen=True)
class Contact:
    """A touch between the robot and the scene: which robot geom, which scene geom and what it
    belongs to (e.g. "coffee_table"), and where (map frame, metres)."""

    robot_geom: str
    scene_geom: str
    owner: str
    position: tuple[float, float, float]
    normal: tuple[float, float, float] = (0.0, 0.0, 0.0)  # unit, from the robot into the scene

    def describe(self) -> str:
        x, y, z = self.position
        return (
            f"its {self.robot_geom} touched the {self.owner} ({self.scene_geom}) at "
            f"({x:.2f}, {y:.2f}, {z:.2f}) m"
        )


BUMPER_SECTOR = math.radians(30.0)  # a bumper tells the segment it was pressed on, not the point


def bumper_bearing(pose: Pose2D, contact: Contact) -> float:
    """The direction (robot frame, rad) the robot pressed against the scene, as the Peoplebot's
    segmented bumpers would give it: to the nearest 30 degrees. From the contact's normal, not
    from the centre to the point: an overhang (a table top) meets the column behind the
    centre, a wall meets a corner of the chassis, and both push straight back."""
    nx, ny, _ = contact.normal
    if math.hypot(nx, ny) < 1e-6:  # pressed from straight above or below: the point's side
        nx, ny = contact.position[0] - pose.x, contact.position[1] - pose.y
    bearing = float(wrap_angle(math.atan2(ny, nx) - pose.yaw))
    return float(wrap_angle(round(bearing / BUMPER_SECTOR) * BUMPER_SECTOR))


def _fmt(pose: Pose2D) -> str:
    return f"({pose.x:.2f}, {pose.y:.2f}) m, {math.degrees(pose.yaw):.1f} deg"


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    idx = mujoco.mj_name2id(model, kind, name)
    if idx < 0:
        raise InputError(
            f"the scene has no {kind.name[6:].lower()} named {name!r}; "
            "does it include models/peoplebot.xml?"
        )
    return idx


class SimRobot:
    """The Peoplebot in a ``World``: the one place that steps the physics for it.

    Every blocking motion advances simulated time by stepping the world, applying the wheel and
    head controls and integrating odometry at every physics step. ``odometry_errors`` makes the
    wheels differ from what odometry assumes (see ``set_odometry_errors``).
    """

    def __init__(
        self,
        world: World,
        start: Pose2D | None = None,
        limits: BaseLimits = PIONEER_LIMITS,
        odometry_errors: OdometryErrors | None = None,
    ) -> None:
        self.world = world
        m = world.model
        self.drive_limits = limits
        self._base = _id(m, mujoco.mjtObj.mjOBJ_BODY, "base")
        self._free_qpos = int(m.jnt_qposadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, "base")])
        self._free_qvel = int(m.jnt_dofadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, "base")])
        self._wheel_qpos = [
            int(m.jnt_qposadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, n)])
            for n in ("left_wheel", "right_wheel")
        ]
        self._wheel_act = [
            _id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ("left_wheel", "right_wheel")
        ]
        self._head_qpos = [
            int(m.jnt_qposadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in ("pan", "tilt")
        ]
        self._head_act = [_id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ("pan", "tilt")]
        self._head_actadr = [int(m.actuator_actadr[a]) for a in self._head_act]
        self._head_qvel = [
            int(m.jnt_dofadr[_id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in ("pan", "tilt")
        ]
        self.camera_id = _id(m, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA_NAME)
        # The geometry odometry assumes: the MJCF's as written (the world keeps it even after
        # set_odometry_errors changed the physical wheels), so odometry and the file agree.
        geom = mujoco.mjtObj.mjOBJ_GEOM
        self._wheel_geoms = [_id(m, geom, n) for n in ("left_wheel", "right_wheel")]
        self._tyre_geoms = [_id(m, geom, n) for n in ("left_tyre", "right_tyre")]
        wheel_size, _ = world.loaded_geom(self._wheel_geoms[0])
        centres = [
            m.body_pos[m.geom_bodyid[g]] + world.loaded_geom(g)[1] for g in self._wheel_geoms
        ]
        self.geometry = DiffDriveGeometry(
            float(wheel_size[0]), float(np.linalg.norm(centres[0] - centres[1]))
        )
        # contacts: every geom of the robot (1) against every scene geom (2) but the floor (0);
        # a plain list, as the check runs at every step of a drive and pairs are few
        root = int(m.body_rootid[self._base])
        self._geom_side = [
            1 if int(m.body_rootid[m.geom_bodyid[g]]) == root else 0 if world.is_ground(g) else 2
            for g in range(m.ngeom)
        ]
        self.stall = StallMonitor(STALL_TORQUE, STALL_TIME, STALL_DUTY)
        lo, hi = m.actuator_ctrlrange[self._head_act[0]]
        tlo, thi = m.actuator_ctrlrange[self._head_act[1]]
        plo, phi = m.actuator_actrange[self._head_act[0]]
        klo, khi = m.actuator_actrange[self._head_act[1]]
        self.head_limits = PanTiltLimits(
            float(plo),
            float(phi),
            float(klo),
            float(khi),
            float(min(-lo, hi)),
            float(min(-tlo, thi)),
        )
        self._head_goal = [0.0, 0.0]
        self._head_speed = [self.head_limits.pan_speed, self.head_limits.tilt_speed]
        self._wheels = (0.0, 0.0)
        self._speed = 0.0
        self._touching_at_start: set[tuple[str, str]] = set()
        # called after every physics step (recorders, wire-protocol emulators, tests)
        self.listeners: list[Callable[[SimRobot], None]] = []
        # Held while stepping and rendering: the serial twins step the world from a thread.
        self.lock = threading.RLock()
        self.odometry = Odometry(self.geometry, Pose2D(0.0, 0.0, 0.0), 0.0, 0.0)
        self.set_odometry_errors(odometry_errors or OdometryErrors())
        self.place(start or world.robot_start() or Pose2D(0.0, 0.0, 0.0))

    # -- state ----------------------------------------------------------------------------------
    def _wheel_angles(self) -> tuple[float, float]:
        q = self.world.data.qpos
        return float(q[self._wheel_qpos[0]]), float(q[self._wheel_qpos[1]])

    def truth_pose(self) -> Pose2D:
        """Ground-truth pose of the base (map frame)."""
        d = self.world.data
        xmat = d.xmat[self._base].reshape(3, 3)
        return Pose2D(
            float(d.xpos[self._base, 0]),
            float(d.xpos[self._base, 1]),
            math.atan2(xmat[1, 0], xmat[0, 0]),
        )

    def odometry_pose(self) -> Pose2D:
        """The wheel-odometry estimate, anchored at the last ``place``/``set_pose``."""
        return self.odometry.pose

    def head(self) -> tuple[float, float]:
        """Current (pan, tilt) joint angles, radians."""
        q = self.world.data.qpos
        return float(q[self._head_qpos[0]]), float(q[self._head_qpos[1]])

    def head_rates(self) -> tuple[float, float]:
        """Current (pan, tilt) joint speeds, rad/s."""
        v = self.world.data.qvel
        return float(v[self._head_qvel[0]]), float(v[self._head_qvel[1]])

    def camera_position(self) -> np.ndarray:
        """Ground-truth optical centre (3,), metres."""
        return self.world.data.cam_xpos[self.camera_id].copy()

    def contacts(self) -> list[Contact]:
        """Touches between the robot and anything in the scene but the floor, now."""
        d, m, side = self.world.data, self.world.model, self._geom_side
        if d.ncon == 0:
            return []
        found = []
        for i, (a, b) in enumerate(d.contact.geom[: d.ncon].tolist()):
            if side[a] + side[b] != 3:  # robot-floor, scene-scene, robot-robot
                continue
            robot, other = (a, b) if side[a] == 1 else (b, a)
            # the contact normal points from geom[0] to geom[1]: make it robot -> scene
            normal = d.contact.frame[i, :3] * (1.0 if robot == a else -1.0)
            found.append(
                Contact(
                    m.geom(robot).name or f"geom {robot}",
                    m.geom(other).name or f"geom {other}",
                    self.world.geom_owner(other),
                    tuple(float(v) for v in d.contact.pos[i]),
                    (float(normal[0]), float(normal[1]), float(normal[2])),
                )
            )
        return found

    # -- setting up -----------------------------------------------------------------------------
    def set_odometry_errors(self, errors: OdometryErrors) -> None:
        """Make the physical wheels differ from what odometry assumes, and seed the slip noise.

        The MuJoCo wheels (and the tyres drawn over them) take the radii and spacing
        ``errors.physical`` gives; odometry keeps the nominal ``self.geometry``. Measured from
        the model as loaded, so setting errors twice does not compound. The slip noise restarts
        from ``errors.seed`` here and at every ``place``.
        """
        m = self.world.model
        left, right, track = errors.physical(self.geometry)
        shift = 0.5 * (track - self.geometry.track)
        for wheel, tyre, radius, side in zip(
            self._wheel_geoms, self._tyre_geoms, (left, right), (1.0, -1.0), strict=True
        ):
            for geom in (wheel, tyre):
                size, pos = self.world.loaded_geom(geom)
                pos[1] += side * shift  # along the axle, which stays the hinge axis
                kind = int(m.geom_type[geom])
                # the rolling circle is in the geom's x-y plane, its z axis is the axle; the
                # bounding radius and box are what the collision broad phase and renderer use
                if kind == int(mujoco.mjtGeom.mjGEOM_ELLIPSOID):
                    size[0] = size[1] = radius
                    half_width = float(size[2])
                    bound = max(radius, half_width)
                elif kind == int(mujoco.mjtGeom.mjGEOM_SPHERE):
                    size[0] = half_width = bound = radius
                else:  # cylinder: radius, half-length
                    size[0], half_width = radius, float(size[1])
                    bound = math.hypot(radius, half_width)
                m.geom_size[geom] = size
                m.geom_pos[geom] = pos
                m.geom_rbound[geom] = bound
                m.geom_aabb[geom, 3:] = (radius, radius, half_width)
        self.odometry_errors = errors
        self.odometry.slip_noise = errors.slip_noise
        self.odometry.rng = np.random.default_rng(errors.seed)
        self.world.forward()

    def place(self, pose: Pose2D, pan: float = 0.0, tilt: float = 0.0, settle: float = 0.3) -> None:
        """Put the robot at rest at ``pose`` with the head at (pan, tilt), then let it settle.

        Only for the start of a run; odometry is anchored to ``pose``.
        """
        self.head_limits.check("sim pan-tilt", pan, tilt)
        d = self.world.data
        d.qpos[self._free_qpos : self._free_qpos + 7] = (
            pose.x,
            pose.y,
            0.0,
            math.cos(pose.yaw / 2),
            0.0,
            0.0,
            math.sin(pose.yaw / 2),
        )
        d.qvel[self._free_qvel : self._free_qvel + 6] = 0.0
        for qadr, actadr, angle in zip(
            self._head_qpos, self._head_actadr, (pan, tilt), strict=True
        ):
            d.qpos[qadr] = angle
            d.act[actadr] = angle
        self._head_goal = [pan, tilt]
        self._wheels = (0.0, 0.0)
        self._speed = 0.0
        self.world.forward()
        self.advance(settle)
        self.odometry.rng = np.random.default_rng(self.odometry_errors.seed)
        self.reset_odometry(pose)

    def reset_odometry(self, pose: Pose2D) -> None:
        """Anchor the odometry estimate at ``pose`` (moves nothing)."""
        self.odometry.reset(pose, *self._wheel_angles())

    # -- stepping -------------------------------------------------------------------------------
    def _apply_controls(self) -> None:
        d, dt = self.world.data, self.world.timestep
        left, right = self._wheels
        d.ctrl[self._wheel_act[0]] = left
        d.ctrl[self._wheel_act[1]] = right
        # head: speed command that lands the integrated setpoint on the goal without overshoot
        for act, actadr, goal, speed in zip(
            self._head_act, self._head_actadr, self._head_goal, self._head_speed, strict=True
        ):
            rate = (goal - float(d.act[actadr])) / dt
            d.ctrl[act] = min(max(rate, -speed), speed)  # plain floats: this runs every step

    def step(self) -> None:
        with self.lock:
            self._apply_controls()
            self.world.step()
            self.odometry.update(*self._wheel_angles())
            for listener in self.listeners:
                listener(self)

    def advance(self, seconds: float) -> None:
        """Let simulated time pass with the current commands."""
        for _ in range(max(0, round(seconds / self.world.timestep))):
            self.step()

    def _run_until(
        self, finished: Callable[[], bool], timeout: float, what: str, device: str
    ) -> None:
        end = self.world.time + timeout
        while not finished():
            if self.world.time >= end:
                raise DeviceTimeoutError(
                    device,
                    what,
                    f"not finished after {timeout:g} s simulated (truth {_fmt(self.truth_pose())})",
                    "check the path is free or allow more time",
                )
            self.step()

    # -- base -----------------------------------------------------------------------------------
    def set_wheel_speeds(self, v: float, omega: float) -> None:
        self._speed = float(v)  # the body speed asked for, m/s: what a pressed bumper stalls
        limit = float(self.world.model.actuator_ctrlrange[self._wheel_act[0], 1])
        left, right = self.geometry.wheel_speeds(v, omega)
        self._wheels = (float(np.clip(left, -limit, limit)), float(np.clip(right, -limit, limit)))

    def go_to(self, goal: Pose2D, timeout: float = 60.0) -> Pose2D:
        """Drive to ``goal`` by wheel speeds (turn, drive, turn) closed on odometry."""
        controller = GoToController(goal, self.drive_limits)
        dt = self.world.timestep
        end = self.world.time + timeout
        asked = f"go to {_fmt(goal)}"
        self._begin()
        while not controller.done:
            if self.world.time >= end:
                self.set_wheel_speeds(0.0, 0.0)
                raise DeviceTimeoutError(
                    "sim base",
                    f"go to {_fmt(goal)}",
                    f"not there after {timeout:g} s "
                    f"simulated; odometry {_fmt(self.odometry_pose())}",
                    "check that the path is free of furniture",
                )
            self.set_wheel_speeds(*controller.command(self.odometry_pose(), dt))
            self.step()
            self._guard(asked)
        self.set_wheel_speeds(0.0, 0.0)
        self.advance(0.2)  # let the servos bring the wheels to rest
        return self.odometry_pose()

    def _fault(self, asked: str, seen: str, bearing: float | None = None) -> DeviceFaultError:
        """Stop the wheels, let the base come to rest (up to 1 s), and build the fault to raise;
        ``seen`` gets the truth pose at rest appended (a knock can still turn the base). With a
        ``bearing`` (robot frame, rad) it is a ``BumpedError``."""
        self.set_wheel_speeds(0.0, 0.0)
        qvel = self.world.data.qvel
        for _ in range(20):
            self.advance(0.05)
            base = qvel[self._free_qvel : self._free_qvel + 6]
            if np.abs(base[:3]).max() < 1e-3 and np.abs(base[3:]).max() < 1e-2:
                break
        args = (
            "sim base",
            asked,
            f"{seen}; at rest at {_fmt(self.truth_pose())} (truth)",
            "choose a stop with a free straight path to it, and check the pose estimate "
            "(odometry drifts)",
        )
        if bearing is None:
            return DeviceFaultError(*args)
        return BumpedError(*args, bearing=bearing)

    def _begin(self) -> None:
        """A drive begins: the stall monitor starts afresh, and the touches felt now are known."""
        self.stall.reset()
        self._touching_at_start = {(t.robot_geom, t.scene_geom) for t in self.contacts()}

    def _guard(self, asked: str) -> None:
        """Raise ``DeviceFaultError`` if the robot touches the scene (anything but the floor) or
        a wheel motor stalls; called after every physics step of a drive.

        The stall is like the Pioneer's flag (motor current, ``StallMonitor``), not a position
        check: the wheels slip against an obstacle, so odometry alone would think the base moves.
        A touch is caught at once, even one that turns the base without straining the motors.
        A touch the base already felt when the drive began (``_begin``) stops it only while it
        drives into it, as the firmware's bump stall stops travel toward a pressed bumper: a
        base at rest against a crate otherwise could never leave it (every later drive, away
        from it too, failed at its first step). A jam still stalls the motors.
        """
        touches = self.contacts()
        if touches:
            pose = self.truth_pose()
            for touch in touches:
                bearing = bumper_bearing(pose, touch)
                known = (touch.robot_geom, touch.scene_geom) in self._touching_at_start
                if known and self._speed * math.cos(bearing) <= 1e-6 * abs(self._speed):
                    continue  # resting against it, and not pushing on
                raise self._fault(
                    asked, f"contact: {touch.describe()}, truth pose {_fmt(pose)}", bearing
                )
        torque = self.world.data.actuator_force[self._wheel_act]
        left, right = self.stall.update(self.world.time, float(torque[0]), float(torque[1]))
        if left or right:
            which = "left and right" if left and right else "left" if left else "right"
            pose = self.truth_pose()
            raise self._fault(
                asked, f"{which} wheel motor stalled: the path is blocked at {_fmt(pose)}"
            )

    def drive(self, speed: float, turn_rate: float, duration: float) -> Pose2D:
        """Hold body speed (m/s) and turn rate (rad/s) for ``duration`` seconds, then stop."""
        self.set_wheel_speeds(speed, turn_rate)
        self._begin()
        asked = f"drive {speed:.2f} m/s, {turn_rate:.2f} rad/s for {duration:g} s"
        for _ in range(max(0, round(duration / self.world.timestep))):
            self.step()
            self._guard(asked)
        self.set_wheel_speeds(0.0, 0.0)
        self.advance(0.2)
        return self.odometry_pose()

    # -- head -----------------------------------------------------------------------------------
    def command_head(self, pan: float, tilt: float, speed: float | None = None) -> None:
        """Start moving the head toward (pan, tilt) at up to ``speed`` rad/s (default: the
        VC-C4's top speeds) and return at once; the motion happens as time is stepped."""
        self.head_limits.check("sim pan-tilt", pan, tilt, speed)
        self._head_goal = [pan, tilt]
        self._head_speed = [
            min(speed or math.inf, self.head_limits.pan_speed),
            min(speed or math.inf, self.head_limits.tilt_speed),
        ]

    def head_settled(self) -> bool:
        """True once the head rests within ``HEAD_TOLERANCE`` of its commanded angles."""
        still = max(map(abs, self.head_rates())) < math.radians(1.0)
        return still and all(
            abs(a - g) < HEAD_TOLERANCE for a, g in zip(self.head(), self._head_goal, strict=True)
        )

    def move_head(
        self, pan: float, tilt: float, speed: float | None = None, timeout: float = 10.0
    ) -> tuple[float, float]:
        """Move the head and step the world until it has settled there; returns (pan, tilt)."""
        self.command_head(pan, tilt, speed)
        self._run_until(
            self.head_settled,
            timeout,
            f"move to pan {math.degrees(pan):.1f} deg, tilt {math.degrees(tilt):.1f} deg",
            "sim pan-tilt",
        )
        return self.head()

    def stop_head(self) -> None:
        d = self.world.data
        self._head_goal = [float(d.act[a]) for a in self._head_actadr]

    def devices(
        self,
        camera: CameraModel = PAPER_CAMERA,
        pose_source: str = "odometry",
        laser: LaserSpec | None = None,
    ) -> Robot:
        """The sim camera, pan-tilt, base and (given its spec) laser as a
        ``twin.core.devices.Robot`` (see ``SimBase`` for ``pose_source``)."""
        return Robot(
            SimCamera(self, camera),
            SimPanTilt(self),
            SimBase(self, pose_source),
            None if laser is None else SimLaser(self, laser),
        )


class _SimDevice:
    name = "sim device"

    def __init__(self, robot: SimRobot) -> None:
        self.robot = robot
        self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected


class SimCamera(_SimDevice, Camera):
    """The head camera, rendered offscreen; opens its GL context on ``connect``.

    Each frame carries its depth (metres along each pixel's ray, NaN where nothing is within
    range) for the visibility model, unless ``depth`` is False: a depth pass costs another
    render, which runs that need no visibility (or stand in for a real camera) can skip.

    ``effects`` makes the camera as imperfect as the VC-C4 (``twin.sim.camera_effects``): with
    a lens, each frame is rendered undistorted at the effects' wider canvas and bent through the
    lens (colour and depth alike), then exposed, balanced, noised, blurred by the head's and
    base's turning and JPEG-coded, seeded by ``seed``. ``model`` is what the mission believes
    the camera is (the true lens, or a calibrated one). Without effects (or with
    ``EffectSettings.ideal()``) frames are exactly the plain renderer's.
    """

    name = "sim camera"

    def __init__(
        self,
        robot: SimRobot,
        model: CameraModel = PAPER_CAMERA,
        *,
        depth: bool = True,
        effects: CameraEffects | None = None,
        seed: int = 0,
    ) -> None:
        super().__init__(robot)
        self.depth = depth
        if effects is not None and effects.settings.is_ideal:
            effects = None
        if effects is not None and (effects.width, effects.height) != (model.width, model.height):
            raise InputError(
                f"sim camera: effects are for {effects.width}x{effects.height} frames but the "
                f"camera model is {model.width}x{model.height}; build both for one size"
            )
        self.effects = effects
        self.seed = seed
        self._rng = np.random.default_rng(seed)
        self._last_grab: float | None = None
        self._clock = robot.world.time  # the world's time at the last physics step seen
        self._reset_seen = False
        fovy = float(robot.world.model.cam_fovy[robot.camera_id])
        lens_renders = effects is not None and effects.settings.lens is not None
        if not lens_renders and abs(fovy - math.degrees(model.vfov)) > 0.01:
            raise OutOfRangeError(
                self.name,
                f"render {model.width}x{model.height} at {math.degrees(model.hfov):.1f} deg hfov",
                f"the MJCF camera has fovy {fovy:.3f} deg, not {math.degrees(model.vfov):.3f}",
                "match the camera's fovy to CameraModel.vfov",
            )
        self._model = model
        self._renderer: FrameRenderer | None = None

    @property
    def model(self) -> CameraModel:
        return self._model

    def connect(self) -> None:
        if self._renderer is None:
            width, height = (
                self.effects.canvas_size
                if self.effects is not None
                else (self._model.width, self._model.height)
            )
            self._renderer = FrameRenderer(self.robot.world.model, width, height, CAMERA_NAME)
        if self.effects is not None and self._watch not in self.robot.listeners:
            self.robot.listeners.append(self._watch)
        self._connected = True

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._watch in self.robot.listeners:
            self.robot.listeners.remove(self._watch)
        self._connected = False

    def _watch(self, robot: SimRobot) -> None:
        """After every physics step: a clock that ran back means the world was reset (a batch
        or an environment reuses it), and the camera restarts as at power-on."""
        now = robot.world.time
        if now < self._clock:
            self._reset_seen = True
        self._clock = now

    def restart(self, seed: int | None = None) -> None:
        """As after power-on in a world that was reset: the noise restarts from ``seed`` (the
        camera's own by default; a batch may give each run its own) and the exposure and white
        balance forget what they had settled on, so a mission in a reused world sees what it
        would in a fresh one."""
        with self.robot.lock:
            if seed is not None:
                self.seed = seed
            self._rng = np.random.default_rng(self.seed)
            self._last_grab = None
            self._reset_seen = False
            if self.effects is not None:
                self.effects.reset()

    def rates(self) -> tuple[float, float]:
        """The camera's (horizontal, vertical) angular rates now, rad/s: pan plus the base's
        turn, and tilt (what smears a frame during its exposure)."""
        pan_rate, tilt_rate = self.robot.head_rates()
        yaw_rate = float(self.robot.world.data.qvel[self.robot._free_qvel + 5])
        return pan_rate + yaw_rate, tilt_rate

    def grab(self) -> Frame:
        self.require_connected("grab a frame")
        assert self._renderer is not None
        with self.robot.lock:
            data = self.robot.world.data
            now = self.robot.world.time
            if self.effects is None:
                image = self._renderer.render(data)
                depth = self._renderer.depth(data) if self.depth else None
                return Frame(image, now, depth)
            if self._reset_seen or (self._last_grab is not None and now < self._last_grab):
                self.restart()  # the world's clock ran back: it was reset, as at power-on
            image, depth = self._render_canvas(data)
            dt = None if self._last_grab is None else now - self._last_grab
            self._last_grab = now
            image, depth = self.effects.apply(image, depth, self._rng, self.rates(), dt)
            return Frame(image, now, depth)

    def _render_canvas(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray | None]:
        """The undistorted frame the effects start from: at the lens's wider canvas field (the
        MJCF camera's fovy is swapped in for this render only, and restored)."""
        assert self._renderer is not None and self.effects is not None
        model, cam = self.robot.world.model, self.robot.camera_id
        if self.effects.settings.lens is None:
            image = self._renderer.render(data)
            return image, self._renderer.depth(data) if self.depth else None
        saved = float(model.cam_fovy[cam])
        model.cam_fovy[cam] = math.degrees(self.effects.canvas_fovy)
        try:
            image = self._renderer.render(data)
            depth = self._renderer.depth(data) if self.depth else None
        finally:
            model.cam_fovy[cam] = saved
        return image, depth

    def now(self) -> float:
        return self.robot.world.time


class SimPanTilt(_SimDevice, PanTilt):
    name = "sim pan-tilt"

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        if self._connected:
            self.robot.stop_head()
        self._connected = False

    @property
    def limits(self) -> PanTiltLimits:
        return self.robot.head_limits

    def move_to(
        self, pan: float, tilt: float = 0.0, *, speed: float | None = None, timeout: float = 10.0
    ) -> tuple[float, float]:
        self.require_connected("move")
        return self.robot.move_head(pan, tilt, speed, timeout)

    def position(self) -> tuple[float, float]:
        self.require_connected("read the position")
        return self.robot.head()

    def stop(self) -> None:
        self.require_connected("stop")
        self.robot.stop_head()


class SimBase(_SimDevice, Base):
    """The base. ``pose()`` reports wheel odometry by default, as the real base does; with
    ``pose_source="truth"`` it reports the ground truth, standing in for the paper's
    SLAM-localized robot ("the pose of the robot is known at all times")."""

    name = "sim base"
    POSE_SOURCES = ("odometry", "truth")

    def __init__(self, robot: SimRobot, pose_source: str = "odometry") -> None:
        super().__init__(robot)
        if pose_source not in self.POSE_SOURCES:
            raise InputError(
                f"sim base pose source {pose_source!r}: use one of {', '.join(self.POSE_SOURCES)}"
            )
        self.pose_source = pose_source

    def connect(self) -> None:
        self._connected = True

    def close(self) -> None:
        if self._connected:
            self.robot.set_wheel_speeds(0.0, 0.0)
        self._connected = False

    def pose(self) -> Pose2D:
        self.require_connected("read the pose")
        if self.pose_source == "truth":
            return self.robot.truth_pose()
        return self.robot.odometry_pose()

    def set_pose(self, pose: Pose2D) -> None:
        self.require_connected("set the pose")
        self.robot.reset_odometry(pose)

    def go_to(self, goal: Pose2D, *, timeout: float = 60.0) -> Pose2D:
        self.require_connected(f"go to {_fmt(goal)}")
        return self.robot.go_to(goal, timeout)

    def drive(self, speed: float, turn_rate: float, duration: float) -> Pose2D:
        self.require_connected(f"drive {speed} m/s, {turn_rate} rad/s for {duration} s")
        self.robot.drive_limits.check_drive(self.name, speed, turn_rate, duration)
        return self.robot.drive(speed, turn_rate, duration)

    def stop(self) -> None:
        self.require_connected("stop")
        self.robot.set_wheel_speeds(0.0, 0.0)


def make_sim_robot(
    scene: str = DEFAULT_SCENE,
    start: Pose2D | None = None,
    camera: CameraModel = PAPER_CAMERA,
    pose_source: str = "odometry",
    odometry_errors: OdometryErrors | None = None,
    laser: LaserSpec | None = None,
) -> tuple[SimRobot, Robot]:
    """Load a scene, put the robot at ``start`` (default: the scene's), return both the
    ``SimRobot`` (ground truth, world) and its devices as a ``twin.core.devices.Robot``
    (with a ``SimLaser`` if ``laser`` is given)."""
    sim = SimRobot(World(scene), start, odometry_errors=odometry_errors)
    return sim, sim.devices(camera, pose_source, laser)
