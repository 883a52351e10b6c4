"""VC-C4 codec golden bytes (specs/protocols.md A9, A10), the answer parser (with a fuzz), the
emulator's state machine and error codes, and the driver against the emulator in-process.

Everything here runs in virtual time (``ManualClock``): the emulator keeps the real camera's
timings (10 ms latency, 9600 baud, 4 s power-on, 2.5 s initialisation) and the driver its
real timeouts, and a test of them takes milliseconds whatever else the machine is doing."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware import vcc4_codec as codec
from hardware.vcc4 import VCC4, ModeError, error_for
from twin.core.clock import ManualClock
from twin.core.devices import (
    ConnectionLostError,
    DeviceBusyError,
    DeviceFaultError,
    DeviceTimeoutError,
    OutOfRangeError,
    ProtocolError,
)
from twin.serial_twins.vcc4 import KinematicHead, VCC4Emulator, VCC4Faults, VCC4Timing

H = bytes.fromhex

# -- golden bytes, host -> camera (A9 1-11) -----------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "wire"),
    [
        (codec.power(True), "FF 30 30 00 A0 31 EF"),
        (codec.power(False), "FF 30 30 00 A0 30 EF"),
        (codec.host_control(), "FF 30 30 00 90 30 EF"),
        (
            codec.pan_tilt(codec.degrees_to_count(90), codec.degrees_to_count(-30)),
            "FF 30 30 00 62 38 33 32 30 37 45 46 35 EF",
        ),
        (
            codec.pan_tilt(codec.degrees_to_count(45), codec.degrees_to_count(10)),
            "FF 30 30 00 62 38 31 39 30 38 30 35 39 EF",
        ),
        (
            codec.pan_tilt(codec.degrees_to_count(-45.5), codec.degrees_to_count(20)),
            "FF 30 30 00 62 37 45 36 43 38 30 42 32 EF",
        ),
        (codec.pan_speed(codec.degrees_to_count(90)), "FF 30 30 00 50 33 32 30 EF"),
        (codec.tilt_speed(codec.degrees_to_count(69)), "FF 30 30 00 51 32 36 35 EF"),
        (codec.zoom(1000), "FF 30 30 00 B3 30 33 45 38 EF"),
        (
            codec.tilt_range(codec.degrees_to_count(-30), codec.degrees_to_count(88)),
            "FF 30 30 00 64 31 37 45 46 35 38 33 30 45 EF",
        ),
        (codec.pan_tilt_request(), "FF 30 30 00 63 EF"),
        (codec.zoom_request(), "FF 30 30 00 B4 30 EF"),
        (codec.pan_tilt_stop(), "FF 30 30 00 53 30 EF"),
        (codec.zoom_stop(), "FF 30 30 00 A2 30 EF"),
        (codec.pedestal_init(), "FF 30 30 00 58 30 EF"),
    ],
)
def test_command_frames_match_the_spec(frame: bytes, wire: str) -> None:
    assert frame == H(wire)
    # and the other way: the emulator's parser reads the golden frame back
    parsed = codec.parse_command(H(wire))
    assert parsed is not None and parsed.device == 0
    assert codec.command_frame(parsed.code, parsed.params) == H(wire)


def test_aux_tunnel_example_carries_the_camera_on_frame() -> None:
    # A10: Camera ON via AUX1 = TTY2 (0x2A), string arg 0x2B, length 7, the raw frame
    packet = H("FA FB 0C 2A 2B 07 FF 30 30 00 A0 31 EF 94 E9")
    assert packet[3:5] == bytes([42, 0x2B]) and packet[5] == len(codec.power(True))
    assert packet[6:13] == codec.power(True)


def test_angle_counts_and_rounding() -> None:
    assert codec.degrees_to_count(-30) == -267  # ARIA rounding, the manual's 7EF5
    assert codec.degrees_to_count(10) == 89 and codec.degrees_to_count(-45.5) == -404
    assert codec.angle_digits(800) == b"8320" and codec.parse_angle(b"7EF5") == -267
    assert codec.count_to_degrees(codec.parse_angle(b"8320")) == pytest.approx(90.0)
    with pytest.raises(ValueError):
        codec.parse_hex(b"7ef5")  # the camera writes uppercase only


# -- golden bytes, camera -> host ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("wire", "flags", "status"),
    [
        ("FE 30 30 30 30 EF", 0x00, b""),
        ("FE 30 30 31 30 EF", 0x10, b""),
        ("FE 30 30 33 30 EF", 0x30, b""),
        ("FE 30 30 35 30 EF", 0x50, b""),
        ("FE 30 30 39 30 EF", 0x90, b""),
        ("FE 30 30 30 30 38 33 32 30 37 45 46 35 EF", 0x00, b"83207EF5"),
        ("FE 30 30 30 30 30 33 45 38 EF", 0x00, b"03E8"),
    ],
)
def test_answer_frames_both_ways(wire: str, flags: int, status: bytes) -> None:
    assert codec.answer_frame(flags, status) == H(wire)
    parser = codec.AnswerParser()
    parser.feed(H(wire))
    assert parser.next_answer() == codec.Answer(0, flags, status)
    assert parser.next_answer() is None


def test_position_and_zoom_answers_decode() -> None:
    pan, tilt = codec.decode_pan_tilt(b"83207EF5")
    assert codec.count_to_degrees(pan) == pytest.approx(90.0)
    assert codec.count_to_degrees(tilt) == pytest.approx(-30.0375)
    assert codec.parse_hex(b"03E8") == 1000


@pytest.mark.parametrize(
    ("flags", "meaning", "kind", "says"),
    [
        (0x10, codec.AnswerError.BUSY, DeviceBusyError, "busy (answer code 10)"),
        (0x30, codec.AnswerError.COMMAND, ProtocolError, "command error (answer code 30)"),
        (0x50, codec.AnswerError.PARAMETER, OutOfRangeError, "parameter error (answer code 50)"),
        (0x90, codec.AnswerError.MODE, ModeError, "mode error (answer code 90)"),
        (0x11, codec.AnswerError.SYSTEM, DeviceFaultError, "system error (answer code 11)"),
        (0x02, codec.AnswerError.UNKNOWN, ProtocolError, "unknown answer code 02"),
    ],
)
def test_every_error_code_is_decoded_and_typed(
    flags: int, meaning: codec.AnswerError, kind: type, says: str
) -> None:
    assert codec.answer_error(flags) is meaning and codec.answer_error(0) is None
    error = error_for(flags, "VC-C4", "do it")  # the driver's translation
    assert type(error) is kind
    assert str(error).startswith(f"VC-C4: do it: {says}") and "\n" not in str(error)
    assert error_for(0, "VC-C4", "do it") is None


# -- the answer parser --------------------------------------------------------------------------


def _drain(parser: codec.AnswerParser) -> tuple[list[codec.Answer], int]:
    answers, errors = [], 0
    for _ in range(10_000):
        try:
            answer = parser.next_answer()
        except codec.FrameError:
            errors += 1
            continue
        if answer is None:
            return answers, errors
        answers.append(answer)
    raise AssertionError("the parser did not come to rest")


def test_parser_skips_junk_and_reports_garbled_frames() -> None:
    parser = codec.AnswerParser()
    parser.feed(b"\x00\x13junk\xef" + codec.answer_frame(0, b"03E8"))
    assert _drain(parser) == ([codec.Answer(0, 0, b"03E8")], 0)
    # a frame cut short by the next one: one error, then the next frame
    parser.feed(H("FE 30 30 30") + codec.answer_frame(0x10))
    assert _drain(parser) == ([codec.Answer(0, 0x10, b"")], 1)
    # a non-ASCII byte inside the status
    parser.feed(H("FE 30 30 30 30 38 B3 32 30 EF") + codec.answer_frame())
    assert _drain(parser) == ([codec.Answer(0, 0, b"")], 1)
    # incomplete: waits, and says how much more could finish a frame
    parser.feed(H("FE 30 30"))
    assert parser.next_answer() is None and parser.partial == H("FE 30 30")
    assert parser.wanted(14) == 3
    parser.feed(H("30 30 38"))
    assert parser.wanted(14) == 8


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.lists(st.binary(max_size=20), max_size=5))
def test_parser_fuzz_never_crashes_or_hangs(junk: bytes, chunks: list[bytes]) -> None:
    parser = codec.AnswerParser()
    for data in (junk, *chunks):
        parser.feed(data)
        answers, _ = _drain(parser)
        for answer in answers:
            assert 0 <= answer.device <= 9 and 0 <= answer.flags <= 0xFF
            assert all(0x20 <= b <= 0x7E for b in answer.status)
        assert parser.wanted(14) >= 1


@settings(max_examples=200, deadline=None)
@given(
    st.binary(max_size=50).filter(lambda b: 0xFE not in b),
    st.binary(max_size=8, min_size=0).map(lambda b: bytes(0x30 + x % 10 for x in b)),
)
def test_parser_finds_a_frame_after_any_junk(junk: bytes, status: bytes) -> None:
    parser = codec.AnswerParser()
    parser.feed(junk + codec.answer_frame(0, status))
    answers, _ = _drain(parser)
    assert answers == [codec.Answer(0, 0, status)]


# -- the emulator's state machine ---------------------------------------------------------------


def _emulator(**options: object) -> tuple[VCC4Emulator, ManualClock, KinematicHead]:
    clock = ManualClock(1000.0)
    head = KinematicHead(clock)
    timing = VCC4Timing(latency=0.010, baud=0, power_seconds=4.0, init_seconds=2.5)
    return VCC4Emulator(head, timing=timing, **options), clock, head  # type: ignore[arg-type]


def _ask(emulator: VCC4Emulator, clock: ManualClock, frame: bytes) -> bytes:
    emulator.receive(frame, clock.now())
    assert emulator.transmit(clock.now() + 0.005) == b""  # not before the ~10 ms latency
    clock.advance(0.011)
    return emulator.transmit(clock.now())


def test_emulator_walks_through_the_init_sequence() -> None:
    emu, clock, head = _emulator(camera_on=False)
    ack = codec.answer_frame()
    mode_error, busy = H("FE 30 30 39 30 EF"), H("FE 30 30 31 30 EF")
    assert _ask(emu, clock, codec.pan_tilt(100, 0)) == mode_error  # local mode
    assert _ask(emu, clock, codec.operation_status(True)) == codec.answer_frame(0, b"40030")
    assert _ask(emu, clock, codec.host_control()) == ack
    assert _ask(emu, clock, codec.pedestal_init()) == mode_error  # camera off
    assert _ask(emu, clock, codec.power(True)) == ack
    assert _ask(emu, clock, codec.pedestal_init()) == busy  # powering on
    clock.advance(4.0)
    assert _ask(emu, clock, codec.pan_tilt(100, 0)) == mode_error  # pedestal not initialised
    assert _ask(emu, clock, codec.pedestal_init()) == busy  # it runs Initialize 2 by itself
    clock.advance(2.5)
    assert _ask(emu, clock, codec.operation_status(True)) == codec.answer_frame(0, b"00000")
    assert _ask(emu, clock, codec.pedestal_init()) == ack
    assert _ask(emu, clock, codec.pan_speed(800)) == busy  # calibrating
    clock.advance(2.5)
    assert _ask(emu, clock, codec.pan_speed(400)) == ack
    assert _ask(emu, clock, codec.tilt_range(-267, 800)) == ack
    assert _ask(emu, clock, codec.operation_status(True)) == codec.answer_frame(0, b"00000")
    # a 45-degree pan at 400 counts/s (45 deg/s) is busy for about a second
    assert _ask(emu, clock, codec.pan_tilt(-400, 700)) == ack  # wire pan negative = left
    assert head.commands[-1][0] == pytest.approx(math.radians(45.0))
    assert head.commands[-1][2] == pytest.approx(math.radians(45.0))
    assert _ask(emu, clock, codec.pan_tilt(0, 0)) == busy
    assert _ask(emu, clock, codec.operation_status()) == codec.answer_frame(0, b"A00")
    clock.advance(10.0)
    assert _ask(emu, clock, codec.pan_tilt_request()) == codec.answer_frame(0, b"7E7082BC")
    assert _ask(emu, clock, codec.operation_status()) == codec.answer_frame(0, b"000")


@pytest.mark.parametrize(
    ("frame", "answer"),
    [
        (codec.pan_tilt(890, 0), "FE 30 30 35 30 EF"),  # beyond the pan range
        (codec.pan_tilt(0, 300), "FE 30 30 35 30 EF"),  # beyond the default +-30 tilt range
        (codec.command_frame(0x62, b"8000"), "FE 30 30 35 30 EF"),  # wrong parameter length
        (codec.command_frame(0x50, b"900"), "FE 30 30 35 30 EF"),  # speed too high
        (codec.command_frame(0x62, b"80008g00"), "FE 30 30 35 30 EF"),  # not hex
        (codec.command_frame(0x3F), "FE 30 30 33 30 EF"),  # unknown command
        (codec.command_frame(0x87), "FE 30 30 30 30 56 43 2D 43 34 EF"),  # product name
        (codec.zoom_max_request(), "FE 30 30 30 30 30 38 35 45 EF"),
    ],
)
def test_emulator_error_codes(frame: bytes, answer: str) -> None:
    emu, clock, _ = _emulator(host_mode=True, pedestal_ready=True)
    assert _ask(emu, clock, frame) == H(answer)


def test_emulator_is_silent_for_other_devices_and_drops_early_commands() -> None:
    emu, clock, _ = _emulator(host_mode=True, pedestal_ready=True)
    assert _ask(emu, clock, codec.command_frame(0x63, device=1)) == b""
    emu.receive(codec.pan_tilt_request() + codec.zoom_request(), clock.now())
    clock.advance(0.05)
    assert emu.transmit(clock.now()) == codec.answer_frame(0, b"80008000")  # zoom request dropped
    assert emu.received[-1].code == codec.PAN_TILT_REQUEST


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.binary(max_size=30),
            st.sampled_from(
                [
                    codec.pan_tilt(100, -50),
                    codec.pan_tilt_request(),
                    codec.host_control(),
                    codec.power(True),
                    codec.pedestal_init(),
                    codec.zoom(5),
                    codec.operation_status(True),
                ]
            ),
        ),
        max_size=12,
    )
)
def test_emulator_fuzz_answers_only_well_formed_frames(chunks: list[bytes]) -> None:
    emu, clock, _ = _emulator()
    parser = codec.AnswerParser()
    for data in chunks:
        emu.receive(data, clock.now())
        clock.advance(0.05)
        parser.feed(emu.transmit(clock.now()))
        assert _drain(parser)[1] == 0  # whatever came in, what goes out parses


def test_emulator_answers_after_its_latency_and_the_bytes_time_on_the_line() -> None:
    clock = ManualClock()
    emu = VCC4Emulator(KinematicHead(clock), host_mode=True, pedestal_ready=True)  # 9600 baud
    emu.receive(codec.pan_tilt_request(), clock.now())
    on_line = 10 * 14 / 9600  # the 14-byte position answer, 10 bits a byte
    assert emu.next_wake(0.0) == pytest.approx(0.010 + on_line)
    assert emu.transmit(0.010 + on_line - 1e-4) == b""
    assert emu.transmit(0.010 + on_line) == codec.answer_frame(0, b"80008000")


def test_emulator_faults() -> None:
    emu, clock, _ = _emulator(
        host_mode=True,
        pedestal_ready=True,
        faults=VCC4Faults(junk=b"xx", junk_count=1, truncate_count=1),
    )
    assert _ask(emu, clock, codec.pan_tilt_request()) == b"xx" + H(
        "FE 30 30 30 30 38 30 30 30 38 30 30"
    )
    emu.faults.garble_count = 1
    assert _ask(emu, clock, codec.pan_tilt_request())[3] == 0xB0
    emu.faults.silent = True
    assert _ask(emu, clock, codec.pan_tilt_request()) == b""


# -- the driver against the emulator, in-process ------------------------------------------------


class LoopTransport:
    """The driver's bytes straight into an emulator, on a ``ManualClock``: a read waits (in
    virtual time) for the emulator's next answer or its timeout. At most ``chunk`` bytes per
    read, like the AUX tunnel handing over 6 bytes and then the rest."""

    name = "loop"

    def __init__(self, emulator: VCC4Emulator, clock: ManualClock, chunk: int = 1000) -> None:
        self.emulator, self.clock, self.chunk = emulator, clock, chunk
        self.buffer = bytearray()
        self.written: list[bytes] = []
        self.closed = False

    def write(self, data: bytes) -> None:
        if self.closed:
            raise ConnectionLostError("loop", "write", "closed", "reconnect")
        self.written.append(bytes(data))
        self.emulator.receive(data, self.clock.now())

    def read(self, size: int, timeout: float) -> bytes:
        clock = self.clock
        end = clock.now() + timeout
        while True:
            self.buffer += self.emulator.transmit(clock.now())
            if len(self.buffer) >= min(size, self.chunk) or clock.now() >= end:
                out = bytes(self.buffer[: min(size, self.chunk)])
                del self.buffer[: len(out)]
                return out
            due = self.emulator.next_wake(0.0)
            clock.sleep((end if due is None else min(due, end)) - clock.now())

    def reset_input(self) -> None:
        self.buffer.clear()

    def close(self) -> None:
        self.closed = True


def _driver(
    chunk: int = 1000, **options: object
) -> tuple[VCC4, VCC4Emulator, LoopTransport, ManualClock]:
    """The driver with its default timeouts against the camera's real timings."""
    clock = ManualClock()
    emulator = VCC4Emulator(KinematicHead(clock), **options)  # type: ignore[arg-type]
    transport = LoopTransport(emulator, clock, chunk)
    return VCC4(transport, clock=clock), emulator, transport, clock


