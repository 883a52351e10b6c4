"""The emulated ARCOS firmware on its own (no pty): handshake bytes, OPEN forms, SIP stream,
still-open behaviour, motion commands, watchdog, AUX tunnel, fault knobs.

The test is the firmware's clock: it hands the emulator each ``now`` and moves the kinematic
robot's ``ManualClock`` along, so motion, SIP cycle and watchdog run in virtual time."""

from __future__ import annotations

import math

import pytest

from hardware.arcos_codec import (
    SERAUX,
    Command,
    PacketError,
    PacketParser,
    command,
    frame,
    is_sip,
    parse_sip,
    parse_sync2,
    vel2_argument,
)
from twin.core.clock import ManualClock
from twin.serial_twins.arcos import ArcosEmulator, KinematicActuator
from twin.serial_twins.bytedevice import EchoDevice


def packets(data: bytes) -> list[bytes]:
    parser = PacketParser()
    parser.feed(data)
    out = []
    while (p := parser.next()) is not None:
        out.append(p)
    return out


def exchange(emu: ArcosEmulator, data: bytes, now: float) -> list[bytes]:
    emu.receive(data, now)
    emu.tick(now)
    return packets(emu.transmit(now))


def later(emu: ArcosEmulator, clock: ManualClock, seconds: float, data: bytes = b"") -> list[bytes]:
    """Let ``seconds`` pass (robot and firmware alike), then exchange ``data``."""
    clock.advance(seconds)
    return exchange(emu, data, clock.now())


def opened(aux1: EchoDevice | None = None) -> tuple[ArcosEmulator, ManualClock]:
    clock = ManualClock(100.0)
    emu = ArcosEmulator(KinematicActuator(clock=clock), aux1, name="MyBot")
    for step in (0, 1, 2):
        exchange(emu, command(step), clock.now())
    exchange(emu, command(Command.OPEN, 1), clock.now())
    return emu, clock


def test_handshake_bytes() -> None:
    emu = ArcosEmulator(KinematicActuator(clock=ManualClock()), name="MyBot")
    now = 0.0
    emu.receive(b"WMS2\r" + command(Command.SYNC0), now)  # ARIA's junk before syncing
    assert emu.transmit(now) == bytes.fromhex("FA FB 03 00 00 00")
    emu.receive(command(Command.SYNC1), now)
    assert emu.transmit(now) == bytes.fromhex("FA FB 03 01 00 01")
    emu.receive(command(Command.SYNC2), now)
    reply = emu.transmit(now)
    assert reply == bytes.fromhex(
        "FA FB 1E 02 4D 79 42 6F 74 00 50 69 6F 6E 65 65 72 00 70 65 "
        "6F 70 6C 65 62 6F 74 2D 73 68 00 69 2D"
    )
    assert parse_sync2(packets(reply)[0]) == ("MyBot", "Pioneer", "peoplebot-sh")


@pytest.mark.parametrize("open_arg", [None, 1])
def test_open_in_both_forms_starts_sips_every_100_ms(open_arg: int | None) -> None:
    emu = ArcosEmulator(KinematicActuator(clock=ManualClock()))
    now = 0.0
    for step in (0, 1, 2):
        exchange(emu, command(step), now)
    assert exchange(emu, command(Command.OPEN, open_arg), now) == []
    assert emu.state == "open"
    sips = []
    for i in range(1, 11):  # half a second of 50 ms ticks, each just past a SIP's due time
        sips += exchange(emu, b"", now + 0.05 * i + 1e-6)
    assert len(sips) == 5 and all(is_sip(p) for p in sips)


def test_no_sips_and_no_motion_before_open() -> None:
    emu = ArcosEmulator(KinematicActuator(clock=ManualClock()))
    now = 0.0
    assert exchange(emu, command(Command.VEL, 200), now + 1) == []
    assert emu.actuator.velocity == (0.0, 0.0)


def test_sync0_while_open_answers_with_sips_then_close_ends_the_session() -> None:
    emu, clock = opened()
    assert later(emu, clock, 0.2, command(Command.SYNC0))[0][0] == 0x32
    assert later(emu, clock, 0.1, command(Command.CLOSE, 1)) == []
    assert emu.state == "waiting"
    assert later(emu, clock, 0.7) == []
    assert later(emu, clock, 0.1, command(Command.SYNC0)) == [b"\x00"]


def test_bad_checksum_is_ignored() -> None:
    emu, clock = opened()
    bad = bytearray(command(Command.ENABLE, 1))
    bad[-1] ^= 1
    exchange(emu, bytes(bad), clock.now())
    assert emu.bad_packets == 1 and not emu.motors_enabled


