"""Every device type a config can name: its role, its typed options, and the factory that builds it.

A config's ``[robot.<role>]`` table names a ``type``; the rest of the table is that type's
options, declared here as a frozen dataclass (``twin.core.options``): name, type, unit, default
and range, checked when the config is read, so a factory only ever sees typed values. The
declarations are kept apart from the drivers so that reading a config never imports MuJoCo or
pyserial; the factories (``twin.app.factory``) import a device's module only to build it.
``twin devices`` prints this table for people.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from twin.core.options import option

ROLES = ("camera", "pantilt", "base")
OPTIONAL_ROLES = ("laser",)  # a robot may have one; localizing by laser needs it


# -- the twin ----------------------------------------------------------------------------------


LENS_DOCS = {
    "intrinsics": "[fx, fy, cx, cy] in pixels (OpenCV's convention: pixel centres at whole "
    "numbers), as `twin calibrate` writes them",
    "distortion": "[k1, k2, p1, p2, k3], OpenCV's radial-tangential coefficients, as `twin "
    "calibrate` writes them",
}


@dataclass(frozen=True)
class SimCameraOptions:
    """The head camera rendered by MuJoCo, as imperfect as the VC-C4 by default (``effects =
    "realistic"``: its wide-end lens with barrel distortion, auto exposure and white balance,
    sensor and analog noise, motion blur, JPEG; see twin.sim.camera_effects for where each
    default comes from). ``effects = "ideal"`` is the plain pinhole render: its vertical field
    of view is the MJCF camera's, so the horizontal one follows from the aspect (320 x 240 gives
    the paper's 45 degrees), and every other option below is ignored."""

    width: int = option(320, unit="px", low=16, high=1920, doc="image width")
    height: int = option(240, unit="px", low=16, high=1080, doc="image height")
    effects: Literal["realistic", "ideal"] = option(
        "realistic", doc='"ideal" turns every effect off (the plain renderer, bit for bit)'
    )
    hfov_deg: float = option(
        47.5,
        unit="deg",
        low=10.0,
        high=120.0,
        doc="the true lens's horizontal field across the frame (VC-C4 wide end: 47.5)",
    )
    lens_distortion: tuple[float, float, float, float, float] = option(
        (-0.20, 0.03, 5e-4, -3e-4, 0.0),
        low=-1.0,
        high=1.0,
        doc="the true lens's [k1, k2, p1, p2, k3] (typical of a 1/4-inch zoom's wide end)",
    )
    lens_centre_offset: tuple[float, float] = option(
        (2.1, -1.4),
        unit="px",
        low=-20.0,
        high=20.0,
        doc="the true principal point minus the image centre, [x, y], pixels at 320 wide",
    )
    lens_model: Literal["true", "calibrated"] = option(
        "true",
        doc='the lens the mission computes wedges with: the true one, or "calibrated" (the '
        "intrinsics and distortion below, from `twin calibrate`)",
    )
    intrinsics: tuple[float, ...] | None = option(None, doc=LENS_DOCS["intrinsics"])
    distortion: tuple[float, ...] | None = option(None, doc=LENS_DOCS["distortion"])
    motion_blur: bool = option(True, doc="blur frames by the head's and base's turning")
    exposure_ms: float = option(
        16.67, unit="ms", low=0.1, high=200.0, doc="exposure time (1/60 s: an NTSC field)"
    )
    auto_exposure: bool = option(True, doc="a lagging gain toward a target mean, clipping")
    exposure_target: float = option(
        0.45, low=0.05, high=0.95, doc="mean brightness the auto exposure aims at (of full scale)"
    )
    exposure_time_constant_s: float = option(
        0.3, unit="s", low=0.0, high=10.0, doc="how fast the auto exposure follows the scene"
    )
    white_balance: bool = option(True, doc="grey-world gains that converge with a lag")
    white_balance_time_constant_s: float = option(
        1.0, unit="s", low=0.0, high=30.0, doc="how fast the white balance follows the scene"
    )
    white_balance_cast: tuple[float, float] = option(
        (1.03, 0.97), low=0.5, high=2.0, doc="[red, blue] gains the balance leaves over"
    )
    noise: bool = option(True, doc="shot and read noise, amplified by the exposure gain")
    read_noise_dn: float = option(
        1.0, unit="DN", low=0.0, high=50.0, doc="read noise, 1 sigma, at gain 1"
    )
    shot_noise_dn: float = option(
        0.02, unit="DN", low=0.0, high=5.0, doc="shot noise variance per DN of signal"
    )
    analog: bool = option(True, doc="composite video's narrow chroma (colour blurred 3 px)")
    jpeg_quality: int = option(80, low=0, high=100, doc="JPEG quality; 0: no JPEG")
    effects_seed: int = option(0, low=0, doc="seed of the camera's noise")


@dataclass(frozen=True)
class SimPanTiltOptions:
    """The head's servos, with the VC-C4's limits and speeds (models/peoplebot.xml)."""


@dataclass(frozen=True)
class SimBaseOptions:
    """The differential-drive base, driven by its wheels through the physics."""

    pose_source: Literal["odometry", "laser", "truth"] = option(
        "odometry",
        doc="what a view's pose comes from: wheel odometry, the laser localized on the map "
        "(needs [robot.laser] and [localization]), or the ground truth (the twin only)",
    )
    wheel_radius_error: tuple[float, float] = option(
        (0.0, 0.0),
        low=-0.1,
        high=0.1,
        doc="[left, right]: how much larger each real wheel is than the odometry assumes "
        "(0.003 = 0.3 %), the first of UMBmark's two dominant systematic errors",
    )
    track_error: float = option(
        0.0, low=-0.2, high=0.2, doc="how much wider the real wheel track is than assumed"
    )
    slip_noise: float = option(
        0.0,
        unit="m",
        low=0.0,
        high=0.5,
        doc="random wheel slip: each wheel's error after 1 m (1 sigma), growing as sqrt(distance)",
    )
    odometry_seed: int = option(0, low=0, doc="seed of the slip noise")