def test_driver_init_sends_the_spec_sequence_and_moves_left_positive() -> None:
    camera, emulator, transport, clock = _driver(camera_on=False)
    with camera:
        # it waited out the 4 s power-on and the 2.5 s initialisation, answered busy meanwhile
        assert 6.5 <= clock.now() < 7.0
        codes = [codec.parse_command(f).code for f in transport.written]  # type: ignore[union-attr]
        first = [c for i, c in enumerate(codes) if i == 0 or c != codes[i - 1]]
        assert first == [0x86, 0x90, 0xA0, 0x58, 0x50, 0x51, 0x64]
        assert transport.written[-1] == codec.tilt_range(-267, 800)
        start = clock.now()
        pan, tilt = camera.move_to(math.radians(30), math.radians(-10))
        assert clock.now() - start >= 30 / 90  # a 30-degree pan at the top 90 deg/s
        assert codec.pan_tilt(-267, -89) in transport.written  # wire pan is positive right
        assert (pan, tilt) == pytest.approx((math.radians(30), math.radians(-10)), abs=2e-3)
        assert emulator.head.position() == pytest.approx((pan, tilt), abs=2e-3)
        # a 20 deg/s cap goes to both axes
        start = clock.now()
        camera.move_to(0.0, 0.0, speed=math.radians(20))
        assert clock.now() - start >= 30 / 20
        assert codec.pan_speed(178) in transport.written
        assert codec.tilt_speed(178) in transport.written
        assert camera.zoom_to(1000) == 1000 and camera.zoom() == 1000
        with pytest.raises(OutOfRangeError):
            camera.zoom_to(5000)
        with pytest.raises(OutOfRangeError):
            camera.move_to(math.radians(120))
        with pytest.raises(OutOfRangeError):
            camera.move_to(0.1, speed=math.radians(0.5))
    # stopped on close; a transport handed in (the AUX tunnel) belongs to its owner
    assert not transport.closed and transport.written[-1] == codec.pan_tilt_stop()


