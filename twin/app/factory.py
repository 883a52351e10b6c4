"""Build a robot from its config: one factory per device ``type``, keyed like LeRobot's.

Each device table of the config names a ``type``; ``twin.app.device_types`` declares each
type's options and names its factory here, which receives them typed and checked. The
simulated devices share one MuJoCo world, created on first need; hardware types are imported
only when a config asks for them, so a sim run never loads pyserial or touches a port. A
hardware device with ``port = "twin"`` talks to its serial twin: an emulator on a
pseudo-terminal driving the same MuJoCo world, started here.
"""

from __future__ import annotations

import importlib
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.app.config import TWIN_PORT, ConfigError, DeviceConfig, SurveyConfig
from twin.app.device_types import device_type
from twin.core.devices import Device, LaserMount, Robot
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.lens import Lens

if TYPE_CHECKING:
    from twin.sim.robot import SimRobot

# Devices are built base first: a VC-C4 on the base's AUX port needs the base's driver.
BUILD_ORDER = ("base", "pantilt", "camera", "laser")


@dataclass
class BuildContext:
    """What the device factories of one robot share: the config and, lazily, the sim world and
    the serial twins. ``close`` stops what it started."""

    config: SurveyConfig
    devices: dict[str, Device] = field(default_factory=dict)
    _sim: SimRobot | None = None
    _twins: Any = None
    _links: Any = None  # a temporary folder of stable links to the twins' pseudo-terminals
    _sim_laser: Any = None

    @property
    def start(self) -> Pose2D:
        x, y, yaw = self.config.mission.start
        return Pose2D(x, y, yaw)

    @property
    def sim(self) -> SimRobot:
        """The MuJoCo world's robot, made on first use (imports MuJoCo and opens EGL)."""
        if self._sim is None:
            from twin.sim import SimRobot, World

            self._sim = SimRobot(World(self.config.scene), self.start)
        return self._sim

    @property
    def sim_in_use(self) -> SimRobot | None:
        """The sim robot if any device lives in the MuJoCo world, else ``None`` (the real
        robot): what ground truth and a world's clock come from."""
        return self._sim

    @property
    def twins(self):  # -> twin.serial_twins.session.SerialTwins, started on first need
        if self._twins is None:
            from twin.serial_twins.session import SerialTwins

            head = self.config.devices["pantilt"]
            wiring = head.options.wiring if head.type == "vcc4" else "direct"
            laser = self.config.devices.get("laser")
            source = None
            if laser is not None and laser.option("port") == TWIN_PORT:
                source = self.sim_laser.ranges_at  # the emulated scanner sees the MuJoCo room
            # Stable paths, so a driver can reopen its port after the twin's line is replaced.
            self._links = tempfile.TemporaryDirectory(prefix="twin-ports-")
            self._twins = SerialTwins(
                self.sim,
                self.config.twin_time_scale,
                wiring,
                Path(self._links.name),
                laser_source=source,
            )
        return self._twins

    @property
    def sim_laser(self):  # -> twin.sim.laser.SimLaser, made on first use
        """The MuJoCo laser: the sim device, or what a serial twin of the scanner reads."""
        if self._sim_laser is None:
            from twin.sim.laser import LaserSpec, SimLaser

            laser = self.config.devices.get("laser")
            beams = laser.option("beams", 181) if laser is not None else 181
            self._sim_laser = SimLaser(self.sim, LaserSpec(beams=beams))
        return self._sim_laser

    def close(self) -> None:
        """Stop the serial twins, if any were started (the devices are closed by the Robot)."""
        if self._twins is not None:
            self._twins.stop()
            self._twins = None
            self._links.cleanup()


def sim_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimCamera

    o = device.options
    model, effects = sim_camera_parts(o, context.sim)
    return SimCamera(context.sim, model, effects=effects, seed=o.effects_seed)