@dataclass(frozen=True)
class SimLaserOptions:
    """The SICK LMS200 simulated by MuJoCo ray casting at 0.30 m on the base."""

    beams: Literal[181, 361] = option(181, doc="beams over 180 degrees: 1 or 0.5 degree apart")


# -- the real robot ----------------------------------------------------------------------------

SERIAL_PORT_DOC = 'serial port, e.g. /dev/ttyUSB0, or "twin" for the emulator on a pty'


@dataclass(frozen=True)
class OpenCVCameraOptions:
    """A camera or capture card read through OpenCV (the VC-C4's video on the Peoplebot)."""

    device: int | str = option(0, doc="camera index, device path, video file or stream URL")
    width: int = option(320, unit="px", low=16, high=4096, doc="frame width delivered")
    height: int = option(240, unit="px", low=16, high=4096, doc="frame height delivered")
    hfov_deg: float = option(
        45.0,
        unit="deg",
        low=1.0,
        high=179.0,
        doc="horizontal field of view (ignored once intrinsics are given)",
    )
    intrinsics: tuple[float, ...] | None = option(None, doc=LENS_DOCS["intrinsics"])
    distortion: tuple[float, ...] | None = option(None, doc=LENS_DOCS["distortion"])
    reconnect_attempts: int = option(3, low=0, high=100, doc="reopen tries after a lost camera")


@dataclass(frozen=True)
class VCC4Options:
    """Canon VC-C4 pan-tilt head over RS-232, on its own port or tunnelled through ARCOS AUX."""

    port: str | None = option(None, doc=SERIAL_PORT_DOC + ' (wiring = "direct")')
    baud: Literal[9600] = option(9600, doc="the VC-C4 speaks 9600 8N1 only")
    wiring: Literal["direct", "aux"] = option(
        "direct", doc='"direct": its own serial port; "aux": through the base\'s AUX port'
    )
    aux_port: int = option(1, low=1, high=3, doc='the ARCOS AUX port (wiring = "aux")')


@dataclass(frozen=True)
class ArcosOptions:
    """The Peoplebot's base over ARCOS on the onboard computer's serial port."""

    port: str = option(doc=SERIAL_PORT_DOC)
    baud: Literal[9600, 19200, 38400, 57600, 115200] = option(9600, doc="the HOST port's rate")
    pose_source: Literal["odometry", "laser"] = option(
        "odometry",
        doc="what a view's pose comes from: the base's odometry, or the laser localized on the "
        "map (needs [robot.laser] and [localization])",
    )


@dataclass(frozen=True)
class LMS2xxOptions:
    """A SICK LMS200/291 laser scanner over RS-232 (the Peoplebot's, at 0.30 m)."""

    port: str = option(doc=SERIAL_PORT_DOC)
    beams: Literal[181, 361] = option(181, doc="beams over 180 degrees: 1 or 0.5 degree apart")
    mount: tuple[float, float, float, float] = option(
        (0.15, 0.0, 0.30, 0.0),
        doc="[x, y, z, yaw_deg] of the scanner on the base: metres forward, left, up, and its "
        "zero beam's angle (the Peoplebot's LMS200 sits 0.15 m ahead of the centre, 0.30 m up)",
    )


@dataclass(frozen=True)
class DeviceType:
    """One ``type`` of one role: its options and its factory (``module:function``)."""

    role: str
    name: str
    options: type
    factory: str
    summary: str


DEVICE_TYPES: dict[tuple[str, str], DeviceType] = {
    (t.role, t.name): t
    for t in (
        DeviceType("camera", "sim", SimCameraOptions, "twin.app.factory:sim_camera",
                   "the head camera rendered in the MuJoCo twin"),
        DeviceType("pantilt", "sim", SimPanTiltOptions, "twin.app.factory:sim_pantilt",
                   "the head's servos in the MuJoCo twin"),
        DeviceType("base", "sim", SimBaseOptions, "twin.app.factory:sim_base",
                   "the differential-drive base in the MuJoCo twin"),
        DeviceType("camera", "opencv", OpenCVCameraOptions, "twin.app.factory:opencv_camera",
                   "a camera or capture card through OpenCV"),
        DeviceType("pantilt", "vcc4", VCC4Options, "twin.app.factory:vcc4_pantilt",
                   "Canon VC-C4 over RS-232"),
        DeviceType("base", "arcos", ArcosOptions, "twin.app.factory:arcos_base",
                   "Peoplebot base over ARCOS"),
        DeviceType("laser", "sim", SimLaserOptions, "twin.app.factory:sim_laser",
                   "the SICK LMS200 simulated in the MuJoCo twin"),
        DeviceType("laser", "lms2xx", LMS2xxOptions, "twin.app.factory:lms2xx_laser",
                   "SICK LMS200/291 over RS-232"),
    )
}  # fmt: skip


def device_type(role: str, name: str) -> DeviceType:
    """The declared type, or a ``KeyError`` (the config turns it into a one-line error)."""
    return DEVICE_TYPES[(role, name)]


def types_of(role: str) -> list[str]:
    return sorted(name for r, name in DEVICE_TYPES if r == role)
