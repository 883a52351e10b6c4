"""What a camera, a pan-tilt unit and a mobile base promise, whoever implements them.

One abstract class per role (LeRobot style): the MuJoCo twin (``twin.sim``) and the serial
hardware drivers (``hardware/``) implement them, and the survey mission talks to a robot only
through them. Every device is a context manager: ``connect()`` on entry, ``close()`` on exit;
calls on a device that is not connected raise ``NotConnectedError``.

Units at this interface: metres, radians, seconds, radians per second; map frame as in
``twin.core.geometry`` (pan positive to the left, tilt positive up). Degrees and wire units
belong to the drivers. Blocking calls return when the motion has finished (or raise), so the
image grabbed next is taken from where the robot says it is.

Errors are ``DeviceError`` (a ``TwinError``): one line naming the device, what was asked, what
was seen, and what to do.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from types import TracebackType

import numpy as np

from twin.core.clock import SYSTEM_CLOCK
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel, Pose2D, require_finite

# -- errors -------------------------------------------------------------------------------------


class DeviceError(TwinError):
    """A device failed: ``device`` did not do ``asked`` because of ``seen``; ``remedy`` helps."""

    def __init__(self, device: str, asked: str, seen: str, remedy: str) -> None:
        self.device, self.asked, self.seen, self.remedy = device, asked, seen, remedy
        super().__init__(f"{device}: {asked}: {seen}; {remedy}")

    def __reduce__(self):  # pickled whole: a worker process's device error reaches the caller
        return (type(self), (self.device, self.asked, self.seen, self.remedy))


class NotConnectedError(DeviceError):
    """The device was used before ``connect()`` or after ``close()``."""


class DeviceTimeoutError(DeviceError):
    """The device did not answer, or did not finish a motion, within the allowed time."""


class OutOfRangeError(DeviceError):
    """A command's argument lies outside what the device can do (angle, speed, pose)."""


class DeviceBusyError(DeviceError):
    """The device refused a command because an earlier one is still running."""


class ProtocolError(DeviceError):
    """The device's answer was malformed: bad checksum, truncated, unexpected bytes."""


class DeviceFaultError(DeviceError):
    """The device reported a fault: motor stall, bumper hit, camera system error."""


class BumpedError(DeviceFaultError):
    """The base touched something: ``bearing`` is where, in radians in the robot's frame (0
    ahead, counter-clockwise positive), as its bumpers tell it. A base that re-plans needs it:
    what the bumper felt is an obstacle its map and laser may not hold (a toy on the floor is
    below the laser's plane), and backing off must move away from it."""

    def __init__(self, device: str, asked: str, seen: str, remedy: str, bearing: float) -> None:
        super().__init__(device, asked, seen, remedy)
        self.bearing = float(bearing)

    def __reduce__(self):
        return (type(self), (self.device, self.asked, self.seen, self.remedy, self.bearing))


class ConnectionLostError(DeviceError):
    """The link to the device vanished (port closed, camera unplugged)."""


