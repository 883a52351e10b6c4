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

from twin.app.config import TWIN_PORT, DeviceConfig, SurveyConfig
from twin.app.device_types import device_type
from twin.core.devices import Device, Robot
from twin.core.geometry import CameraModel, Pose2D

if TYPE_CHECKING:
    from twin.sim.robot import SimRobot

# Devices are built base first: a VC-C4 on the base's AUX port needs the base's driver.
BUILD_ORDER = ("base", "pantilt", "camera")


@dataclass
class BuildContext:
    """What the device factories of one robot share: the config and, lazily, the sim world and
    the serial twins. ``close`` stops what it started."""

    config: SurveyConfig
    devices: dict[str, Device] = field(default_factory=dict)
    _sim: SimRobot | None = None
    _twins: Any = None
    _links: Any = None  # a temporary folder of stable links to the twins' pseudo-terminals

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
            # Stable paths, so a driver can reopen its port after the twin's line is replaced.
            self._links = tempfile.TemporaryDirectory(prefix="twin-ports-")
            self._twins = SerialTwins(
                self.sim, self.config.twin_time_scale, wiring, Path(self._links.name)
            )
        return self._twins

    def close(self) -> None:
        """Stop the serial twins, if any were started (the devices are closed by the Robot)."""
        if self._twins is not None:
            self._twins.stop()
            self._twins = None
            self._links.cleanup()


def sim_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimCamera

    options = device.options
    return SimCamera(context.sim, _sim_camera_model(context.sim, options.width, options.height))


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
    from twin.sim.robot import SimBase

    return SimBase(context.sim, device.options.pose_source)


def opencv_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.opencv_camera import OpenCVCamera

    o = device.options
    return OpenCVCamera(
        o.device,
        o.width,
        o.height,
        math.radians(o.hfov_deg),
        reconnect_attempts=o.reconnect_attempts,
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
            device = config.devices[role]
            context.devices[role] = _factory(device)(device, context)
    except BaseException:
        context.close()
        raise
    devices = context.devices
    return Robot(devices["camera"], devices["pantilt"], devices["base"]), context
