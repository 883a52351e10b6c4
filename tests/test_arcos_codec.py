"""ARCOS codec: golden bytes from every worked example of specs/protocols.md (B4, B8, A10),
both directions, SIP round trips with x/y wrap-around, and a fuzz of the packet parser."""

from __future__ import annotations

import contextlib
import math
import subprocess
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware.arcos_codec import (
    Command,
    PacketError,
    PacketParser,
    Sip,
    SipExtension,
    checksum,
    command,
    encode_sip,
    frame,
    parse_command,
    parse_sip,
    parse_sync2,
    sync2_reply,
    vel2_argument,
    vel2_wheels,
    xy_delta,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# (command, argument, packet) from section B8 (and A10 for the AUX tunnel)
GOLDEN_COMMANDS = [
    (Command.SYNC0, None, "FA FB 03 00 00 00"),
    (Command.SYNC1, None, "FA FB 03 01 00 01"),
    (Command.SYNC2, None, "FA FB 03 02 00 02"),
    (Command.PULSE, None, "FA FB 03 00 00 00"),
    (Command.OPEN, None, "FA FB 03 01 00 01"),
    (Command.OPEN, 1, "FA FB 06 01 3B 01 00 02 3B"),
    (Command.VEL, 200, "FA FB 06 0B 3B C8 00 D3 3B"),
    (Command.VEL, -200, "FA FB 06 0B 1B C8 00 D3 1B"),
    (Command.ENABLE, 1, "FA FB 06 04 3B 01 00 05 3B"),
    (Command.ENABLE, 0, "FA FB 06 04 3B 00 00 04 3B"),
    (Command.RVEL, 30, "FA FB 06 15 3B 1E 00 33 3B"),
    (Command.MOVE, 1000, "FA FB 06 08 3B E8 03 F0 3E"),
    (Command.HEAD, 90, "FA FB 06 0C 3B 5A 00 66 3B"),
    (Command.DHEAD, -45, "FA FB 06 0D 1B 2D 00 3A 1B"),
    (Command.STOP, None, "FA FB 03 1D 00 1D"),
    (Command.SETO, None, "FA FB 03 07 00 07"),
    (Command.SONAR, 1, "FA FB 06 1C 3B 01 00 1D 3B"),
    (Command.IOREQUEST, 2, "FA FB 06 28 3B 02 00 2A 3B"),
    (Command.CONFIG, 1, "FA FB 06 12 3B 01 00 13 3B"),
    (Command.CLOSE, 1, "FA FB 06 02 3B 01 00 03 3B"),
    (Command.CLOSE, None, "FA FB 03 02 00 02"),
    (Command.SETV, 500, "FA FB 06 06 3B F4 01 FA 3C"),
    (Command.SETA, -300, "FA FB 06 05 1B 2C 01 31 1C"),
    (Command.VEL2, vel2_argument(100, 100), "FA FB 06 20 3B 05 05 25 40"),
    (Command.VEL2, vel2_argument(-100, 100), "FA FB 06 20 1B FB 04 1B 1F"),
    (Command.TTY2, h("FF 30 30 00 63 EF"), "FA FB 0B 2A 2B 06 FF 30 30 00 63 EF 61 52"),
    (Command.TTY2, h("FF 30 30 00 A0 31 EF"), "FA FB 0C 2A 2B 07 FF 30 30 00 A0 31 EF 94 E9"),
    (Command.GETAUX, 6, "FA FB 06 2B 3B 06 00 31 3B"),
]


@pytest.mark.parametrize(("cmd", "arg", "packet"), GOLDEN_COMMANDS)
def test_golden_commands_both_ways(cmd: int, arg: int | bytes | None, packet: str) -> None:
    assert command(cmd, arg) == h(packet)
    parser = PacketParser()
    parser.feed(h(packet))
    decoded = parse_command(parser.next())
    assert (decoded.number, decoded.arg) == (cmd, arg)
    assert parser.next() is None


def test_vel2_wheels_decode() -> None:
    assert vel2_wheels(0x0505) == (100, 100)
    assert vel2_wheels(-1275) == (-100, 100)


def test_checksum_worked_sums() -> None:
    assert checksum(h("2A 2B 06 FF 30 30 00 63 EF")) == 0x6152  # odd length: XOR of the last
    assert checksum(b"\x00") == 0


SIP_GOLDEN = (
    "FA FB 21 33 E8 03 F4 01 00 04 64 00 78 00 7D 00 00 00 04 1F 00 00 02 00 F4 01 "
    "01 B0 04 00 00 00 FF 00 10 33"
)
SIP_EXT_GOLDEN = (
    "FA FB 2C 33 E8 03 F4 01 00 04 64 00 78 00 7D 00 00 00 04 1F 00 00 02 00 F4 01 "
    "01 B0 04 00 00 00 FF 00 7D 00 00 25 00 00 00 00 00 81 00 B6 B0"
)
SIP_VALUES = Sip(
    moving=True,
    x=1000,
    y=500,
    th=1024,
    left_vel=100,
    right_vel=120,
    battery_dv=125,
    stall_bumpers=0,
    control=1024,
    flags=0x001F,
    compass=0,
    sonar=((0, 500), (1, 1200)),
    digin=0xFF,
)


def test_sip_golden_both_ways() -> None:
    assert encode_sip(SIP_VALUES) == h(SIP_GOLDEN)
    parser = PacketParser()
    parser.feed(h(SIP_GOLDEN))
    sip = parse_sip(parser.next())
    assert sip == SIP_VALUES
    assert sip.heading == pytest.approx(math.pi / 2)
    assert sip.battery == 12.5 and sip.motors_enabled and sip.fault() is None


def test_sip_extension_golden_both_ways() -> None:
    ext = SipExtension(
        battery_dv=125,
        charge_state=0,
        rot_vel=37,
        fault_flags=0,
        lat_vel=0,
        temperature=-127,
        state_of_charge=0,
    )
    sip = Sip(**{**SIP_VALUES.__dict__, "extension": ext})
    assert encode_sip(sip) == h(SIP_EXT_GOLDEN)
    parser = PacketParser()
    parser.feed(h(SIP_EXT_GOLDEN))
    assert parse_sip(parser.next()) == sip


def test_sync2_golden_both_ways() -> None:
    packet = h(
        "FA FB 1E 02 4D 79 42 6F 74 00 50 69 6F 6E 65 65 72 00 70 65 6F 70 6C 65 62 6F "
        "74 2D 73 68 00 69 2D"
    )
    assert sync2_reply("MyBot", "Pioneer", "peoplebot-sh") == packet
    parser = PacketParser()
    parser.feed(packet)
    assert parse_sync2(parser.next()) == ("MyBot", "Pioneer", "peoplebot-sh")


def test_stall_and_bumper_bits() -> None:
    sip = Sip(False, 0, 0, 0, 0, 0, 120, stall_bumpers=0x0001 | 0x0100 | (0b101 << 9) | (1 << 1))
    assert sip.left_stall and sip.right_stall
    assert sip.front_bumpers == 0b101 and sip.rear_bumpers == 1
    assert "left and right wheel stalled" in sip.fault()


@given(st.integers(-200_000, 200_000), st.lists(st.integers(-250, 250), max_size=60))
def test_xy_wraparound_unwraps_to_continuous(start: int, steps: list[int]) -> None:
    """A position walked in SIP-sized steps and sent as 15 bits unwraps to the true walk."""
    true, raw_prev = start, start & 0x7FFF
    total = 0
    for step in steps:
        true += step
        sip = Sip(False, true, -true, 0, 0, 0, 120)
        back = parse_sip(encode_sip(sip)[3:-2])
        total += xy_delta(raw_prev, back.x)
        raw_prev = back.x
        assert back.y == (-true) & 0x7FFF
    assert total == sum(steps)


def test_wrap_across_the_15_bit_edge() -> None:
    assert xy_delta(0x7FF0, 0x0010) == 0x20
    assert xy_delta(0x0010, 0x7FF0) == -0x20


@given(st.integers(-2048, 4095))
def test_heading_round_trip(th: int) -> None:
    sip = parse_sip(encode_sip(Sip(False, 0, 0, th, 0, 0, 120))[3:-2])
    assert -math.pi <= sip.heading < math.pi
    assert math.isclose(math.cos(sip.heading), math.cos(th * 2 * math.pi / 4096), abs_tol=1e-9)


def test_parser_skips_junk_and_splits_back_to_back_packets() -> None:
    parser = PacketParser()
    stream = b"WMS2\r\xfa\x00junk" + command(Command.STOP) + command(Command.VEL, 5)
    for i in range(0, len(stream), 3):  # arrives in dribbles
        parser.feed(stream[i : i + 3])
    assert parser.next() == b"\x1d"
    assert parse_command(parser.next()).arg == 5
    assert parser.next() is None and not parser.partial


def test_parser_bad_checksum_raises_then_resyncs() -> None:
    bad = bytearray(command(Command.VEL, 200))
    bad[-1] ^= 0xFF
    parser = PacketParser()
    parser.feed(bytes(bad) + command(Command.STOP))
    with pytest.raises(PacketError, match="bad checksum"):
        parser.next()
    assert parser.next() == b"\x1d"


def test_parser_truncated_packet_is_an_error_after_silence() -> None:
    parser = PacketParser()
    parser.feed(command(Command.VEL, 200)[:5])
    assert parser.next() is None and parser.partial
    with pytest.raises(PacketError, match="truncated"):
        parser.expire_partial()
    assert not parser.partial
    parser.feed(command(Command.STOP))
    assert parser.next() == b"\x1d"


def test_parser_truncated_packet_followed_by_a_good_one_recovers_it() -> None:
    parser = PacketParser()
    parser.feed(command(Command.VEL, 200)[:5] + command(Command.STOP) + command(Command.STOP))
    seen, errors = [], 0
    for _ in range(10):
        try:
            data = parser.next()
        except PacketError:
            errors += 1
            continue
        if data is None:
            break
        seen.append(data)
    assert errors >= 1 and b"\x1d" in seen


def test_bad_byte_count_is_an_error() -> None:
    parser = PacketParser()
    parser.feed(b"\xfa\xfb\x01\x00")
    with pytest.raises(PacketError, match="byte count"):
        parser.next()


def test_frame_limits() -> None:
    with pytest.raises(ValueError):
        frame(b"")
    with pytest.raises(ValueError):
        command(Command.TTY2, bytes(200))
    with pytest.raises(ValueError):
        command(Command.VEL, 70000)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(max_size=64), max_size=12))
