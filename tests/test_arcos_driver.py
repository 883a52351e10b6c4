"""The ARCOS driver against the emulated firmware (kinematic actuator: no MuJoCo): handshake,
odometry, motion, keep-alive, AUX tunnel, and the faults of issue 6 — junk, bad checksums,
truncated packets, silence, a hung-up line.

Most tests run on a ``MemoryLink`` in virtual time (``ManualClock``): the driver's reader
thread, the emulator's server thread and the robot share one clock that moves only when all of
them wait, so the 2 s watchdog, the SIP timeouts and the handshake's retries are checked to the
millisecond and a loaded machine cannot fire them early. The last few run end to end over a
real pseudo-terminal in real time: the CLI, and a line hung up under the driver.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from hardware.arcos import ArcosBase
from twin.core.clock import ManualClock
from twin.core.devices import (
    BumpedError,
    ConnectionLostError,
    DeviceFaultError,
    DeviceTimeoutError,
    NotConnectedError,
    OutOfRangeError,
)
from twin.core.geometry import Pose2D
from twin.serial_twins.arcos import KinematicActuator, serve_arcos
from twin.serial_twins.bytedevice import EchoDevice, LineServer
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.pty import PtyLink


def _serve(clock: ManualClock, actuator: KinematicActuator | None = None) -> LineServer:
    link = MemoryLink(clock, "arcos line")
    actuator = actuator or KinematicActuator(clock=clock)
    return serve_arcos(actuator, link, aux1=EchoDevice(), clock=clock)


@pytest.fixture
def server() -> Iterator[LineServer]:
    srv = _serve(ManualClock())
    yield srv
    srv.stop()


def base_on(server: LineServer, **options: object) -> ArcosBase:
    """A driver on the server's line and clock, with short timeouts."""
    options = {"reply_timeout": 0.3, "sync_attempts": 4, "sip_timeout": 0.5, **options}
    link = server.link
    assert isinstance(link, MemoryLink)
    return ArcosBase(lambda: link.transport("ARCOS base"), clock=server.clock, **options)  # type: ignore[arg-type]


def odometry_in_map(server: LineServer, start: Pose2D) -> Pose2D:
    x, y, th = server.emulator.actuator.odometry()
    c, s = math.cos(start.yaw), math.sin(start.yaw)
    return Pose2D(start.x + c * x - s * y, start.y + s * x + c * y, start.yaw + th)


def test_connect_reports_identity_and_anchors_the_start(server: LineServer) -> None:
    start = Pose2D(1.0, 2.0, math.pi / 2)
    with base_on(server, start=start) as base:
        assert base.identity == ("twin", "Pioneer", "peoplebot-sh")
        pose = base.pose()
        assert (pose.x, pose.y, pose.yaw) == pytest.approx((1.0, 2.0, math.pi / 2), abs=2e-3)
        assert base.last_sip.motors_enabled and base.last_sip.battery == pytest.approx(12.6)
        assert server.emulator.max_vel == 500.0  # SETV from the driver's limits
    assert server.emulator.state == "waiting"  # CLOSE on exit
    assert server.emulator.commands[-1] == (2, 1)


def test_use_before_connect_is_a_typed_error(server: LineServer) -> None:
    with pytest.raises(NotConnectedError):
        base_on(server).pose()


def test_drive_moves_the_robot_for_its_duration_and_the_pose_tracks_its_odometry(
    server: LineServer,
) -> None:
    start = Pose2D(0.5, 0.5, 0.0)
    clock = server.clock
    with base_on(server, start=start) as base:
        began = clock.now()
        pose = base.drive(0.1, math.radians(20), 2.0)
        # two seconds of driving, then a stop that settles within a few SIP cycles
        assert 2.0 <= clock.now() - began < 2.6
        truth = odometry_in_map(server, start)
        assert pose.distance_to(truth) < 0.005
        assert abs(pose.heading_error_to(truth)) < math.radians(0.3)
        assert 0.15 < pose.distance_to(start) < 0.21  # an arc of 0.1 m/s for 2 s, and the stop
        assert server.emulator.actuator.velocity == (0.0, 0.0)
        with pytest.raises(OutOfRangeError):
            base.drive(3.0, 0.0, 1.0)


def test_go_to_ends_within_5_cm_and_3_degrees(server: LineServer) -> None:
    start = Pose2D(1.0, 1.0, 0.0)
    with base_on(server, start=start) as base:
        for goal in (
            Pose2D(2.0, 1.5, math.pi / 2),
            Pose2D(1.2, 0.4, -2.5),
            Pose2D(1.21, 0.41, 1.0),
        ):
            pose = base.go_to(goal, timeout=20.0)
            truth = odometry_in_map(server, start)
            for p in (pose, truth):
                assert p.distance_to(goal) < 0.05
                assert abs(p.heading_error_to(goal)) < math.radians(3.0)


