"""Build a robot from its config: one factory per device ``type``, keyed like LeRobot's.

Each device table of the config names a ``type``; the factory for (role, type) receives the
table's other keys as options. The simulated devices share one MuJoCo world, created on first
need; hardware types are imported only when a config asks for them, so a sim run never loads
pyserial or touches a port. A hardware device with ``port = "twin"`` talks to its serial twin:
an emulator on a pseudo-terminal driving the same MuJoCo world, started here.
"""

from __future__ import annotations

import importlib
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.app.config import DeviceConfig, SurveyConfig
from twin.core.devices import Device, Robot
from twin.core.errors import InputError
from twin.core.geometry import CameraModel, Pose2D

# (role, type) -> "module:function"; the function takes (DeviceConfig, BuildContext).
DEVICE_FACTORIES: dict[tuple[str, str], str] = {
    ("camera", "sim"): "twin.app.factory:sim_camera",
    ("pantilt", "sim"): "twin.app.factory:sim_pantilt",
    ("base", "sim"): "twin.app.factory:sim_base",
    ("camera", "opencv"): "twin.app.factory:opencv_camera",
    ("pantilt", "vcc4"): "twin.app.factory:vcc4_pantilt",
    ("base", "arcos"): "twin.app.factory:arcos_base",
}
TWIN_PORT = "twin"
# Devices are built base first: a VC-C4 on the base's AUX port needs the base's driver.
BUILD_ORDER = ("base", "pantilt", "camera")


@dataclass
class BuildContext:
    """What the device factories of one robot share: the config and, lazily, the sim world."""

    config: SurveyConfig
    camera: CameraModel = field(default_factory=CameraModel)
    devices: dict[str, Device] = field(default_factory=dict)
    _sim: Any = None
    _twins: Any = None
    _links: Any = None  # a temporary folder of stable links to the twins' pseudo-terminals

    @property
    def start(self) -> Pose2D:
        x, y, yaw = self.config.mission.start
        return Pose2D(x, y, yaw)

    @property
    def sim(self):  # -> twin.sim.SimRobot; imported lazily (MuJoCo, EGL)
        if self._sim is None:
            from twin.sim import SimRobot, World

            self._sim = SimRobot(World(self.config.scene), self.start)
        return self._sim

    @property
    def twins(self):  # -> twin.serial_twins.session.SerialTwins, started on first need
        if self._twins is None:
            from twin.serial_twins.session import SerialTwins

            head = self.config.devices["pantilt"]
            wiring = head.options.get("wiring", "direct") if head.type == "vcc4" else "direct"
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


def _take(device: DeviceConfig, allowed: dict[str, Any]) -> dict[str, Any]:
    """The device's options with defaults filled in; an unknown option is a ``InputError``."""
    unknown = sorted(set(device.options) - set(allowed))
    if unknown:
        raise InputError(
            f"robot.{device.role}.{unknown[0]}: unknown option for type {device.type!r}; "
            f"known: {', '.join(sorted(allowed)) or 'none'}"
        )
    return {**allowed, **device.options}


def sim_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimCamera

    _take(device, {})
    return SimCamera(context.sim, context.camera)


def sim_pantilt(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimPanTilt

    _take(device, {})
    return SimPanTilt(context.sim)


def sim_base(device: DeviceConfig, context: BuildContext) -> Device:
    from twin.sim.robot import SimBase

    options = _take(device, {"pose_source": "odometry"})
    return SimBase(context.sim, options["pose_source"])


def opencv_camera(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.opencv_camera import OpenCVCamera

    o = _take(
        device,
        {"device": 0, "width": 320, "height": 240, "hfov_deg": 45.0, "reconnect_attempts": 3},
    )
    camera = OpenCVCamera(
        o["device"],
        int(o["width"]),
        int(o["height"]),
        math.radians(o["hfov_deg"]),
        reconnect_attempts=o["reconnect_attempts"],
    )
    return camera


def arcos_base(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.arcos import ArcosBase

    o = _take(device, {"port": None, "baud": 9600})
    port = _port(device, o["port"], lambda: context.twins.arcos_path)
    return ArcosBase.open(port, baudrate=int(o["baud"]), start=context.start)


def vcc4_pantilt(device: DeviceConfig, context: BuildContext) -> Device:
    from hardware.vcc4 import VCC4

    o = _take(device, {"port": None, "baud": 9600, "wiring": "direct", "aux_port": 1})
    if o["wiring"] == "aux":
        base = context.devices.get("base")
        if context.config.devices["base"].type != "arcos" or base is None:
            raise InputError(
                "robot.pantilt.wiring: 'aux' tunnels through the robot's AUX port, "
                "so robot.base must be of type 'arcos'"
            )
        return VCC4(base.aux_transport(int(o["aux_port"])), answer_timeout=1.0)
    if o["wiring"] != "direct":
        raise InputError(f"robot.pantilt.wiring: expected direct or aux, got {o['wiring']!r}")
    port = _port(device, o["port"], lambda: context.twins.vcc4_path)
    return VCC4.open(port, baudrate=int(o["baud"]))


def _port(device: DeviceConfig, port: Any, twin_path: Callable[[], str | None]) -> str:
    """The serial port to open: the given path, or the serial twin's pty for ``"twin"``."""
    if port == TWIN_PORT:
        path = twin_path()
        assert path is not None
        return path
    if not isinstance(port, str) or not port:
        raise InputError(
            f"robot.{device.role}.port: give the serial port (e.g. /dev/ttyUSB0), "
            f'or "{TWIN_PORT}" for its serial twin'
        )
    return port


def _factory(device: DeviceConfig) -> Callable[[DeviceConfig, BuildContext], Device]:
    key = (device.role, device.type)
    if key not in DEVICE_FACTORIES:
        known = sorted(t for role, t in DEVICE_FACTORIES if role == device.role)
        raise InputError(
            f"robot.{device.role}.type: unknown type {device.type!r}; use one of {', '.join(known)}"
        )
    module_name, function_name = DEVICE_FACTORIES[key].split(":")
    return getattr(importlib.import_module(module_name), function_name)


def uses_sim_world(config: SurveyConfig) -> bool:
    """Whether the config's robot lives in the MuJoCo world (sim devices or serial twins)."""
    return any(
        d.type == "sim" or d.options.get("port") == TWIN_PORT for d in config.devices.values()
    )


def build_robot(
    config: SurveyConfig, context: BuildContext | None = None
) -> tuple[Robot, BuildContext]:
    """The robot of ``config`` (not yet connected) and the context its devices share."""
    context = context or BuildContext(config)
    for role in BUILD_ORDER:
        device = config.devices[role]
        context.devices[role] = _factory(device)(device, context)
    devices = context.devices
    return Robot(devices["camera"], devices["pantilt"], devices["base"]), context
