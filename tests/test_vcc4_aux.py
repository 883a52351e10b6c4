"""The VC-C4 on the robot's AUX1 port: the driver's bytes tunnelled through the real ARCOS
driver and the emulated ARCOS firmware (TTY2 out, GETAUX/SERAUX in, section A10) to the
emulated camera moving the MuJoCo head, end to end over a real pseudo-terminal in real time
(the world at 4x the wall clock), as ``twin hw vcc4 --via-aux`` meets it. The same tunnel in
virtual time, with the camera's real timings, is tests/test_arcos_aux_vcc4.py."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from hardware.arcos import ArcosBase
from hardware.vcc4 import VCC4
from twin.cli import main
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.bytedevice import LineServer
from twin.serial_twins.pty import PtyLink
from twin.serial_twins.runner import WorldRunner
from twin.serial_twins.vcc4 import SimHeadActuator, VCC4Emulator, VCC4Timing
from twin.sim import SimRobot, make_sim_robot

TOLERANCE = math.radians(0.3)


@pytest.fixture(scope="module")
def sim() -> Iterator[SimRobot]:
    robot, _ = make_sim_robot()
    with WorldRunner(robot, time_scale=4.0):
        yield robot


@pytest.fixture
def server(sim: SimRobot, tmp_path: Path) -> Iterator[LineServer]:
    camera = VCC4Emulator(
        SimHeadActuator(sim), timing=VCC4Timing(power_seconds=0.2, init_seconds=0.2)
    )
    with serve_arcos(sim, PtyLink(tmp_path / "arcos"), aux1=camera) as srv:
        yield srv


def test_driver_moves_the_sim_head_through_the_aux_tunnel(
    sim: SimRobot, server: LineServer
) -> None:
    with (
        ArcosBase.open(server.path) as base,
        VCC4(base.aux_transport(1), answer_timeout=1.0) as camera,
    ):
        pan, tilt = camera.move_to(math.radians(-35), math.radians(20))
        with sim.lock:
            assert sim.head() == pytest.approx((math.radians(-35), math.radians(20)), abs=TOLERANCE)
        assert (pan, tilt) == pytest.approx(sim.head(), abs=TOLERANCE)
        assert camera.zoom_to(300) == 300


def test_cli_via_aux(server: LineServer, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "vcc4", "--port", server.path, "--via-aux", "goto", "12", "0"]) == 0
    pan, tilt = re.match(r"pan (\S+) deg, tilt (\S+) deg", capsys.readouterr().out).groups()
    assert (float(pan), float(tilt)) == pytest.approx((12.0, 0.0), abs=0.1)