def test_set_pose_reanchors_without_moving(server: LineServer) -> None:
    with base_on(server) as base:
        base.set_pose(Pose2D(3.0, 4.0, 1.0))
        pose = base.pose()
        assert (pose.x, pose.y, pose.yaw) == pytest.approx((3.0, 4.0, 1.0), abs=2e-3)
        base.drive(0.1, 0.0, 0.5)
        pose = base.pose()
        assert pose.x > 3.0 and pose.y > 4.0  # forward along yaw 1 rad


def test_keepalive_holds_the_watchdog_off(server: LineServer) -> None:
    with base_on(server) as base:
        server.clock.sleep(2.6)  # idle past the 2 s watchdog: the reader thread sent PULSEs
        assert not server.emulator.watchdog_tripped
        assert base.pose() is not None
        base.pulse_period = 10.0  # without them the firmware stops the robot
        server.clock.sleep(2.6)
        assert server.emulator.watchdog_tripped


def test_robot_left_open_by_a_crashed_client_is_closed_and_resynced(server: LineServer) -> None:
    crashed = base_on(server)
    crashed.connect()
    crashed._stop_link()  # a client that dies without CLOSE
    assert server.emulator.state == "open"
    with base_on(server) as base:
        assert base.still_open_recoveries >= 1
        assert base.identity is not None and base.pose() is not None


def test_junk_bad_checksums_and_truncated_packets_are_survived(server: LineServer) -> None:
    with base_on(server) as base:
        faults = server.emulator.faults
        faults.junk = b"WMS2\r\xfa\x00garbage"
        faults.bad_checksum = 3
        server.clock.sleep(0.6)
        faults.truncate = 2
        server.clock.sleep(0.6)
        assert base.protocol_errors >= 5
        assert str(base.last_protocol_error).startswith("ARCOS base: read a packet: ")
        count = base.sip_count
        pose = base.drive(0.1, 0.0, 1.0)
        assert base.sip_count > count and pose.x > 0.05


def test_a_robot_that_stops_answering_is_a_timeout_not_a_hang(server: LineServer) -> None:
    clock = server.clock
    with base_on(server) as base:
        server.emulator.faults.mute = True
        began = clock.now()
        with pytest.raises(DeviceTimeoutError, match=r"no SIP from the robot for 0\.5 s"):
            base.go_to(Pose2D(1.0, 0.0, 0.0), timeout=30.0)
        assert 0.5 <= clock.now() - began < 0.7  # the 0.5 s SIP timeout, not go_to's 30 s
        with pytest.raises(DeviceTimeoutError):
            base.pose()


def test_handshake_with_a_silent_robot_times_out(server: LineServer) -> None:
    server.emulator.faults.mute = True
    base = base_on(server, reply_timeout=0.2, sync_attempts=3)
    began = server.clock.now()
    with pytest.raises(DeviceTimeoutError, match=r"SYNC0 handshake: no proper reply in 3 tries"):
        base.connect()
    assert server.clock.now() - began == pytest.approx(3 * 0.2)  # 3 x 0.2 s, each waited out
    assert not base.is_connected


def test_stall_during_motion_is_a_fault(server: LineServer) -> None:
    with base_on(server) as base:
        server.emulator.actuator.stalled = True
        with pytest.raises(DeviceFaultError, match="stalled"):
            base.drive(0.1, 0.0, 2.0)
        server.emulator.actuator.stalled = False
        server.emulator.actuator.front_bumpers = 0b100
        with pytest.raises(BumpedError, match="front bumpers") as caught:
            base.go_to(Pose2D(1.0, 0.0, 0.0))
        assert caught.value.bearing == 0.0  # ahead: what the re-planning base plans around


def test_a_line_cut_mid_use_reconnects_through_the_still_open_handshake(
    server: LineServer,
) -> None:
    start = Pose2D(1.0, 1.0, 0.0)
    with base_on(server, start=start) as base:
        base.drive(0.1, 0.0, 1.5)
        before = base.pose()
        server.hangup()  # whichever notices first, the reader or the next command, reconnects
        pose = base.go_to(Pose2D(2.0, 1.0, 0.0), timeout=20.0)
        assert base.reconnects == 1 and base.still_open_recoveries >= 1
        assert pose.distance_to(Pose2D(2.0, 1.0, 0.0)) < 0.05
        assert before.x > 1.1


def test_a_line_cut_without_auto_reconnect_is_connection_lost(server: LineServer) -> None:
    with base_on(server, auto_reconnect=False) as base:
        server.hangup()
        server.clock.sleep(0.05)  # the reader's next 20 ms read meets the dead line
        with pytest.raises(ConnectionLostError, match="arcos line was hung up"):
            base.pose()
        with pytest.raises(ConnectionLostError):
            base.go_to(Pose2D(1.0, 0.0, 0.0))


