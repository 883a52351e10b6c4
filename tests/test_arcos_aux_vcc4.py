"""The camera on the robot's AUX1 port: the real VC-C4 driver over ``ArcosBase.aux_transport``
(TTY2 out, GETAUX/SERAUX back) to the emulated VC-C4 behind the emulated ARCOS firmware, all
through one line, in virtual time (``ManualClock``: the camera's real power-on and
initialisation spells and its 9600-baud answers cost no wall time)."""

from __future__ import annotations

import math

import pytest

from hardware.arcos import ArcosBase
from hardware.vcc4 import VCC4
from twin.core.clock import ManualClock
from twin.serial_twins.arcos import KinematicActuator, serve_arcos
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.vcc4 import KinematicHead, VCC4Emulator


def test_vcc4_driver_through_the_arcos_aux_port() -> None:
    clock = ManualClock()
    camera = VCC4Emulator(KinematicHead(clock), camera_on=False)  # the real camera's timing
    link = MemoryLink(clock, "arcos line")
    server = serve_arcos(KinematicActuator(clock=clock), link, aux1=camera, clock=clock)
    try:
        with (
            ArcosBase(lambda: link.transport("ARCOS base"), reply_timeout=0.5, clock=clock) as base,
            VCC4(base.aux_transport(1), clock=clock) as head,
        ):
            assert camera.camera_on and camera.pedestal_ready and camera.host_mode
            pan, tilt = head.move_to(math.radians(30.0), math.radians(-10.0))
            assert (pan, tilt) == pytest.approx(
                (math.radians(30), math.radians(-10)), abs=math.radians(0.2)
            )
            assert head.position() == pytest.approx((pan, tilt))
            assert base.protocol_errors == 0
            commands = [number for number, _ in server.emulator.commands]
            assert 42 in commands and 43 in commands  # TTY2 and GETAUX carried the camera
    finally:
        server.stop()
