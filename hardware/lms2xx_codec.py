"""The SICK LMS2xx (LMS200/211/221/291) serial telegrams as pure functions: CRC, framing both
ways, an incremental parser that resynchronises on junk, requests, replies and scans.

No I/O here, so the driver (``hardware.lms2xx``) and the emulator
(``twin.serial_twins.lms2xx``) share one definition of every byte, and the golden tests pin it to
the worked examples of shared/specs/sick-lms2xx.md (section numbers below are that spec's).

A telegram is ``02 ADDR LEN_L LEN_H CMD DATA... [STATUS] CRC_L CRC_H`` (section 2): ADDR is
``00`` host -> scanner and ``80`` scanner -> host; LEN counts CMD .. STATUS; only the scanner's
telegrams carry the STATUS byte; the reply to a request is its code + 0x80. ``06`` (ACK) and
``15`` (NAK) are single bytes outside any telegram. Multi-byte fields are little-endian. Ranges
on the wire are whole cm, mm or 10 cm (the units code of the count word); this module converts
them to metres, with NaN for "no return" and invalid readings.

The codec imports nothing of ``twin``: bytes it cannot accept raise ``LmsCodecError`` (a
``TelegramError`` for framing in a byte stream, a ``ReplyError`` for a well-framed telegram whose
content does not decode); the driver turns them into typed device errors naming the device.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

STX = 0x02
LMS_ADDRESS = 0x00  # ADDR of host -> scanner telegrams: the scanner's address (default 0)
HOST_ADDRESS = 0x80  # ADDR of scanner -> host telegrams: 0x80 + the scanner's address
ACK, NAK = 0x06, 0x15
MAX_TELEGRAM = 812  # bytes of the largest telegram (a 401-value scan), section 2
MAX_LEN = MAX_TELEGRAM - 6  # the largest LEN field
STATUS_OK = 0x10  # the status byte of normal replies (section 7)
PASSWORD = b"SICK_LMS"  # installation-mode password (section 5.2)
MIRROR_HZ = 75.0  # mirror turns per second: a 1 deg scan takes one turn, 0.5 deg two (6.5)
MAX_VALUES = 721  # most values a count word announces (section 6.2)


class LmsCodecError(ValueError):
    """Bytes the LMS2xx protocol does not allow; the message says which and why."""


class TelegramError(LmsCodecError):
    """A byte stream held a broken telegram (bad length, CRC, cut off); the parser has dropped
    the bytes it names, so parsing continues with what follows."""


class CrcError(TelegramError):
    """A complete telegram whose CRC is wrong: the one case a scanner answers with NAK."""


class ReplyError(LmsCodecError):
    """A well-framed telegram whose content is not what its code promises."""


class Command(IntEnum):
    """Request codes, host -> scanner (section 5)."""

    RESET = 0x10
    MODE = 0x20
    SCAN = 0x30
    STATUS = 0x31
    ERRORS = 0x32
    COUNTERS = 0x35
    TYPE = 0x3A
    VARIANT = 0x3B
    READ_CONFIG = 0x74
    WRITE_CONFIG = 0x77


class Reply(IntEnum):
    """Telegram codes, scanner -> host: a request's reply is its code + 0x80, plus the
    unrequested ones (scans in a stream, power-on, reset confirmation, incorrect command)."""

    POWER_ON = 0x90
    RESET_CONFIRM = 0x91
    INCORRECT = 0x92
    MODE = 0xA0
    SCAN = 0xB0
    STATUS = 0xB1
    ERRORS = 0xB2
    COUNTERS = 0xB5
    SUBRANGE_SCAN = 0xB7
    TYPE = 0xBA
    VARIANT = 0xBB
    CONFIG = 0xF4
    CONFIG_WRITTEN = 0xF7


class Mode(IntEnum):
    """Operating modes of the ``20`` request (section 5.1) that this project uses."""

    INSTALLATION = 0x00
    CONTINUOUS = 0x24
    ON_REQUEST = 0x25
    SUBRANGE = 0x27
    PARTIAL = 0x2A
    BAUD_38400 = 0x40
    BAUD_19200 = 0x41
    BAUD_9600 = 0x42
    BAUD_500000 = 0x48


class Signal(IntEnum):
    """The single bytes the scanner sends before each reply (section 4)."""

    ACK = 0x06
    NAK = 0x15


class Units(IntEnum):
    """Range units: the count word's bits 14-15 and configuration byte 6 (sections 5.4, 6.2).
    ``2`` (10 cm) is used by Player and ARIA and called reserved by EPFL: decoded, never sent."""

    CM = 0
    MM = 1
    TEN_CM = 2

    @property
    def metres(self) -> float:
        """Metres per unit."""
        return {0: 0.01, 1: 0.001, 2: 0.1}[int(self)]


BAUD_MODES = {
    9600: Mode.BAUD_9600,
    19200: Mode.BAUD_19200,
    38400: Mode.BAUD_38400,
    500000: Mode.BAUD_500000,
}
BAUD_WORDS = {9600: 0x8067, 19200: 0x8033, 38400: 0x8019, 500000: 0x8001}
MODE_RESULTS = {0: "mode changed", 1: "refused: wrong password", 2: "refused: fault in the scanner"}
MODE_NAMES = {
    0x00: "installation",
    0x10: "diagnostic",
    0x24: "continuous output",
    0x25: "values on request",
    0x27: "continuous subrange",
    0x2A: "continuous partial scans",
}

# Measuring mode (configuration byte 5) -> bits of a value word that carry the range (6.3).
# Mode 05 is 15 bits as in [TBX] and ARIA ([RL] masks 14; the spec marks it): two drivers
# that read mode 05 agree on 15, and so does the mode table (32 m in mm needs 15 bits).
RANGE_BITS = {0x00: 13, 0x01: 13, 0x02: 13, 0x03: 14, 0x04: 14, 0x05: 15, 0x06: 15, 0x0F: 16}
REFLECTIVITY_MODE = 0x3F
# Special codes, as offsets below a width's all-ones value (1FFF .. 1FF7 in 13-bit modes;
# 3FFx / 7FFx in 14/15-bit modes, section 6.3). The 16-bit mode 0F has no flag bits; its
# codes are taken as FFFx by the same rule (no source says; the spec marks it).
NO_ECHO_OFFSET = 8  # 1FF7: measured value > maximum (no echo in range)
SPECIAL_NAMES = {
    0: "value not valid",
    1: "dazzling",
    2: "operation overflow",
    4: "signal-to-noise ratio too small",
    5: "error reading channel 1",
    8: "no echo in range",
}


# -- CRC and framing ----------------------------------------------------------------------------


def crc16(data: bytes) -> int:
    """Section 3: a 16-bit register shifted left (XOR 0x8005 when its top bit falls out), then
    XORed with the word (previous byte << 8 | this byte). Not a textbook CRC-16."""
    crc = prev = 0
    for b in data:
        crc = ((crc & 0x7FFF) << 1) ^ 0x8005 if crc & 0x8000 else (crc << 1) & 0xFFFF
        crc ^= b | (prev << 8)
        prev = b
    return crc


def frame(address: int, payload: bytes) -> bytes:
    """``02 ADDR LEN payload CRC``: ``payload`` is CMD .. STATUS, what LEN counts."""
    if not 1 <= len(payload) <= MAX_LEN:
        raise LmsCodecError(f"a telegram carries 1..{MAX_LEN} bytes, not {len(payload)}")
    head = bytes([STX, address]) + len(payload).to_bytes(2, "little") + payload
    return head + crc16(head).to_bytes(2, "little")


def request(body: bytes) -> bytes:
    """A host -> scanner telegram (no status byte): ``body`` is CMD + DATA."""
    return frame(LMS_ADDRESS, body)


def reply(body: bytes, status: int = STATUS_OK) -> bytes:
    """A scanner -> host telegram: ``body`` (CMD + DATA) and its status byte."""
    return frame(HOST_ADDRESS, body + bytes([status]))


@dataclass(frozen=True)
class Telegram:
    """One good telegram: its ADDR and everything LEN counts (CMD .. STATUS). Whether the last
    byte is a status byte follows from the direction: scanner telegrams (ADDR 0x80..) have one."""

    address: int
    payload: bytes

    @property
    def has_status(self) -> bool:
        return bool(self.address & 0x80)

    @property
    def command(self) -> int:
        return self.payload[0]

    @property
    def data(self) -> bytes:
        """The bytes between CMD and STATUS (or the CRC, for a host telegram)."""
        return self.payload[1:-1] if self.has_status else self.payload[1:]

    @property
    def status(self) -> int | None:
        return self.payload[-1] if self.has_status else None

    @property
    def size(self) -> int:
        """Bytes on the line, STX to CRC."""
        return len(self.payload) + 6

    def to_bytes(self) -> bytes:
        return frame(self.address, self.payload)


class TelegramParser:
    """Finds telegrams in a byte stream that may hold junk and broken telegrams (section 9).

    ``feed`` bytes in; ``next`` returns the next ``Telegram``, a ``Signal`` (a lone 06 / 15
    byte, when ``signals``), None until more bytes come, or raises ``TelegramError`` for a broken
    telegram. Bytes before an STX are junk (counted in ``junk``); an STX not followed by
    ``address`` is junk too. On a bad length or CRC only the leading STX is dropped and the search
    goes on from the next byte, so a good telegram that began inside a broken one is still found
    ([GBX], [BOT2]); with ``discard_bad`` (the scanner's side, section 11) a telegram with a bad
    CRC is dropped whole instead, since it was answered with one NAK.

    ``address`` is what the telegrams must carry: ``HOST_ADDRESS`` (0x80) for a host reading
    the scanner's replies (with status byte), ``LMS_ADDRESS`` for a scanner reading requests.
    """

    def __init__(
        self, address: int = HOST_ADDRESS, *, signals: bool = True, discard_bad: bool = False
    ) -> None:
        self.address, self.signals, self.discard_bad = address, signals, discard_bad
        self._min_len = 2 if address & 0x80 else 1  # CMD (+ STATUS)
        self._buf = bytearray()
        self.junk = 0  # bytes skipped that belonged to no telegram

    def feed(self, data: bytes) -> None:
        self._buf += data

    def clear(self) -> None:
        self._buf.clear()

    @property
    def partial(self) -> bytes:
        """The bytes of a telegram that has begun and is not complete (empty when none)."""
        return bytes(self._buf) if self._buf[:1] == bytes([STX]) else b""

    def _start(self) -> int:
        """Index of the first byte that can begin something (STX, or ACK/NAK), or -1."""
        starts = (STX, ACK, NAK) if self.signals else (STX,)
        found = [i for i in (self._buf.find(b) for b in starts) if i >= 0]
        return min(found, default=-1)

    def next(self) -> Telegram | Signal | None:
        buf = self._buf
        while True:
            start = self._start()
            if start < 0:
                self.junk += len(buf)
                buf.clear()
                return None
            if start:
                self.junk += start
                del buf[:start]
            if buf[0] != STX:
                signal = Signal(buf[0])
                del buf[0]
                return signal
            if len(buf) < 2:
                return None
            if buf[1] != self.address:  # a 02 inside junk or in a foreign telegram
                self.junk += 1
                del buf[0]
                continue
            if len(buf) < 4:
                return None
            length = buf[2] | buf[3] << 8
            if not self._min_len <= length <= MAX_LEN:
                header = describe(bytes(buf[:4]))
                del buf[0]
                raise TelegramError(
                    f"telegram length {length} outside {self._min_len}..{MAX_LEN} (header {header})"
                )
            total = length + 6
            if len(buf) < total:
                return None
            raw = bytes(buf[:total])
            sent, computed = raw[-2] | raw[-1] << 8, crc16(raw[:-2])
            if sent != computed:
                del buf[: total if self.discard_bad else 1]
                raise CrcError(
                    f"bad CRC {sent:04X} (computed {computed:04X}) on a {total}-byte telegram "
                    f"{describe(raw)}"
                )
            del buf[:total]
            return Telegram(raw[1], raw[4:-2])

    def expire_partial(self) -> None:
        """Give up on a telegram that stopped arriving: drop its STX (with ``discard_bad``, all
        of it) and raise ``TelegramError``; the rest is searched again on the next ``next``."""
        partial = self.partial
        if not partial:
            return
        del self._buf[: len(partial) if self.discard_bad else 1]
        raise TelegramError(f"truncated telegram {describe(partial)} (the line fell silent)")


def describe(data: bytes) -> str:
    """Bytes as spaced hex for error messages (``02 80 03``), cut after 16 bytes."""
    text = data[:16].hex(" ").upper()
    return text + (" ..." if len(data) > 16 else "")


# -- requests (host -> scanner) -----------------------------------------------------------------


def mode_request(mode: int, params: bytes = b"") -> bytes:
    """``20 mode params``: change the operating mode (section 5.1)."""
    return request(bytes([Command.MODE, mode]) + params)


def installation_mode_request(password: bytes = PASSWORD) -> bytes:
    """``20 00 SICK_LMS``: the mode in which ``77`` may write the configuration."""
    return mode_request(Mode.INSTALLATION, password)


def stream_request(on: bool) -> bytes:
    """``20 24`` (continuous B0 scans) or ``20 25`` (values on request: stops the stream)."""
    return mode_request(Mode.CONTINUOUS if on else Mode.ON_REQUEST)


def partial_stream_request() -> bytes:
    """``20 2A``: continuous partial (interlaced) scans."""
    return mode_request(Mode.PARTIAL)


def subrange_request(first: int, last: int) -> bytes:
    """``20 27 first last``: stream values ``first``..``last`` (1-based words) as B7."""
    return mode_request(Mode.SUBRANGE, first.to_bytes(2, "little") + last.to_bytes(2, "little"))


def baud_request(baud: int) -> bytes:
    """``20 4x``: switch to ``baud`` (9600, 19200, 38400, 500000); answered at the old rate."""
    if baud not in BAUD_MODES:
        raise LmsCodecError(f"{baud} baud is not an LMS2xx rate: use one of {sorted(BAUD_MODES)}")
    return mode_request(BAUD_MODES[baud])


def reset_request() -> bytes:
    return request(bytes([Command.RESET]))


def scan_request(subcode: int = 1) -> bytes:
    """``30 01``: one scan of all values (mode 25)."""
    return request(bytes([Command.SCAN, subcode]))


def status_request() -> bytes:
    return request(bytes([Command.STATUS]))


def errors_request() -> bytes:
    return request(bytes([Command.ERRORS]))


def counters_request() -> bytes:
    return request(bytes([Command.COUNTERS]))


def type_request() -> bytes:
    return request(bytes([Command.TYPE]))


def read_config_request() -> bytes:
    return request(bytes([Command.READ_CONFIG]))


def write_config_request(block: bytes) -> bytes:
    """``77 block``: write the configuration (installation mode only), the block read with
    ``74`` with the changed bytes; its length is the scanner's (32 or 34 bytes, section 5.4)."""
    return request(bytes([Command.WRITE_CONFIG]) + bytes(block))


# -- variants -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Variant:
    """Scanning angle (whole degrees) and angular resolution (1/100 degree), section 5.3."""

    angle: int
    resolution: int

    @property
    def count(self) -> int:
        """Values in one complete scan (181 for 180 deg at 1 deg)."""
        return self.angle * 100 // self.resolution + 1

    def angles_deg(self) -> np.ndarray:
        """Beam bearings in degrees, value 0 rightmost (-angle/2), counter-clockwise (6.4)."""
        return -self.angle / 2 + np.arange(self.count) * (self.resolution / 100.0)

    def angles_rad(self) -> np.ndarray:
        return np.radians(self.angles_deg())

    @property
    def mirror_turns(self) -> int:
        """Mirror turns one complete scan takes (1 deg: 1, 0.5 deg: 2, 0.25 deg: 4)."""
        return max(1, 100 // self.resolution)

    def __str__(self) -> str:
        return f"{self.angle} deg at {self.resolution / 100:g} deg ({self.count} values)"


VARIANTS = frozenset(
    {Variant(180, 100), Variant(180, 50), Variant(100, 100), Variant(100, 50), Variant(100, 25)}
)


def variant_request(variant: Variant) -> bytes:
    """``3B angle resolution``: switch the variant (stop the stream first, section 5.3)."""
    return request(
        bytes([Command.VARIANT])
        + variant.angle.to_bytes(2, "little")
        + variant.resolution.to_bytes(2, "little")
    )


def parse_variant(data: bytes) -> Variant:
    """The four bytes ``AA AA RR RR`` of a ``3B`` request or a ``BB`` reply."""
    if len(data) != 4:
        raise ReplyError(f"a variant is 4 bytes, got {len(data)}")
    return Variant(int.from_bytes(data[:2], "little"), int.from_bytes(data[2:], "little"))


# -- replies (scanner -> host) ------------------------------------------------------------------


def _expect(t: Telegram, code: int, length: int | None = None, at_least: int = 0) -> bytes:
    if t.command != code:
        raise ReplyError(f"expected a {code:02X} telegram, got {t.command:02X}")
    data = t.data
    if (length is not None and len(data) != length) or len(data) < at_least:
        want = f"{length}" if length is not None else f"at least {at_least}"
        raise ReplyError(f"a {code:02X} telegram carries {want} data bytes, this one {len(data)}")
    return data


def decode_mode_reply(t: Telegram) -> int:
    """``A0 rr``: 0 mode changed, 1 wrong password, 2 fault in the scanner (section 5.1)."""
    return _expect(t, Reply.MODE, 1)[0]


def encode_type(text: str) -> bytes:
    """The ``BA`` body: a 20-character ASCII type string (space-padded) and one ``00``."""
    raw = text.encode("ascii")
    if len(raw) > 20:
        raise LmsCodecError(f"a type string has at most 20 characters, not {len(raw)}")
    return bytes([Reply.TYPE]) + raw.ljust(20) + b"\x00"


def decode_type(t: Telegram) -> str:
    """``BA``: the type string (``LMS200;30106;V02.30``), NUL and padding stripped (5.6)."""
    data = _expect(t, Reply.TYPE, at_least=1)
    return data.split(b"\x00", 1)[0].decode("ascii", "replace").strip()


def decode_variant_reply(t: Telegram) -> tuple[bool, Variant]:
    """``BB ok variant``: whether the switch happened, and the variant now in force."""
    data = _expect(t, Reply.VARIANT, 5)
    return data[0] == 1, parse_variant(data[1:])


def decode_errors(t: Telegram) -> list[tuple[int, int]]:
    """``B2``: (type, code) pairs; none when the scanner has no errors (5.7)."""
    data = _expect(t, Reply.ERRORS)
    if len(data) % 2:
        raise ReplyError(f"a B2 telegram carries (type, code) pairs, not {len(data)} bytes")
    return [(data[i], data[i + 1]) for i in range(0, len(data), 2)]


def decode_counters(t: Telegram) -> tuple[int, int]:
    """``B5``: (operating hours, switch-ons); the wire counts hours / 2 (5.7)."""
    data = _expect(t, Reply.COUNTERS, 4)
    return 2 * int.from_bytes(data[:2], "little"), int.from_bytes(data[2:], "little")


def decode_power_on(t: Telegram) -> bytes:
    """``90``: the scanner is ready after a reset or power-up; its 21 bytes are undocumented."""
    return _expect(t, Reply.POWER_ON)


def decode_incorrect_command(t: Telegram) -> None:
    """``92``: the scanner refused the request (which requests provoke it is undocumented: an
    unknown code, a wrong length, the wrong mode); it carries nothing but its status."""
    _expect(t, Reply.INCORRECT, 0)


def decode_reset_confirmation(t: Telegram) -> None:
    """``91``: the scanner confirms a reset (``10``); ``90`` follows when it is ready."""
    _expect(t, Reply.RESET_CONFIRM, 0)


# -- configuration block (74 -> F4, 77 -> F7) ---------------------------------------------------


@dataclass(frozen=True)
class ConfigBlock:
    """The configuration block, as long as the scanner's (32 bytes on an LMS200, 34 on the
    others: take it from LEN, section 5.4). Byte 4: availability flags, 5: measuring mode,
    6: units."""

    raw: bytes

    AVAILABILITY = 4
    MEASURING_MODE = 5
    UNITS = 6
    REAL_TIME_INDICES = 0x02  # availability flag: a real-time index byte after the values

    def __post_init__(self) -> None:
        if len(self.raw) < 7:
            raise ReplyError(f"a configuration block has at least 7 bytes, not {len(self.raw)}")

    @property
    def availability(self) -> int:
        return self.raw[self.AVAILABILITY]

    @property
    def measuring_mode(self) -> int:
        return self.raw[self.MEASURING_MODE]

    @property
    def units(self) -> int:
        return self.raw[self.UNITS]

    def with_settings(
        self,
        *,
        units: int | None = None,
        measuring_mode: int | None = None,
        availability: int | None = None,
    ) -> ConfigBlock:
        """The same block with the given bytes changed (everything else as read)."""
        raw = bytearray(self.raw)
        changes = (
            (self.UNITS, units),
            (self.MEASURING_MODE, measuring_mode),
            (self.AVAILABILITY, availability),
        )
        for offset, value in changes:
            if value is not None:
                raw[offset] = value
        return replace(self, raw=bytes(raw))


def default_config(size: int = 32) -> ConfigBlock:
    """The block the emulator powers on with: mode 00, mm, multiple evaluation 2, restart 2
    (the bytes of section 10's examples), 32 bytes (LMS200) or 34 (multiple evaluation for
    dazzle 2 in bytes 32-33)."""
    if size not in (32, 34):
        raise LmsCodecError(f"a configuration block is 32 or 34 bytes, not {size}")
    raw = bytearray(size)
    raw[ConfigBlock.UNITS] = Units.MM
    raw[9] = raw[10] = 2
    if size == 34:
        raw[32] = 2
    return ConfigBlock(bytes(raw))


def decode_config(t: Telegram) -> ConfigBlock:
    """``F4 block``."""
    return ConfigBlock(_expect(t, Reply.CONFIG, at_least=7))


def decode_config_written(t: Telegram) -> tuple[bool, ConfigBlock]:
    """``F7 ok block``: whether the block was accepted, and the block now in force."""
    data = _expect(t, Reply.CONFIG_WRITTEN, at_least=8)
    return data[0] == 1, ConfigBlock(data[1:])


# -- status (31 -> B1) --------------------------------------------------------------------------

STATUS_SIZE = 152  # data bytes of B1 (section 5.5)


@dataclass(frozen=True)
class Status:
    """The fields of ``B1`` that the drivers agree on (section 5.5; offsets ``p`` count from the
    B1 byte, as [TBX] does). ``units``: 0 cm, 1 mm; ``baud``: None for an unknown baud word."""

    software_version: str
    operating_mode: int
    device_status: int
    serial: str
    variant_type: int
    measuring_mode: int
    variant: Variant
    baud_word: int
    permanent_baud: bool
    address: int
    units: int
    boot_version: str

    @property
    def baud(self) -> int | None:
        return {word: rate for rate, word in BAUD_WORDS.items()}.get(self.baud_word)


def _ascii(data: bytes) -> str:
    return data.split(b"\x00", 1)[0].decode("ascii", "replace").strip()


def decode_status(t: Telegram) -> Status:
    data = _expect(t, Reply.STATUS, STATUS_SIZE)

    def at(p: int, n: int = 1) -> bytes:  # payload offset p (p = 0 is the B1 byte)
        return data[p - 1 : p - 1 + n]

    def word(p: int) -> int:
        return int.from_bytes(at(p, 2), "little")

    return Status(
        software_version=_ascii(at(1, 7)),
        operating_mode=at(8)[0],
        device_status=at(9)[0],
        serial=_ascii(at(10, 8)),
        variant_type=at(18)[0],
        measuring_mode=at(102)[0],
        variant=Variant(word(107), word(109)),
        baud_word=word(116),
        permanent_baud=bool(at(119)[0]),
        address=at(120)[0],
        units=at(122)[0],
        boot_version=_ascii(at(124, 7)),
    )


def encode_status(status: Status) -> bytes:
    """The ``B1`` body (code + 152 data bytes) carrying ``status``; the fields no driver reads
    (pollution, calibration, counters, fields) are zero."""
    data = bytearray(STATUS_SIZE)

    def put(p: int, raw: bytes) -> None:
        data[p - 1 : p - 1 + len(raw)] = raw

    put(1, status.software_version.encode("ascii")[:7].ljust(7))
    put(8, bytes([status.operating_mode, status.device_status]))
    put(10, status.serial.encode("ascii")[:8].ljust(8))
    put(18, bytes([status.variant_type]))
    put(102, bytes([status.measuring_mode]))
    put(107, status.variant.angle.to_bytes(2, "little"))
    put(109, status.variant.resolution.to_bytes(2, "little"))
    put(116, status.baud_word.to_bytes(2, "little"))
    put(119, bytes([int(status.permanent_baud), status.address]))
    put(122, bytes([status.units]))
    put(124, status.boot_version.encode("ascii")[:7].ljust(7))
    return bytes([Reply.STATUS]) + bytes(data)


# -- scans (B0, B7) -----------------------------------------------------------------------------


def count_word(count: int, units: int, *, partial: bool = False, index: int = 0) -> int:
    """Bits 0-9 the number of values, 10 zero (no source uses it), 11-12 the partial-scan index
    k, 13 partial scan, 14-15 units (section 6.2)."""
    if not 0 <= count <= MAX_VALUES or not 0 <= index <= 3 or units not in (0, 1, 2):
        raise LmsCodecError(f"no count word for {count} values, index {index}, units {units}")
    return count | index << 11 | int(partial) << 13 | units << 14


def range_bits(measuring_mode: int) -> int:
    """Bits of a value word that carry the range in ``measuring_mode`` (section 6.3)."""
    if measuring_mode == REFLECTIVITY_MODE:
        raise LmsCodecError("measuring mode 3F sends reflectivity values, not ranges")
    try:
        return RANGE_BITS[measuring_mode]
    except KeyError:
        raise LmsCodecError(f"unknown measuring mode {measuring_mode:02X}") from None


def largest_value(measuring_mode: int) -> int:
    """The largest valid range value (8182 in the 13-bit modes: 8.182 m in mm)."""
    return (1 << range_bits(measuring_mode)) - 1 - NO_ECHO_OFFSET - 1


def max_range(units: int, measuring_mode: int) -> float:
    """The longest range (m) the scanner reports in these units and this measuring mode."""
    return largest_value(measuring_mode) * Units(units).metres


@dataclass(frozen=True)
class ScanData:
    """A decoded ``B0`` (or the scan inside a ``B7``): the value words as sent, the units, the
    partial-scan flag and index, the real-time index (None unless present) and the status."""

    words: np.ndarray  # uint16, value 0 rightmost
    units: Units
    partial: bool
    index: int
    rti: int | None
    status: int

    @property
    def count(self) -> int:
        return len(self.words)

    def ranges(self, measuring_mode: int) -> np.ndarray:
        """Metres, NaN for no echo and every other special code."""
        return ranges_from_words(self.words, self.units, measuring_mode)


def encode_scan(
    words: Sequence[int] | np.ndarray,
    units: int,
    *,
    partial: bool = False,
    index: int = 0,
    rti: int | None = None,
) -> bytes:
    """The ``B0`` body (code, count word, value words, optional real-time index byte)."""
    values = np.asarray(words, dtype="<u2")
    word = count_word(len(values), units, partial=partial, index=index)
    body = bytes([Reply.SCAN]) + word.to_bytes(2, "little") + values.tobytes()
    return body + (bytes([rti & 0xFF]) if rti is not None else b"")


def _decode_values(data: bytes, what: str) -> tuple[np.ndarray, Units, bool, int, int | None]:
    if len(data) < 2:
        raise ReplyError(f"a {what} without its count word")
    word = int.from_bytes(data[:2], "little")
    count, index, partial = word & 0x3FF, (word >> 11) & 0x3, bool(word & 0x2000)
    units = word >> 14
    if units == 3:
        raise ReplyError(f"{what}: unknown units code 3 in count word {word:04X}")
    extra = len(data) - 2 - 2 * count
    if extra not in (0, 1):  # the real-time index byte is there exactly when LEN says so
        raise ReplyError(
            f"{what}: count word {word:04X} announces {count} values, but LEN leaves room for "
            f"{(len(data) - 2) / 2:g}"
        )
    words = np.frombuffer(data[2 : 2 + 2 * count], dtype="<u2").astype(np.uint16)
    return words, Units(units), partial, index, (data[-1] if extra else None)


def decode_scan(t: Telegram) -> ScanData:
    """``B0``: the count word's bits 0-9 are the number of values (never a wider mask); an RTI
    byte is there when LEN has room for exactly one more byte than the values."""
    data = _expect(t, Reply.SCAN, at_least=2)
    words, units, partial, index, rti = _decode_values(data, "B0 scan")
    return ScanData(words, units, partial, index, rti, t.status or 0)


def encode_subrange_scan(
    first: int, last: int, words: Sequence[int] | np.ndarray, units: int, rti: int | None = None
) -> bytes:
    """The ``B7`` body: first and last (1-based) indices, then a count word and values as B0."""
    return (
        bytes([Reply.SUBRANGE_SCAN])
        + first.to_bytes(2, "little")
        + last.to_bytes(2, "little")
        + encode_scan(words, units, rti=rti)[1:]
    )


def decode_subrange_scan(t: Telegram) -> tuple[int, int, ScanData]:
    """``B7``: (first, last, the values) of a subrange stream (mode 27)."""
    data = _expect(t, Reply.SUBRANGE_SCAN, at_least=6)
    first, last = int.from_bytes(data[:2], "little"), int.from_bytes(data[2:4], "little")
    words, units, partial, index, rti = _decode_values(data[4:], "B7 subrange scan")
    return first, last, ScanData(words, units, partial, index, rti, t.status or 0)


def split_words(words: np.ndarray, measuring_mode: int) -> tuple[np.ndarray, np.ndarray]:
    """(range values, flag bits above them) of value words in ``measuring_mode``."""
    bits = range_bits(measuring_mode)
    words = np.asarray(words, dtype=np.uint32)
    return words & ((1 << bits) - 1), words >> bits


def ranges_from_words(words: np.ndarray, units: int, measuring_mode: int) -> np.ndarray:
    """Metres from value words: the flag bits dropped, special codes (no echo, dazzling,
    invalid, ...) as NaN, since the Scan type has one marker for "no usable range"."""
    values, _ = split_words(words, measuring_mode)
    ranges = values.astype(float) * Units(units).metres
    ranges[values > largest_value(measuring_mode)] = np.nan
    return ranges


def special_code(measuring_mode: int, offset: int) -> int:
    """A special code in this measuring mode's width: offset 8 is no echo (1FF7 / 3FF7 ...)."""
    return (1 << range_bits(measuring_mode)) - 1 - offset


def words_from_ranges(ranges_m: np.ndarray, units: int, measuring_mode: int) -> np.ndarray:
    """Value words for ranges in metres, rounded to the nearest unit: NaN, infinite and
    beyond-range readings become the no-echo code (1FF7 in 13-bit modes); negative ones
    (no range at all) the not-valid code (1FFF). Flag bits are zero."""
    ranges = np.asarray(ranges_m, dtype=float)
    no_echo = special_code(measuring_mode, NO_ECHO_OFFSET)
    top = largest_value(measuring_mode)
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = np.round(ranges / Units(units).metres)
        words = np.where(np.isfinite(scaled) & (scaled <= top), scaled, no_echo)
        words = np.where(ranges < 0, special_code(measuring_mode, 0), words)
    return words.astype(np.uint16)