def test_driver_waits_for_answers_at_9600_baud() -> None:
    camera, _, _, clock = _driver(host_mode=True, pedestal_ready=True)
    with camera:
        start = clock.now()
        camera.position()
        # 10 ms latency plus 14 bytes at 9600 baud: the driver read it as soon as it was there
        assert clock.now() - start == pytest.approx(0.010 + 10 * 14 / 9600)


def test_driver_reads_answers_handed_over_in_pieces() -> None:
    camera, _, _, _ = _driver(chunk=2, host_mode=True, pedestal_ready=True)
    with camera:
        camera.move_to(math.radians(-45), math.radians(20))
        assert camera.position() == pytest.approx((math.radians(-45), math.radians(20)), abs=2e-3)


def test_driver_recovers_from_one_bad_answer_and_types_persistent_ones() -> None:
    camera, emulator, _, clock = _driver(host_mode=True, pedestal_ready=True)
    with camera:
        for knob in ("junk_count", "truncate_count", "garble_count"):
            setattr(emulator.faults, knob, 1)
            assert camera.position() == pytest.approx((0.0, 0.0))
        emulator.faults.truncate_count = 5
        with pytest.raises(ProtocolError, match="truncated"):
            camera.position()
        emulator.faults.truncate_count = 0
        emulator.faults.garble_count = 5
        with pytest.raises(ProtocolError, match=r"read the position: garbled answer frame"):
            camera.position()
        emulator.faults.garble_count = 0
        emulator.faults.silent = True
        start = clock.now()
        with pytest.raises(DeviceTimeoutError, match=r"no answer within 0\.4 s"):
            camera.position()
        # the 0.4 s answer timeout, once more after one resend: no shorter, no longer
        assert clock.now() - start == pytest.approx(2 * 0.4)
        emulator.faults.silent = False
        assert camera.position() == pytest.approx((0.0, 0.0))


def test_driver_reinitialises_after_a_mode_error_and_bounds_busy_retries() -> None:
    camera, emulator, _, clock = _driver(host_mode=True, pedestal_ready=True)
    with camera:
        emulator.host_mode = False  # the camera was switched to local control
        camera.move_to(math.radians(10))
        assert emulator.host_mode
        emulator.pedestal_ready = False  # a power blip: the camera lost its calibration
        pan, _ = camera.move_to(math.radians(-10), speed=math.radians(30))
        assert emulator.pedestal_ready and pan == pytest.approx(math.radians(-10), abs=2e-3)
        assert emulator.pan_speed == 267  # the asked speed survives the re-initialisation
        emulator.timing.init_seconds = 5.0
        emulator.receive(codec.pedestal_init(), clock.now())  # someone recalibrates
        clock.advance(0.02)
        assert emulator.transmit(clock.now()) == codec.answer_frame()
        camera.busy_timeout = 0.2
        start = clock.now()
        with pytest.raises(DeviceBusyError):
            camera.stop()
        # retried busy answers for its 0.2 s (plus the last round trip), not the 5 s init
        assert 0.2 <= clock.now() - start < 0.3
