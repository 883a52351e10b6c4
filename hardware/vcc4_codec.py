"""The Canon VC-C4 wire format as pure functions: frames, numbers, angles, error codes.

No I/O here, so the driver (``hardware.vcc4``) and the emulator (``twin.serial_twins.vcc4``)
share one definition of every byte and the golden tests pin it to specs/protocols.md (A2-A9).

Host -> camera: ``FF D1 D2 00 cc params EF``; camera -> host: ``FE D1 D2 E1 E2 [status] EF``.
Numbers are fixed-width uppercase ASCII hex. Angles are counts of 0.1125 degrees around 0x8000,
pan positive to the RIGHT on the wire (the driver converts to the API's left-positive radians).

The codec imports nothing of ``twin``: a garbled frame is a ``FrameError`` and an answer's error
code an ``AnswerError``; the driver turns them into the typed device errors that name the
device, what was asked and the remedy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

CMD_HEADER = 0xFF
ANSWER_HEADER = 0xFE
END = 0xEF
DEGREES_PER_COUNT = 0.1125
ANGLE_CENTER = 0x8000
MIN_ANSWER = 6  # FE D1 D2 E1 E2 EF: an ACK or any error answer
MAX_STATUS = 32  # longest status payload we accept; the longest real one is 8 hex digits

# Error-flag bits of the answer's E1 E2 byte (A4).
FLAG_MODE = 0x80
FLAG_PARAMETER = 0x40
FLAG_COMMAND = 0x20
FLAG_BUSY = 0x10
FLAG_SYSTEM = 0x01

# Command codes (second byte of the two-byte code ``00 cc``), A5.
PAN_SPEED = 0x50
TILT_SPEED = 0x51
SPEED_REQUEST = 0x52
PAN_TILT_STOP = 0x53
HOME = 0x57
PEDESTAL_INIT = 0x58
PAN_TILT = 0x62
PAN_TILT_REQUEST = 0x63
RANGE_SET = 0x64
RANGE_REQUEST = 0x65
OPERATION_STATUS = 0x86
PRODUCT_NAME = 0x87
CONTROL_MODE = 0x90
POWER = 0xA0
ZOOM_MOVE = 0xA2
ZOOM = 0xB3
ZOOM_REQUEST = 0xB4

# Speeds in counts/s ("PPS", 0.1125 deg/s each), A3/A6.
PAN_SPEED_MIN, PAN_SPEED_MAX = 0x008, 0x320
TILT_SPEED_MIN, TILT_SPEED_MAX = 0x008, 0x26E
# Movable ranges in counts around 0 (A6, normal mount).
PAN_RANGE = (-889, 889)
TILT_RANGE_MAX = (-267, 800)
TILT_RANGE_DEFAULT = (-267, 267)

# Operation status bits (``00 86``, 3 hex digits; ``00 86 30``, 5 hex digits), A5.
STATUS_TILTING = 1 << 11
STATUS_PANNING = 1 << 9
STATUS_ZOOMING = 1 << 7
STATUS_POWER_OFF = 1 << 5
STATUS_NOT_INITIALISED = 1 << 4
STATUS_LOCAL_MODE = 1 << 18


# -- numbers and angles -------------------------------------------------------------------------


def hex_digits(value: int, width: int) -> bytes:
    """``value`` as ``width`` uppercase ASCII hex digits; ValueError if it does not fit."""
    if not 0 <= value < 16**width:
        raise ValueError(f"{value} does not fit in {width} hex digits")
    return b"%0*X" % (width, value)


def parse_hex(digits: bytes) -> int:
    """Uppercase ASCII hex digits -> int; ValueError on anything else (lowercase included)."""
    if not digits or any(b not in b"0123456789ABCDEF" for b in digits):
        raise ValueError(f"not uppercase hex digits: {digits!r}")
    return int(digits, 16)


def degrees_to_count(degrees: float) -> int:
    """Angle in degrees -> counts of 0.1125 degrees, ARIA's rounding ``floor(x + 0.49)``.

    The spec (A3) lists four rules in the wild; this one reproduces the manual's own examples
    (-30 deg -> -267 -> ``7EF5``)."""
    return math.floor(degrees / DEGREES_PER_COUNT + 0.49)


def count_to_degrees(count: int) -> float:
    return count * DEGREES_PER_COUNT


def angle_digits(count: int) -> bytes:
    """Counts around 0 -> the four hex digits of ``0x8000 + count``."""
    return hex_digits(ANGLE_CENTER + count, 4)


def parse_angle(digits: bytes) -> int:
    """Four hex digits -> counts around 0 (``0x8320`` -> 800)."""
    if len(digits) != 4:
        raise ValueError(f"an angle is 4 hex digits, got {digits!r}")
    return parse_hex(digits) - ANGLE_CENTER


# -- frames -------------------------------------------------------------------------------------


def device_bytes(device: int) -> bytes:
    """Device number 0..9 -> ``30 3n`` (0 after power-on; 1..9 in a cascade)."""
    if not 0 <= device <= 9:
        raise ValueError(f"device number {device} outside 0..9")
    return b"0" + bytes([0x30 + device])


def command_frame(code: int, params: bytes = b"", device: int = 0) -> bytes:
    """``FF D1 D2 00 cc params EF``."""
    return bytes([CMD_HEADER]) + device_bytes(device) + bytes([0x00, code]) + params + bytes([END])


@dataclass(frozen=True)
class Command:
    """A host -> camera frame as the camera sees it."""

    device: int
    code: int
    params: bytes


def parse_command(frame: bytes) -> Command | None:
    """A complete command frame -> ``Command``; None when it is not one (wrong header, end
    mark, device bytes or code prefix), which a camera would ignore."""
    if len(frame) < 6 or frame[0] != CMD_HEADER or frame[-1] != END:
        return None
    if frame[1] != 0x30 or not 0x30 <= frame[2] <= 0x39 or frame[3] != 0x00:
        return None
    return Command(frame[2] - 0x30, frame[4], bytes(frame[5:-1]))


def answer_frame(flags: int = 0, status: bytes = b"", device: int = 0) -> bytes:
    """``FE D1 D2 E1 E2 [status] EF``: the error-flag byte as two hex digits, then status."""
    return (
        bytes([ANSWER_HEADER]) + device_bytes(device) + hex_digits(flags, 2) + status + bytes([END])
    )


@dataclass(frozen=True)
class Answer:
    """A camera -> host frame: device number, error-flag byte, status payload (ASCII)."""

    device: int
    flags: int
    status: bytes


# The commands, named after the manual. Angles in counts, speeds in counts/s.
def power(on: bool) -> bytes:
    return command_frame(POWER, b"1" if on else b"0")


def host_control(host: bool = True) -> bytes:
    return command_frame(CONTROL_MODE, b"0" if host else b"1")


def pedestal_init(return_home: bool = True) -> bytes:
    """Initialize 1 (calibrate, then home) or 2 (calibrate, then back where it was)."""
    return command_frame(PEDESTAL_INIT, b"0" if return_home else b"1")


def pan_speed(pps: int) -> bytes:
    return command_frame(PAN_SPEED, hex_digits(pps, 3))


def tilt_speed(pps: int) -> bytes:
    return command_frame(TILT_SPEED, hex_digits(pps, 3))


def pan_tilt(pan: int, tilt: int) -> bytes:
    """Absolute move, pan positive right, counts around 0."""
    return command_frame(PAN_TILT, angle_digits(pan) + angle_digits(tilt))


def pan_tilt_request() -> bytes:
    return command_frame(PAN_TILT_REQUEST)


def pan_tilt_stop() -> bytes:
    return command_frame(PAN_TILT_STOP, b"0")


def tilt_range(low: int, high: int) -> bytes:
    return command_frame(RANGE_SET, b"1" + angle_digits(low) + angle_digits(high))


def pan_range(low: int, high: int) -> bytes:
    return command_frame(RANGE_SET, b"0" + angle_digits(low) + angle_digits(high))


def zoom(position: int) -> bytes:
    """Zoom position 2 (absolute, 0 = wide end)."""
    return command_frame(ZOOM, hex_digits(position, 4))


def zoom_request() -> bytes:
    return command_frame(ZOOM_REQUEST, b"0")


def zoom_max_request() -> bytes:
    return command_frame(ZOOM_REQUEST, b"3")


def zoom_stop() -> bytes:
    return command_frame(ZOOM_MOVE, b"0")


def operation_status(extended: bool = False) -> bytes:
    return command_frame(OPERATION_STATUS, b"0" if extended else b"")


# -- answers ------------------------------------------------------------------------------------


def decode_pan_tilt(status: bytes) -> tuple[int, int]:
    """``pppp tttt`` -> (pan, tilt) counts around 0, pan positive right."""
    if len(status) != 8:
        raise ValueError(f"a pan/tilt answer carries 8 hex digits, got {status!r}")
    return parse_angle(status[:4]), parse_angle(status[4:])


class AnswerError(Enum):
    """What an answer's non-zero error-flag byte says (A4); the value is the manual's name."""

    MODE = "mode error"
    COMMAND = "command error"
    PARAMETER = "parameter error"
    SYSTEM = "system error"
    BUSY = "busy"
    UNKNOWN = "unknown answer code"


def answer_error(flags: int) -> AnswerError | None:
    """The error an answer's flag byte reports, or None for an ACK.

    Busy is set beside every other error bit, so the priority is the manual's: mode > command >
    parameter > busy; a system error (b0) outranks a plain busy."""
    if flags == 0:
        return None
    for bit, error in (
        (FLAG_MODE, AnswerError.MODE),
        (FLAG_COMMAND, AnswerError.COMMAND),
        (FLAG_PARAMETER, AnswerError.PARAMETER),
        (FLAG_SYSTEM, AnswerError.SYSTEM),
        (FLAG_BUSY, AnswerError.BUSY),
    ):
        if flags & bit:
            return error
    return AnswerError.UNKNOWN


class FrameError(ValueError):
    """Bytes that cannot be an answer frame; the message says which byte and why."""


# -- incremental answer parser ------------------------------------------------------------------

_HEX = frozenset(b"0123456789ABCDEF")


class AnswerParser:
    """Finds answer frames in a byte stream that may hold junk, cut-off or garbled frames.

    ``feed`` bytes in; ``next_answer`` returns the next complete ``Answer``, None while one is
    incomplete, or raises ``FrameError`` for a garbled frame (whose bytes are dropped, so
    calling again continues with what follows). Bytes before an ``FE`` are skipped as junk.
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        self._buf += data

    def clear(self) -> None:
        self._buf.clear()

    @property
    def partial(self) -> bytes:
        """The bytes of an unfinished frame (empty when none has started)."""
        start = self._buf.find(ANSWER_HEADER)
        return bytes(self._buf[start:]) if start >= 0 else b""

    def wanted(self, expected: int) -> int:
        """How many more bytes to ask a transport for, never past what could end a frame: an
        error answer is 6 bytes even when an ``expected``-byte status answer was asked for."""
        have = len(self.partial)
        if have < MIN_ANSWER:
            return MIN_ANSWER - have
        return max(1, expected - have)

    def next_answer(self) -> Answer | None:
        start = self._buf.find(ANSWER_HEADER)
        if start < 0:
            self._buf.clear()
            return None
        del self._buf[:start]
        buf = self._buf
        # FE D1 D2 E1 E2: device '0'..'9' pair, error code two hex digits
        for i, byte in enumerate(buf[1 : MIN_ANSWER - 1], start=1):
            ok = (byte == 0x30) if i == 1 else (0x30 <= byte <= 0x39) if i == 2 else byte in _HEX
            if not ok:
                self._drop(i)
                raise self._garbled(f"byte {i} is {byte:02X}")
        end = buf.find(END, MIN_ANSWER - 1)
        limit = MIN_ANSWER + MAX_STATUS
        body = buf[MIN_ANSWER - 1 : end if end >= 0 else min(len(buf), limit)]
        for j, byte in enumerate(body, start=MIN_ANSWER - 1):
            if not 0x20 <= byte <= 0x7E:  # status payloads are printable ASCII
                self._drop(j)
                raise self._garbled(f"status byte {j} is {byte:02X}")
        if end < 0:
            if len(buf) >= limit:
                self._drop(limit)
                raise self._garbled(f"no end mark within {limit} bytes")
            return None
        answer = Answer(buf[2] - 0x30, int(bytes(buf[3:5]), 16), bytes(buf[5:end]))
        del buf[: end + 1]
        return answer

    def _drop(self, upto: int) -> None:
        # Keep a header at ``upto`` (a new frame starting inside the bad one); drop the rest.
        del self._buf[: max(upto, 1)]

    def _garbled(self, what: str) -> FrameError:
        return FrameError(f"garbled answer frame ({what})")


def describe(data: bytes) -> str:
    """Bytes as spaced hex for error messages (``FE 30 30``), cut after 24 bytes."""
    text = data[:24].hex(" ").upper()
    return text + (" ..." if len(data) > 24 else "")
