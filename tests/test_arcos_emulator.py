"""The emulated ARCOS firmware on its own (no pty): handshake bytes, OPEN forms, SIP stream,
still-open behaviour, motion commands, watchdog, AUX tunnel, fault knobs."""

from __future__ import annotations

import math
import time

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


def opened(aux1: EchoDevice | None = None, scale: float = 1.0) -> tuple[ArcosEmulator, float]:
    emu = ArcosEmulator(KinematicActuator(scale), aux1, name="MyBot")
    now = time.monotonic()
    for step in (0, 1, 2):
        exchange(emu, command(step), now)
    exchange(emu, command(Command.OPEN, 1), now)
    return emu, now


def test_handshake_bytes() -> None:
    emu = ArcosEmulator(KinematicActuator(), name="MyBot")
    now = time.monotonic()
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
    emu = ArcosEmulator(KinematicActuator())
    now = time.monotonic()
    for step in (0, 1, 2):
        exchange(emu, command(step), now)
    assert exchange(emu, command(Command.OPEN, open_arg), now) == []
    assert emu.state == "open"
    sips = []
    for i in range(1, 11):  # half a second of 50 ms ticks, each just past a SIP's due time
        sips += exchange(emu, b"", now + 0.05 * i + 1e-6)
    assert len(sips) == 5 and all(is_sip(p) for p in sips)


def test_no_sips_and_no_motion_before_open() -> None:
    emu = ArcosEmulator(KinematicActuator())
    now = time.monotonic()
    assert exchange(emu, command(Command.VEL, 200), now + 1) == []
    assert emu.actuator.velocity == (0.0, 0.0)


def test_sync0_while_open_answers_with_sips_then_close_ends_the_session() -> None:
    emu, now = opened()
    assert exchange(emu, command(Command.SYNC0), now + 0.2)[0][0] == 0x32
    assert exchange(emu, command(Command.CLOSE, 1), now + 0.3) == []
    assert emu.state == "waiting"
    assert exchange(emu, b"", now + 1.0) == []
    assert exchange(emu, command(Command.SYNC0), now + 1.1) == [b"\x00"]


def test_bad_checksum_is_ignored() -> None:
    emu, now = opened()
    bad = bytearray(command(Command.ENABLE, 1))
    bad[-1] ^= 1
    exchange(emu, bytes(bad), now)
    assert emu.bad_packets == 1 and not emu.motors_enabled


def test_motion_needs_enable_and_follows_vel_rvel_vel2_stop() -> None:
    emu, now = opened()
    act = emu.actuator
    exchange(emu, command(Command.VEL, 200), now)
    assert act.velocity == (0.0, 0.0)  # motors off: ignored (allenh1/p2os#41)
    exchange(
        emu,
        command(Command.ENABLE, 1)
        + command(Command.SETA, 10000)
        + command(Command.SETA, -10000)
        + command(Command.SETRA, 10000)
        + command(Command.SETRA, -10000),
        now,
    )
    exchange(emu, command(Command.VEL, 200) + command(Command.RVEL, -30), now)
    time.sleep(0.05)
    exchange(emu, b"", now + 0.05)
    v, w = act.velocity
    assert v == pytest.approx(0.2) and w == pytest.approx(math.radians(-30))
    exchange(emu, command(Command.VEL2, vel2_argument(-100, 100)), now + 0.1)
    time.sleep(0.05)
    exchange(emu, b"", now + 0.15)
    v, w = act.velocity
    assert v == pytest.approx(0.0, abs=1e-9) and w == pytest.approx(0.2 / act.track)
    exchange(emu, command(Command.STOP), now + 0.2)
    time.sleep(0.05)
    exchange(emu, b"", now + 0.25)
    assert act.velocity == (0.0, 0.0)


def _run(emu: ArcosEmulator, seconds: float, now: float) -> float:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now += 0.01
        exchange(emu, command(Command.PULSE), now)
        time.sleep(0.005)
    return now


def test_head_and_move_servo_to_their_targets() -> None:
    emu, now = opened(scale=8.0)
    exchange(emu, command(Command.ENABLE, 1), now)
    exchange(emu, command(Command.HEAD, 90), now)
    now = _run(emu, 0.6, now)
    x, y, th = emu.actuator.odometry()
    assert math.degrees(th) == pytest.approx(90.0, abs=0.6)
    exchange(emu, command(Command.MOVE, 500), now)
    now = _run(emu, 0.8, now)
    x, y, th = emu.actuator.odometry()
    assert (x, y) == pytest.approx((0.0, 0.5), abs=0.01)
    sip = parse_sip([p for p in exchange(emu, b"", now + 0.2) if is_sip(p)][-1])
    assert not sip.moving and sip.y == pytest.approx(500, abs=10)
    exchange(emu, command(Command.DHEAD, -45), now)
    now = _run(emu, 0.5, now)
    assert math.degrees(emu.actuator.odometry()[2]) == pytest.approx(45.0, abs=0.6)
    exchange(emu, command(Command.SETO), now)
    sip = parse_sip([p for p in exchange(emu, b"", now + 0.2) if is_sip(p)][-1])
    assert (sip.x, sip.y, sip.th) == (0, 0, 0)


def test_watchdog_halts_after_two_silent_seconds_and_resumes_on_traffic() -> None:
    emu, now = opened()
    exchange(emu, command(Command.ENABLE, 1) + command(Command.SETA, 10000), now)
    exchange(emu, command(Command.VEL, 300), now)
    time.sleep(0.05)
    exchange(emu, b"", now + 0.1)
    assert emu.actuator.velocity[0] == pytest.approx(0.3)
    exchange(emu, b"", now + 1.9)
    assert not emu.watchdog_tripped
    exchange(emu, b"", now + 2.1)
    assert emu.watchdog_tripped and emu.actuator.velocity == (0.0, 0.0)
    sips = exchange(emu, b"", now + 2.3)
    assert sips, "SIPs keep coming while the watchdog holds the wheels"
    exchange(emu, command(Command.PULSE), now + 2.4)
    time.sleep(0.05)
    exchange(emu, b"", now + 2.45)
    assert not emu.watchdog_tripped and emu.actuator.velocity[0] == pytest.approx(0.3)


def test_aux_tunnel_getaux_waits_for_n_bytes() -> None:
    echo = EchoDevice()
    emu, now = opened(echo)
    assert exchange(emu, command(Command.GETAUX, 6), now) == []

    def aux(data: bytes) -> list[bytes]:
        return [p for p in exchange(emu, data, now) if p[0] == SERAUX]

    assert aux(command(Command.TTY2, b"abc")) == []  # only 3 of 6
    assert aux(command(Command.TTY2, b"defgh")) == [bytes([SERAUX]) + b"abcdef"]
    assert aux(command(Command.GETAUX, 0)) == []  # flush drops "gh"
    assert aux(command(Command.GETAUX, 1)) == []
    assert aux(command(Command.TTY2, b"z")) == [frame(b"\xb0z")[3:-2]]


def test_fault_knobs() -> None:
    emu, now = opened()
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