# -- data ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    """One camera image: H x W x 3 uint8 RGB, row 0 at the top; ``timestamp`` in seconds on
    the robot's clock (simulated time in the twin, the driver's ``twin.core.clock`` on hardware)."""

    image: np.ndarray
    timestamp: float
    # H x W metres along each pixel's ray to the first surface (NaN: nothing within range), when
    # the camera knows it (the twin renders it with the image); None for a real camera
    depth: np.ndarray | None = None


@dataclass(frozen=True)
class View:
    """An image with where it was taken from: the base pose (map frame) and the head's pan and
    tilt (radians) at capture. This is what a bearing wedge is projected from."""

    image: np.ndarray
    pose: Pose2D
    pan: float
    tilt: float
    timestamp: float
    # 3 x 3 covariance of (x, y, yaw) in m^2 and rad^2 when the base knows it (a localizer),
    # None when it does not (bare odometry, whose error only grows)
    pose_covariance: np.ndarray | None = None
    depth: np.ndarray | None = None  # the frame's depth, when the camera gives one (Frame.depth)


@dataclass(frozen=True)
class PanTiltLimits:
    """Angle limits (rad) and top speeds (rad/s) of a pan-tilt unit."""

    pan_min: float
    pan_max: float
    tilt_min: float
    tilt_max: float
    pan_speed: float
    tilt_speed: float

    def check(self, device: str, pan: float, tilt: float, speed: float | None = None) -> None:
        """Raise ``OutOfRangeError`` unless the angles and the optional pan speed are reachable."""
        asked = f"move to pan {math.degrees(pan):.1f} deg, tilt {math.degrees(tilt):.1f} deg"
        if not (math.isfinite(pan) and math.isfinite(tilt)):
            raise OutOfRangeError(device, asked, "the angles are not finite", "pass numbers")
        if not self.pan_min <= pan <= self.pan_max:
            raise OutOfRangeError(
                device,
                asked,
                f"pan outside [{math.degrees(self.pan_min):.1f}, "
                f"{math.degrees(self.pan_max):.1f}] deg",
                "turn the base for wider headings",
            )
        if not self.tilt_min <= tilt <= self.tilt_max:
            raise OutOfRangeError(
                device,
                asked,
                f"tilt outside [{math.degrees(self.tilt_min):.1f}, "
                f"{math.degrees(self.tilt_max):.1f}] deg",
                "choose a reachable tilt",
            )
        if speed is not None and not 0.0 < speed <= self.pan_speed:
            raise OutOfRangeError(
                device,
                f"{asked} at {speed!r} rad/s",
                f"speed outside (0, {self.pan_speed:.3f}] rad/s",
                "use a positive speed within the unit's maximum",
            )


@dataclass(frozen=True)
class BaseLimits:
    """Speed and acceleration limits of a mobile base (SI units): what a base's controller or
    firmware is set to, and the bounds ``Base.drive`` accepts. The defaults are the Pioneer
    class's, gentle indoors."""

    speed: float = 0.5  # m/s
    accel: float = 0.6  # m/s^2
    turn_rate: float = math.radians(100.0)  # rad/s
    turn_accel: float = math.radians(250.0)  # rad/s^2
    max_duration: float = 600.0  # s: the longest timed drive

    def check_drive(self, device: str, speed: float, turn_rate: float, duration: float) -> None:
        """Raise ``OutOfRangeError`` unless a timed drive is within the limits."""
        asked = f"drive {speed:.3f} m/s, {turn_rate:.3f} rad/s for {duration:g} s"
        if not (
            abs(speed) <= self.speed
            and abs(turn_rate) <= self.turn_rate
            and 0.0 <= duration <= self.max_duration
        ):
            raise OutOfRangeError(
                device,
                asked,
                f"limits are |speed| <= {self.speed} m/s, |turn rate| <= "
                f"{self.turn_rate:.2f} rad/s, 0..{self.max_duration:g} s",
                "use smaller values",
            )


# A Pioneer-class base driven gently indoors: the sim's controller and the ARCOS firmware's
# settings (SETV, SETA, SETRV, SETRA) by default.
PIONEER_LIMITS = BaseLimits()

# The Canon VC-C4's mechanical limits and top speeds (specs/protocols.md, section A6).
VCC4_LIMITS = PanTiltLimits(
    pan_min=math.radians(-100.0),
    pan_max=math.radians(100.0),
    tilt_min=math.radians(-30.0),
    tilt_max=math.radians(90.0),
    pan_speed=math.radians(90.0),
    tilt_speed=math.radians(70.0),
)


# -- devices ------------------------------------------------------------------------------------


class Device(ABC):
    """Connect/close lifecycle shared by every device. ``name`` appears in every error."""

    name: str = "device"

    @abstractmethod
    def connect(self) -> None:
        """Open the link and bring the device to a known state; idempotent."""

    @abstractmethod
    def close(self) -> None:
        """Stop any motion and release the link; safe to call twice."""

    @property
    @abstractmethod
    def is_connected(self) -> bool: ...

    def require_connected(self, asked: str) -> None:
        if not self.is_connected:
            raise NotConnectedError(
                self.name,
                asked,
                "the device is not connected",
                "use it inside 'with device:' or call connect() first",
            )

    def __enter__(self) -> Device:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class Camera(Device):
    """A camera delivering RGB frames of a known geometry."""

    @property
    @abstractmethod
    def model(self) -> CameraModel:
        """Image size and horizontal field of view: the pixel column <-> bearing mapping."""

    @abstractmethod
    def grab(self) -> Frame:
        """The newest frame taken after this call began (never a stale buffered one)."""

    def now(self) -> float:
        """The robot's clock, in seconds: the one frame timestamps are read on (simulated time
        in the twin, the driver's clock on hardware). A mission times its views on it, so a
        resumed run's clock continues. This default is the system's monotonic clock."""
        return SYSTEM_CLOCK.now()


class PanTilt(Device):
    """A pan-tilt head. Angles in radians, pan positive left, tilt positive up."""

    @property
    @abstractmethod
    def limits(self) -> PanTiltLimits: ...

    @abstractmethod
    def move_to(
        self, pan: float, tilt: float = 0.0, *, speed: float | None = None, timeout: float = 10.0
    ) -> tuple[float, float]:
        """Move and wait until there; ``speed`` (rad/s) caps pan and tilt speed (default: the
        unit's top speeds). Returns the reached (pan, tilt). ``OutOfRangeError`` if
        unreachable, ``DeviceTimeoutError`` if not there within ``timeout`` seconds."""

    @abstractmethod
    def position(self) -> tuple[float, float]:
        """Current (pan, tilt) in radians."""

    @abstractmethod
    def stop(self) -> None:
        """Stop moving where the head is."""


