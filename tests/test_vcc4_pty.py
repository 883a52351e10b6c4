"""The real VC-C4 driver against the emulator moving the MuJoCo robot's head.

End to end over a real pseudo-terminal in real time (the world stepped at 4x the wall clock):
a move, a line hung up and reopened, and the CLI. The rest runs on a ``MemoryLink`` in virtual
time (``ManualClock``, the world at exactly real-time pace in it): the camera's 9600-baud
answers, its busy spells and the driver's timeouts are exact there, whatever the machine's load.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from hardware import vcc4_codec as codec
from hardware.transport import SerialTransport
from hardware.vcc4 import VCC4
from twin.cli import main
from twin.core.clock import ManualClock
from twin.core.devices import ConnectionLostError, DeviceTimeoutError, ProtocolError
from twin.serial_twins.bytedevice import LineServer
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.pty import PtyLink
from twin.serial_twins.runner import WorldRunner
from twin.serial_twins.vcc4 import VCC4Timing, serve_vcc4
from twin.sim import SimRobot, make_sim_robot

TIME_SCALE = 4.0
TOLERANCE = math.radians(0.3)


@pytest.fixture(scope="module")
def sim() -> Iterator[SimRobot]:
    robot, _ = make_sim_robot()
    with WorldRunner(robot, time_scale=TIME_SCALE):
        yield robot


@pytest.fixture
def server(sim: SimRobot, tmp_path: Path) -> Iterator[LineServer]:
    timing = VCC4Timing(power_seconds=0.2, init_seconds=0.2)
    with serve_vcc4(sim, PtyLink(tmp_path / "vcc4"), timing=timing, camera_on=False) as srv:
        yield srv


@pytest.fixture(scope="module")
def virtual_sim() -> Iterator[tuple[SimRobot, ManualClock]]:
    clock = ManualClock()
    robot, _ = make_sim_robot()
    with WorldRunner(robot, clock=clock):
        yield robot, clock


@pytest.fixture
def virtual(virtual_sim: tuple[SimRobot, ManualClock]) -> Iterator[tuple[LineServer, VCC4]]:
    """An emulator with the real camera's timing on a memory line, and a driver on it."""
    sim, clock = virtual_sim
    link = MemoryLink(clock, "vcc4 line")
    with serve_vcc4(sim, link, clock=clock) as srv:
        camera = VCC4(opener=lambda: link.transport("VC-C4"), clock=clock)
        yield srv, camera
        camera.close()


def test_move_to_reaches_the_angle_in_the_sim_left_positive(
    sim: SimRobot, server: LineServer
) -> None:
    with VCC4.open(server.path) as camera:
        assert server.emulator.host_mode and server.emulator.pedestal_ready
        pan, tilt = camera.move_to(math.radians(40), math.radians(15))
        with sim.lock:
            truth = sim.head()
        assert truth == pytest.approx((math.radians(40), math.radians(15)), abs=TOLERANCE)
        assert (pan, tilt) == pytest.approx(truth, abs=TOLERANCE)
        # left on the API is negative on the wire
        last = [c for c in server.emulator.received if c.code == codec.PAN_TILT][-1]
        assert codec.decode_pan_tilt(last.params)[0] == codec.degrees_to_count(-40)
        camera.move_to(math.radians(-60), 0.0)
        with sim.lock:
            assert sim.head()[0] == pytest.approx(math.radians(-60), abs=TOLERANCE)
        assert camera.position() == pytest.approx((math.radians(-60), 0.0), abs=TOLERANCE)


def _top_pan_rate(sim: SimRobot, move: object) -> float:
    """The fastest the sim's pan joint turned (rad/s) while ``move`` ran."""
    rates = [0.0]

    def watch(robot: SimRobot) -> None:
        rates.append(abs(robot.head_rates()[0]))

    with sim.lock:
        sim.listeners.append(watch)
    try:
        move()  # type: ignore[operator]
    finally:
        with sim.lock:
            sim.listeners.remove(watch)
    return max(rates)