def test_aux_tunnel_round_trip(server: LineServer) -> None:
    clock = server.clock
    with base_on(server) as base:
        aux = base.aux_transport()
        aux.write(b"\xff\x30\x30\x00\x63\xef")
        assert aux.read(6, 1.0) == b"\xff\x30\x30\x00\x63\xef"
        big = bytes(range(256)) * 2  # more than one TTY2 / GETAUX packet
        aux.write(big)
        assert aux.read(len(big), 3.0) == big
        aux.write(b"abc")  # a shorter answer than asked for still gets through
        began = clock.now()
        assert aux.read(6, 0.8) == b"abc"
        assert 0.8 <= clock.now() - began < 0.85  # waited out its 0.8 s, then returned
        aux.write(b"stale")
        clock.sleep(0.1)
        aux.reset_input()
        aux.write(b"new")
        assert aux.read(3, 1.0) == b"new"
        assert aux.read(1, 0.2) == b""


def test_failed_connect_leaves_the_robot_closed(server: LineServer) -> None:
    original = server.emulator._handle

    def refuse_enable(number: int, arg: object, now: float) -> None:
        if number != 4:  # ENABLE: the robot is there, but its motors stay off
            original(number, arg, now)  # type: ignore[arg-type]

    server.emulator._handle = refuse_enable  # type: ignore[method-assign]
    with pytest.raises(DeviceFaultError, match="STOP button"):
        base_on(server).connect()
    server.clock.sleep(0.1)
    assert server.emulator.state == "waiting"


def test_sip_x_wraparound_is_unwrapped_into_continuous_odometry() -> None:
    """Start 5 cm short of the 15-bit x wrap (32.767 m): the SIP's x jumps to ~0, the pose
    must not."""
    clock = ManualClock()
    srv = _serve(clock, KinematicActuator(start=(32.72, -32.72, 0.0), clock=clock))
    try:
        with base_on(srv, start=Pose2D(1.0, 1.0, 0.0)) as base:
            assert base.last_sip.x > 32000
            pose = base.drive(0.1, 0.0, 1.5)
            assert base.last_sip.x < 1000  # wrapped on the wire
            moved = srv.emulator.actuator.odometry()[0] - 32.72
            assert moved > 0.1
            assert pose.x == pytest.approx(1.0 + moved, abs=0.003)
            assert pose.y == pytest.approx(1.0, abs=0.003)
    finally:
        srv.stop()


# -- end to end over a real pseudo-terminal, in real time ------------------------------------

SCALE = 4.0  # the kinematic robot's clock runs this much faster than the wall


@pytest.fixture
def pty_server(tmp_path: Path) -> Iterator[LineServer]:
    srv = serve_arcos(KinematicActuator(SCALE), PtyLink(tmp_path / "arcos"), aux1=EchoDevice())
    yield srv
    srv.stop()


def _eventually(condition: Callable[[], bool], seconds: float = 10.0) -> bool:
    """True once ``condition`` holds; False if it still does not after ``seconds`` (a bound
    for a thread of the driver to notice something, far beyond what it needs)."""
    end = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def test_cli_status_and_drive(pty_server: LineServer, capsys: pytest.CaptureFixture[str]) -> None:
    from twin.cli import main

    path = pty_server.path
    assert main(["hw", "arcos", "--port", path, "status"]) == 0
    out = capsys.readouterr().out
    assert "robot: twin  class: Pioneer  subclass: peoplebot-sh" in out
    assert "battery: 12.6 V" in out and "stall/bumpers: clear" in out
    assert not pty_server.emulator.motors_enabled
    drive = ["drive", "--vel", "100", "--rvel", "0", "--seconds", "0.5"]
    assert main(["hw", "arcos", "--port", path, *drive]) == 0
    assert "drove" in capsys.readouterr().out
    assert pty_server.emulator.actuator.odometry()[0] > 0.1  # ~0.1 m/s x 0.5 s x SCALE
    assert main(["hw", "arcos", "--port", path + ".missing", "status"]) == 2
    assert "no such port" in capsys.readouterr().err


def test_pty_hangup_mid_use_reopens_the_port_and_reconnects(pty_server: LineServer) -> None:
    start = Pose2D(1.0, 1.0, 0.0)
    with ArcosBase.open(pty_server.path, start=start) as base:
        base.drive(0.1, 0.0, 0.5)
        before = base.pose()
        pty_server.hangup()  # a new pty behind the same path, the robot still open
        pose = base.go_to(Pose2D(2.0, 1.0, 0.0), timeout=20.0)
        assert base.reconnects == 1 and base.still_open_recoveries >= 1
        assert pose.distance_to(Pose2D(2.0, 1.0, 0.0)) < 0.05
        assert before.x > 1.1


def test_pty_hangup_without_auto_reconnect_is_connection_lost(pty_server: LineServer) -> None:
    with ArcosBase.open(pty_server.path, auto_reconnect=False) as base:
        pty_server.hangup()
        # the reader thread meets the dead pty on its next read (a 20 ms slice)
        assert _eventually(lambda: base._lost is not None)
        with pytest.raises(ConnectionLostError):
            base.pose()
        with pytest.raises(ConnectionLostError):
            base.go_to(Pose2D(1.0, 0.0, 0.0))