def test_fuzz_parser_never_crashes_or_hangs(chunks: list[bytes]) -> None:
    parser = PacketParser()
    for chunk in chunks:
        parser.feed(chunk)
        for _ in range(200):  # every call consumes bytes or returns None: bounded
            try:
                data = parser.next()
            except PacketError:
                continue
            if data is None:
                break
            assert data  # a packet has at least its type byte
            for decode in (parse_sip, parse_command, parse_sync2):
                with contextlib.suppress(PacketError):
                    decode(data)
        else:
            pytest.fail("parser did not settle")
    for _ in range(100):  # after silence: expire, then take what the rest holds
        if not parser.partial:
            break
        try:
            parser.expire_partial()
            while parser.next() is not None:
                pass
        except PacketError:
            pass
    assert not parser.partial


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=40), st.integers(0, 255), st.binary(max_size=40))
def test_fuzz_a_valid_packet_survives_junk_in_front(junk: bytes, cmd: int, payload: bytes) -> None:
    packet = frame(bytes([cmd]) + payload)
    parser = PacketParser()
    parser.feed(junk + packet)
    found = []
    for _ in range(200):
        try:
            data = parser.next()
        except PacketError:
            continue
        if data is None:
            break
        found.append(data)
    # junk may itself hold a header that swallows the packet; otherwise it must come out intact
    if b"\xfa" not in junk:
        assert found == [bytes([cmd]) + payload]


def test_codec_errors_carry_what_the_driver_names() -> None:
    """A codec error has no device name, but what was done, what was wrong and the remedy:
    the driver makes its ``ProtocolError`` from them, so the user's line stays complete."""
    bad = bytearray(command(Command.VEL, 200))
    bad[-1] ^= 0xFF
    parser = PacketParser()
    parser.feed(bytes(bad))
    with pytest.raises(PacketError) as caught:
        parser.next()
    error = caught.value
    assert error.doing == "read a packet" and error.seen.startswith("bad checksum 0x")
    assert error.remedy.startswith("check the baud rate") and "\n" not in str(error)


def test_the_wire_codecs_import_nothing_of_twin() -> None:
    code = (
        "import sys, hardware.arcos_codec, hardware.vcc4_codec; "
        "print(sorted(m for m in sys.modules if m == 'twin' or m.startswith('twin.')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