def sim_camera_parts(options: Any, sim: SimRobot | None) -> tuple[CameraModel, Any]:
    """The sim camera's ``CameraModel`` (what the mission computes wedges with) and its
    ``twin.sim.camera_effects.CameraEffects`` (None for ``effects = "ideal"``), from its
    ``SimCameraOptions``. Public so that frames rendered elsewhere (a detector's calibration
    views) can go through the same camera. ``sim`` gives an ideal camera's field (the MJCF
    camera's); without it, the Peoplebot model's (the paper's 45 degrees at 4:3)."""
    o = options
    if o.effects == "ideal":
        if sim is None:
            from twin.sim.robot import PAPER_CAMERA

            fovy = PAPER_CAMERA.vfov
            hfov = 2.0 * math.atan(math.tan(fovy / 2.0) * o.width / o.height)
            return CameraModel(o.width, o.height, hfov), None
        return _sim_camera_model(sim, o.width, o.height), None
    from twin.sim.camera_effects import CameraEffects, EffectSettings, lens_for_field

    true_lens = lens_for_field(
        o.width, o.height, math.radians(o.hfov_deg), o.lens_distortion, o.lens_centre_offset
    )
    settings = EffectSettings(
        lens=true_lens,
        motion_blur=o.motion_blur,
        exposure_s=o.exposure_ms / 1000.0,
        auto_exposure=o.auto_exposure,
        exposure_target=o.exposure_target,
        exposure_time_constant_s=o.exposure_time_constant_s,
        white_balance=o.white_balance,
        white_balance_time_constant_s=o.white_balance_time_constant_s,
        white_balance_cast=o.white_balance_cast,
        noise=o.noise,
        read_noise_dn=o.read_noise_dn,
        shot_noise_dn=o.shot_noise_dn,
        analog=o.analog,
        jpeg_quality=o.jpeg_quality,
    )
    lens = true_lens
    if o.lens_model == "calibrated":
        lens = configured_lens("sim camera", o.width, o.height, o.intrinsics, o.distortion)
        if lens is None:
            raise ConfigError(
                'sim camera: lens_model = "calibrated" needs intrinsics and distortion in '
                '[robot.camera]; run `twin calibrate --config ...` or set lens_model = "true"'
            )
    return CameraModel.with_lens(o.width, o.height, lens), CameraEffects(
        settings, o.width, o.height
    )


def configured_lens(
    device: str,
    width: int,
    height: int,
    intrinsics: tuple[float, ...] | None,
    distortion: tuple[float, ...] | None,
) -> Lens | None:
    """The lens a camera table's ``intrinsics``/``distortion`` give (None if neither is set);
    a ``ConfigError`` naming ``device`` and the remedy if they are incomplete or do not fit a
    ``width`` x ``height`` image."""
    if intrinsics is None and distortion is None:
        return None
    remedy = "run `twin calibrate --config ...` to write both, or remove them"
    if intrinsics is None or distortion is None:
        given = "intrinsics" if intrinsics is not None else "distortion"
        raise ConfigError(f"{device}: [robot.camera] has {given} but not both; {remedy}")
    if len(intrinsics) != 4 or len(distortion) != 5:
        raise ConfigError(
            f"{device}: intrinsics must be [fx, fy, cx, cy] and distortion [k1, k2, p1, p2, k3],"
            f" got {len(intrinsics)} and {len(distortion)} numbers; {remedy}"
        )
    fx, fy, cx, cy = intrinsics
    if fx <= 0 or fy <= 0 or not (0 <= cx < width and 0 <= cy < height):
        raise ConfigError(
            f"{device}: intrinsics {list(intrinsics)} do not fit a {width}x{height} image "
            f"(calibrated at another size?); {remedy}"
        )
    lens = Lens.from_lists(intrinsics, distortion)
    try:  # the whole frame must undistort (the polynomial folds back far outside its data)
        CameraModel.with_lens(width, height, lens).pixel_rays(
            np.array([0.0, width, 0.0, width]), np.array([0.0, 0.0, height, height])
        )
    except InputError as exc:
        raise ConfigError(
            f"{device}: the distortion cannot be inverted over the frame; {remedy}"
        ) from exc
    return lens


def _sim_camera_model(sim: SimRobot, width: int, height: int) -> CameraModel:
    """The camera model of the MJCF head camera rendered at ``width`` x ``height``: MuJoCo fixes
    the vertical field of view, so the horizontal one follows from the aspect."""
    fovy = math.radians(float(sim.world.model.cam_fovy[sim.camera_id]))
    hfov = 2.0 * math.atan(math.tan(fovy / 2.0) * width / height)
    return CameraModel(width, height, hfov)


