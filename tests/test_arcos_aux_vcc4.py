"""The camera on the robot's AUX1 port: the real VC-C4 driver over ``ArcosBase.aux_transport``
(TTY2 out, GETAUX/SERAUX back) to the emulated VC-C4 behind the emulated ARCOS firmware, all
through one pseudo-terminal."""

from __future__ import annotations

import math

import pytest

from hardware.arcos import ArcosBase
from hardware.vcc4 import VCC4
from twin.serial_twins.arcos import KinematicActuator, serve_arcos
from twin.serial_twins.vcc4 import KinematicHead, VCC4Emulator, VCC4Timing


def test_vcc4_driver_through_the_arcos_aux_port() -> None:
    camera = VCC4Emulator(KinematicHead(), timing=VCC4Timing(power_seconds=0.5, init_seconds=0.5))
    server = serve_arcos(KinematicActuator(), aux1=camera)
    try:
        with (
            ArcosBase.open(server.path, reply_timeout=0.5) as base,
            VCC4(base.aux_transport(1)) as head,
        ):
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