class Base(Device):
    """A mobile base that knows its pose in the map frame (from odometry, or better)."""

    @abstractmethod
    def pose(self) -> Pose2D:
        """The base's own estimate of its pose (map frame): what a view is projected from."""

    def pose_covariance(self) -> np.ndarray | None:
        """The 3 x 3 covariance of ``pose()``'s (x, y, yaw), m^2 and rad^2, when the base knows
        how sure it is (a laser localizer does); ``None`` for bare odometry."""
        return None

    @abstractmethod
    def set_pose(self, pose: Pose2D) -> None:
        """Declare the current pose in the map frame (re-anchors the odometry; moves nothing)."""

    @abstractmethod
    def go_to(self, goal: Pose2D, *, timeout: float = 60.0) -> Pose2D:
        """Drive to ``goal`` (turn, drive straight, turn) and stop within 5 cm and 3 degrees of
        it; returns the final pose estimate. ``DeviceTimeoutError`` if not there in time,
        ``DeviceFaultError`` on a stall or bumper hit."""

    @abstractmethod
    def drive(self, speed: float, turn_rate: float, duration: float) -> Pose2D:
        """Drive at ``speed`` (m/s) and ``turn_rate`` (rad/s, CCW positive) for ``duration``
        seconds, then stop; returns the pose estimate."""

    @abstractmethod
    def stop(self) -> None:
        """Stop the wheels."""


@dataclass(frozen=True)
class LaserMount:
    """Where a planar laser sits on the base: position (m) in the base frame (x forward, y left,
    z up from the floor) and the yaw (rad) of its zero beam relative to the base's heading."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.30
    yaw: float = 0.0


@dataclass(frozen=True)
class Scan:
    """One planar laser scan, in the scanner's own frame.

    ``angles`` (n,) are the beam bearings in radians, counter-clockwise from the scanner's zero
    direction, increasing (an LMS200's 180 degrees: -pi/2 on the right .. +pi/2 on the left);
    ``ranges`` (n,) are metres, NaN where the beam saw nothing within ``max_range`` or the reading
    is invalid (a dazzled or dropped-out beam); ``timestamp`` is on the robot's clock (the one
    ``Camera.now`` reads), taken when the scan was complete."""

    angles: np.ndarray
    ranges: np.ndarray
    timestamp: float
    max_range: float

    def points(self) -> np.ndarray:
        """(k, 2) returns of the beams that hit something, in metres in the scanner's frame."""
        hit = np.isfinite(self.ranges)
        r, a = self.ranges[hit], self.angles[hit]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


class Laser(Device):
    """A planar laser range finder on the base (the Peoplebot's SICK LMS200 at 0.30 m)."""

    @property
    @abstractmethod
    def mount(self) -> LaserMount:
        """Where the scanner sits on the base."""

    @abstractmethod
    def scan(self, timeout: float = 2.0) -> Scan:
        """The newest complete scan that began after this call (never a stale buffered one);
        ``DeviceTimeoutError`` if none arrives within ``timeout`` seconds."""


@dataclass
class Robot:
    """The devices of a survey robot: camera, pan-tilt head, base, and optionally a laser.
    Connecting it connects them all (closing those already open if one fails), and
    ``capture`` takes one ``View``."""

    camera: Camera
    pantilt: PanTilt
    base: Base
    laser: Laser | None = None

    @property
    def devices(self) -> tuple[Device, ...]:
        """In connection order: the base first (a head or laser may ride on its AUX ports)."""
        extra = (self.laser,) if self.laser is not None else ()
        return (self.base, self.pantilt, self.camera, *extra)

    def connect(self) -> None:
        opened: list[Device] = []
        try:
            for device in self.devices:
                device.connect()
                opened.append(device)
        except BaseException:
            for device in reversed(opened):
                device.close()
            raise

    def close(self) -> None:
        errors: list[BaseException] = []
        for device in reversed(self.devices):
            try:
                device.close()
            except Exception as exc:  # close every device even if one fails
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> Robot:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def capture(self) -> View:
        """Grab a frame and pair it with the base pose and head angles at that moment."""
        frame = self.camera.grab()
        pan, tilt = self.pantilt.position()
        pose = self.base.pose()
        require_finite("view pose", pose.x, pose.y, pose.yaw, pan, tilt)
        covariance = self.base.pose_covariance()
        return View(frame.image, pose, pan, tilt, frame.timestamp, covariance, frame.depth)