def test_speeds_are_respected(
    virtual_sim: tuple[SimRobot, ManualClock], virtual: tuple[LineServer, VCC4]
) -> None:
    sim, clock = virtual_sim
    _, camera = virtual
    with camera:
        camera.move_to(0.0, 0.0)
        start = clock.now()
        slow = _top_pan_rate(sim, lambda: camera.move_to(math.radians(30), speed=math.radians(20)))
        assert clock.now() - start >= 30 / 20  # 30 degrees at 20 deg/s
        fast = _top_pan_rate(sim, lambda: camera.move_to(0.0))
        assert math.radians(15) < slow < math.radians(20) * 1.05
        assert fast > math.radians(60)


def test_a_silent_camera_is_a_timeout_not_a_hang(virtual: tuple[LineServer, VCC4]) -> None:
    server, camera = virtual
    camera.answer_timeout = 0.3
    with camera:
        clock = camera.clock
        server.emulator.faults.silent = True
        start = clock.now()
        with pytest.raises(DeviceTimeoutError, match=r"no answer within 0\.3 s"):
            camera.position()
        assert clock.now() - start == pytest.approx(2 * 0.3)  # one resend, then the error
        server.emulator.faults.silent = False
        assert camera.position() == pytest.approx((0.0, 0.0), abs=TOLERANCE)


def test_line_faults_are_recovered_or_typed(virtual: tuple[LineServer, VCC4]) -> None:
    server, camera = virtual
    faults = server.emulator.faults
    with camera:
        faults.junk_count = 3
        camera.move_to(math.radians(5))
        faults.truncate_count, faults.garble_count = 1, 1
        assert camera.position()[0] == pytest.approx(math.radians(5), abs=TOLERANCE)
        faults.truncate_count = 2
        with pytest.raises(ProtocolError, match="truncated"):
            camera.position()
        faults.garble_count = 2
        with pytest.raises(ProtocolError, match="garbled"):
            camera.position()
        assert camera.position()[0] == pytest.approx(math.radians(5), abs=TOLERANCE)


def test_a_cut_memory_line_is_reopened_by_the_driver(virtual: tuple[LineServer, VCC4]) -> None:
    server, camera = virtual
    with camera:
        camera.move_to(math.radians(10))
        server.hangup()
        assert camera.move_to(math.radians(-10))[0] == pytest.approx(
            math.radians(-10), abs=TOLERANCE
        )


def test_hangup_mid_use_reopens_or_says_connection_lost(server: LineServer) -> None:
    with VCC4.open(server.path) as camera:
        camera.move_to(math.radians(10))
        server.hangup()  # unplugged and plugged in again: a new pty behind the same path
        assert camera.move_to(math.radians(-10))[0] == pytest.approx(
            math.radians(-10), abs=TOLERANCE
        )
    # a transport handed in (as the AUX tunnel is) is not the driver's to reopen
    transport = SerialTransport(server.path, 9600, "VC-C4", rts=True)
    camera = VCC4(transport)
    camera.connect()
    server.hangup()
    with pytest.raises(ConnectionLostError):
        camera.position()
    transport.close()


def _numbers(text: str) -> list[float]:
    return [float(n) for n in re.findall(r"-?\d+(?:\.\d+)?", text.split("\n")[-2])]


def test_cli_goto_and_position(server: LineServer, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["hw", "vcc4", "--port", server.path, "init"]) == 0
    assert capsys.readouterr().out.startswith("initialised")
    assert main(["hw", "vcc4", "--port", server.path, "goto", "25", "-5"]) == 0
    assert _numbers(capsys.readouterr().out) == pytest.approx([25.0, -5.0], abs=0.1)
    assert main(["hw", "vcc4", "--port", server.path, "zoom", "500"]) == 0
    assert main(["hw", "vcc4", "--port", server.path, "position"]) == 0
    assert _numbers(capsys.readouterr().out) == pytest.approx([25.0, -5.0, 500], abs=0.1)
    assert main(["hw", "vcc4", "--port", server.path, "goto", "150", "0"]) == 2
    assert "pan outside" in capsys.readouterr().err
    assert main(["hw", "vcc4", "--port", "/nonexistent/tty", "position"]) == 2
    assert "no such port" in capsys.readouterr().err