def sim_pantilt(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimPanTilt

    return SimPanTilt(context.sim)


def sim_base(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.drive import OdometryErrors
    from twin.sim.robot import SimBase

    o = device.options
    context.sim.set_odometry_errors(
        OdometryErrors(o.wheel_radius_error, o.track_error, o.slip_noise, o.odometry_seed)
    )
    # a laser-localized base drives on odometry; the localizer around it gives the pose
    source = device.options.pose_source
    return SimBase(context.sim, "odometry" if source == "laser" else source)


def opencv_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.opencv_camera import OpenCVCamera

    o = device.options
    return OpenCVCamera(
        o.device,
        o.width,
        o.height,
        math.radians(o.hfov_deg),
        reconnect_attempts=o.reconnect_attempts,
        lens=configured_lens(
            f"opencv camera {o.device}", o.width, o.height, o.intrinsics, o.distortion
        ),
    )


def arcos_base(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.arcos import ArcosBase

    o = device.options
    port = _port(o.port, lambda: context.twins.arcos_path)
    return ArcosBase.open(port, baudrate=o.baud, start=context.start)


def vcc4_pantilt(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.vcc4 import VCC4

    o = device.options
    if o.wiring == "aux":  # the config checked that the base is an ARCOS base
        return VCC4(context.devices["base"].aux_transport(o.aux_port), answer_timeout=1.0)
    return VCC4.open(_port(o.port, lambda: context.twins.vcc4_path), baudrate=o.baud)


def sim_laser(device: DeviceConfig, context: BuildContext) -> Device:
    return context.sim_laser


def lms2xx_laser(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.lms2xx import LMS2xx

    o = device.options
    x, y, z, yaw_deg = o.mount
    if o.port == TWIN_PORT:  # the emulated scanner sits where the MuJoCo laser does
        mount = context.sim_laser.mount
    else:
        mount = LaserMount(x, y, z, math.radians(yaw_deg))
    port = _port(o.port, lambda: context.twins.lms2xx_path)
    return LMS2xx.open(port, resolution=1.0 if o.beams == 181 else 0.5, mount=mount)


def _port(port: str, twin_path: Callable[[], str | None]) -> str:
    """The serial port to open: the given path, or the serial twin's pty for ``"twin"``."""
    if port != TWIN_PORT:
        return port
    path = twin_path()
    assert path is not None, "the serial twins started without this device's pty"
    return path


def _factory(device: DeviceConfig) -> Callable[[DeviceConfig, BuildContext], Device]:
    module_name, function_name = device_type(device.role, device.type).factory.split(":")
    return getattr(importlib.import_module(module_name), function_name)


def build_robot(
    config: SurveyConfig, context: BuildContext | None = None
) -> tuple[Robot, BuildContext]:
    """The robot of ``config`` (not yet connected) and the context its devices share; on a
    failure, whatever the context started (serial twins) is stopped again."""
    context = context or BuildContext(config)
    try:
        for role in BUILD_ORDER:
            if role not in config.devices:
                continue
            device = config.devices[role]
            context.devices[role] = _factory(device)(device, context)
        devices = context.devices
        base, laser = devices["base"], devices.get("laser")
        if config.localization is not None:
            base = localized_base(config, context, base, laser)
    except BaseException:
        context.close()
        raise
    return Robot(devices["camera"], devices["pantilt"], base, laser), context


def build_camera(config: SurveyConfig) -> tuple[Device, BuildContext]:
    """The config's camera alone (not yet connected) and its context: what a calibration
    needs, without opening the base's or the head's ports."""
    context = BuildContext(config)
    try:
        device = config.devices["camera"]
        camera = _factory(device)(device, context)
    except BaseException:
        context.close()
        raise
    return camera, context


def localized_base(config: SurveyConfig, context: BuildContext, base, laser) -> Device:
    """``base`` localized by ``laser`` on the config's map (a map_server file, or the scene
    cut at the laser's height in the twin), starting around the mission's start pose."""
    from twin.app.localization import LaserLocalizedBase, LocalizerSettings

    o = config.localization
    assert o is not None and laser is not None  # the config checked both
    from twin.nav.maps import load_map
    from twin.sim.scene_map import drive_map, scene_map

    # the room's model: the twin's world, or on the robot the scene file
    sim = context.sim_in_use
    world = sim.world if sim is not None else _scene_model(config)
    if config.map_file is not None:
        occupancy = load_map(config.map_file)
    else:
        occupancy = scene_map(world, laser.mount.z, o.resolution)
    settings = LocalizerSettings(
        particles=o.particles,
        beams=o.beams,
        start_sigma=(o.start_sigma_m, o.start_sigma_m, math.radians(o.start_sigma_deg)),
        seed=o.seed,
    )
    start = None if o.global_start else context.start
    drive = drive_map(world, occupancy)  # plan round what the laser's plane misses (table tops)
    return LaserLocalizedBase(base, laser, occupancy, settings, start, drive)


def _scene_model(config: SurveyConfig):
    from twin.sim import World

    return World(config.scene)
