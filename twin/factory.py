"""Build a robot from its config: one factory per device ``type``, keyed like LeRobot's.

Each device table of the config names a ``type``; the factory for (role, type) receives the
table's other keys as options. The simulated devices share one MuJoCo world, created on first
need; hardware types are imported only when a config asks for them, so a sim run never loads
pyserial or touches a port.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from twin.config import DeviceConfig, SurveyConfig
from twin.devices import Device, Robot
from twin.errors import InputError
from twin.geometry import CameraModel, Pose2D

# (role, type) -> "module:function"; the function takes (DeviceConfig, BuildContext).
DEVICE_FACTORIES: dict[tuple[str, str], str] = {
    ("camera", "sim"): "twin.factory:sim_camera",
    ("pantilt", "sim"): "twin.factory:sim_pantilt",
    ("base", "sim"): "twin.factory:sim_base",
}


@dataclass
class BuildContext:
    """What the device factories of one robot share: the config and, lazily, the sim world."""

    config: SurveyConfig
    camera: CameraModel = field(default_factory=CameraModel)
    _sim: Any = None

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


def _factory(device: DeviceConfig) -> Callable[[DeviceConfig, BuildContext], Device]:
    key = (device.role, device.type)
    if key not in DEVICE_FACTORIES:
        known = sorted(t for role, t in DEVICE_FACTORIES if role == device.role)
        raise InputError(
            f"robot.{device.role}.type: unknown type {device.type!r}; use one of {', '.join(known)}"
        )
    module_name, function_name = DEVICE_FACTORIES[key].split(":")
    return getattr(importlib.import_module(module_name), function_name)


def build_robot(
    config: SurveyConfig, context: BuildContext | None = None
) -> tuple[Robot, BuildContext]:
    """The robot of ``config`` (not yet connected) and the context its devices share."""
    context = context or BuildContext(config)
    devices = {role: _factory(d)(d, context) for role, d in config.devices.items()}
    return Robot(devices["camera"], devices["pantilt"], devices["base"]), context