def test_motion_needs_enable_and_follows_vel_rvel_vel2_stop() -> None:
    emu, clock = opened()
    act = emu.actuator
    exchange(emu, command(Command.VEL, 200), clock.now())
    assert act.velocity == (0.0, 0.0)  # motors off: ignored (allenh1/p2os#41)
    exchange(
        emu,
        command(Command.ENABLE, 1)
        + command(Command.SETA, 10000)
        + command(Command.SETA, -10000)
        + command(Command.SETRA, 10000)
        + command(Command.SETRA, -10000),
        clock.now(),
    )
    exchange(emu, command(Command.VEL, 200) + command(Command.RVEL, -30), clock.now())
    later(emu, clock, 0.05)  # 10 m/s^2 and 10000 deg/s^2: full speed within one tick
    v, w = act.velocity
    assert v == pytest.approx(0.2) and w == pytest.approx(math.radians(-30))
    later(emu, clock, 0.05, command(Command.VEL2, vel2_argument(-100, 100)))
    later(emu, clock, 0.05)
    v, w = act.velocity
    assert v == pytest.approx(0.0, abs=1e-9) and w == pytest.approx(0.2 / act.track)
    later(emu, clock, 0.05, command(Command.STOP))
    later(emu, clock, 0.05)
    assert act.velocity == (0.0, 0.0)


def _run(emu: ArcosEmulator, clock: ManualClock, seconds: float) -> None:
    """``seconds`` of a client that keeps talking, ticked every 10 ms like the pty server."""
    for _ in range(round(seconds / 0.01)):
        later(emu, clock, 0.01, command(Command.PULSE))


def test_head_and_move_servo_to_their_targets() -> None:
    emu, clock = opened()
    exchange(emu, command(Command.ENABLE, 1), clock.now())
    exchange(emu, command(Command.HEAD, 90), clock.now())
    _run(emu, clock, 2.0)  # 90 deg at up to 100 deg/s, 150 deg/s^2
    x, y, th = emu.actuator.odometry()
    assert math.degrees(th) == pytest.approx(90.0, abs=0.6)
    exchange(emu, command(Command.MOVE, 500), clock.now())
    _run(emu, clock, 3.5)  # 0.5 m at up to 0.75 m/s, 0.3 m/s^2
    x, y, th = emu.actuator.odometry()
    assert (x, y) == pytest.approx((0.0, 0.5), abs=0.01)
    sip = parse_sip([p for p in later(emu, clock, 0.2) if is_sip(p)][-1])
    assert not sip.moving and sip.y == pytest.approx(500, abs=10)
    exchange(emu, command(Command.DHEAD, -45), clock.now())
    _run(emu, clock, 1.5)
    assert math.degrees(emu.actuator.odometry()[2]) == pytest.approx(45.0, abs=0.6)
    exchange(emu, command(Command.SETO), clock.now())
    # the next SIP, before the robot moved on: the firmware's SIP clock jumps, the robot's not
    sip = parse_sip([p for p in exchange(emu, b"", clock.now() + 0.2) if is_sip(p)][-1])
    assert (sip.x, sip.y, sip.th) == (0, 0, 0)


def test_watchdog_halts_after_two_silent_seconds_and_resumes_on_traffic() -> None:
    emu, clock = opened()
    exchange(emu, command(Command.ENABLE, 1) + command(Command.SETA, 10000), clock.now())
    exchange(emu, command(Command.VEL, 300), clock.now())
    later(emu, clock, 0.1)
    assert emu.actuator.velocity[0] == pytest.approx(0.3)
    later(emu, clock, 1.8)  # 1.9 s of silence
    assert not emu.watchdog_tripped
    later(emu, clock, 0.2)  # 2.1 s
    assert emu.watchdog_tripped and emu.actuator.velocity == (0.0, 0.0)
    stopped_at = emu.actuator.odometry()
    sips = later(emu, clock, 0.2)
    assert sips, "SIPs keep coming while the watchdog holds the wheels"
    assert emu.actuator.odometry() == stopped_at
    later(emu, clock, 0.1, command(Command.PULSE))
    later(emu, clock, 0.05)
    assert not emu.watchdog_tripped and emu.actuator.velocity[0] == pytest.approx(0.3)


def test_aux_tunnel_getaux_waits_for_n_bytes() -> None:
    echo = EchoDevice()
    emu, clock = opened(echo)
    now = clock.now()
    assert exchange(emu, command(Command.GETAUX, 6), now) == []

    def aux(data: bytes) -> list[bytes]:
        return [p for p in exchange(emu, data, now) if p[0] == SERAUX]

    assert aux(command(Command.TTY2, b"abc")) == []  # only 3 of 6
    assert aux(command(Command.TTY2, b"defgh")) == [bytes([SERAUX]) + b"abcdef"]
    assert aux(command(Command.GETAUX, 0)) == []  # flush drops "gh"
    assert aux(command(Command.GETAUX, 1)) == []
    assert aux(command(Command.TTY2, b"z")) == [frame(b"\xb0z")[3:-2]]


def test_fault_knobs() -> None:
    emu, clock = opened()
    now = clock.now()
    emu.faults.junk = b"noise"
    emu.faults.bad_checksum = 1
    emu.receive(command(Command.PULSE), now)
    emu.tick(now + 0.2)
    data = emu.transmit(now + 0.2)
    assert data.startswith(b"noise")
    with pytest.raises(PacketError, match="checksum"):
        packets(data)
    emu.faults.truncate = 1
    emu.tick(now + 0.4)
    parser = PacketParser()
    parser.feed(emu.transmit(now + 0.4))
    assert parser.next() is None and parser.partial
    emu.faults.mute = True
    assert exchange(emu, command(Command.SYNC0), now + 0.6) == []
