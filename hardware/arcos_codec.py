"""ARCOS wire codec: packets, checksums, command arguments and SIPs, with no I/O at all.

Both the driver (``hardware.arcos``) and the emulator (``twin.serial_twins.arcos``) build and
parse bytes here, so the two cannot drift apart; the golden tests pin it to the worked examples
of specs/protocols.md (sections B2, B3, B6, B8, A10).

A packet is ``FA FB N data... CHK_hi CHK_lo``: N counts the data bytes plus the two checksum
bytes; ``data[0]`` is the command number (client to robot) or the packet type (robot to client).
Integers in the data are little-endian, the checksum big-endian. Wire units (PeopleBot SH
conversion factors, section B7): millimetres, mm/s, degrees, 4096ths of a turn, 0.1 V.

The codec imports nothing of ``twin``: bytes it cannot decode raise ``PacketError``, which the
driver turns into a ``ProtocolError`` naming the device (the emulator just counts them).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from enum import IntEnum

HEADER = b"\xfa\xfb"
ARGINT, ARGNINT, ARGSTR = 0x3B, 0x1B, 0x2B
MAX_CLIENT_COUNT = 204  # ARCOS ignores client packets with a larger byte count (section B2)
MAX_STRING = 199  # bytes of one string argument: keeps the byte count within 204 (ARIA: 199)
ANGLE_UNITS = 4096  # THPOS units per turn; the 0.001534 rad AngleConvFactor is 2*pi/4096
RAD_PER_UNIT = 2.0 * math.pi / ANGLE_UNITS
XY_BITS = 0x7FFF  # the SIP's x/y keep 15 bits and wrap (section B7)
VEL2_DIVISOR = 20  # mm/s per VEL2 wheel unit


class Command(IntEnum):
    """Client command numbers (section B5)."""

    PULSE = 0
    SYNC0 = 0
    OPEN = 1
    SYNC1 = 1
    CLOSE = 2
    SYNC2 = 2
    ENABLE = 4
    SETA = 5
    SETV = 6
    SETO = 7
    MOVE = 8
    ROTATE = 9
    SETRV = 10
    VEL = 11
    HEAD = 12
    DHEAD = 13
    CONFIG = 18
    RVEL = 21
    SETRA = 23
    SONAR = 28
    STOP = 29
    VEL2 = 32
    IOREQUEST = 40
    TTY2 = 42
    GETAUX = 43
    BUMPSTALL = 44
    HOSTBAUD = 50
    AUX1BAUD = 51
    ESTOP = 55


class PacketError(ValueError):
    """Bytes that are not a valid packet: what the codec was ``doing``, what was wrong
    (``seen``) and the ``remedy``; a driver adds its device's name to make the
    ``ProtocolError`` the user sees."""

    def __init__(self, doing: str, seen: str, remedy: str) -> None:
        self.doing, self.seen, self.remedy = doing, seen, remedy
        super().__init__(f"{doing}: {seen}; {remedy}")


SIP_STOPPED, SIP_MOVING = 0x32, 0x33
SERAUX = 0xB0  # robot to client: bytes from AUX1


def checksum(data: bytes) -> int:
    """Section B2: add the data bytes as big-endian 16-bit pairs modulo 2**16, then XOR a
    leftover odd byte into the low byte."""
    c = 0
    for i in range(0, len(data) - 1, 2):
        c = (c + (data[i] << 8 | data[i + 1])) & 0xFFFF
    if len(data) % 2:
        c ^= data[-1]
    return c


def frame(data: bytes) -> bytes:
    """Wrap ``data`` (type/command byte first) into a full packet with count and checksum."""
    if not 1 <= len(data) <= 253:
        raise ValueError(f"ARCOS packet data must be 1..253 bytes, got {len(data)}")
    return HEADER + bytes([len(data) + 2]) + data + checksum(data).to_bytes(2, "big")


def command(cmd: int, arg: int | bytes | None = None) -> bytes:
    """A client packet: ``cmd`` alone, with a signed int (3B/1B + |v| LE), or a string (2B,
    length, bytes; no NUL, like ARIA's comStrN)."""
    data = bytes([cmd])
    if isinstance(arg, bool):
        arg = int(arg)
    if isinstance(arg, int):
        if not -0xFFFF <= arg <= 0xFFFF:
            raise ValueError(f"ARCOS int argument {arg} does not fit 16 bits")
        data += bytes([ARGNINT if arg < 0 else ARGINT]) + abs(arg).to_bytes(2, "little")
    elif isinstance(arg, (bytes, bytearray)):
        if len(arg) > MAX_STRING:
            raise ValueError(f"ARCOS string argument of {len(arg)} bytes; at most {MAX_STRING}")
        data += bytes([ARGSTR, len(arg)]) + bytes(arg)
    return frame(data)


def vel2_argument(left_mm_s: float, right_mm_s: float) -> int:
    """VEL2's int: high byte left, low byte right, each signed 8-bit in 20 mm/s units, sent as a
    signed 16-bit number (so a backward left wheel makes it negative, section B5)."""
    left = max(-128, min(127, round(left_mm_s / VEL2_DIVISOR)))
    right = max(-128, min(127, round(right_mm_s / VEL2_DIVISOR)))
    value = ((left & 0xFF) << 8) | (right & 0xFF)
    return value - 0x10000 if value & 0x8000 else value


def vel2_wheels(arg: int) -> tuple[int, int]:
    """Inverse of ``vel2_argument``: (left, right) wheel speeds in mm/s."""
    value = arg & 0xFFFF
    left, right = value >> 8, value & 0xFF
    return (
        (left - 256 if left > 127 else left) * VEL2_DIVISOR,
        (right - 256 if right > 127 else right) * VEL2_DIVISOR,
    )


@dataclass(frozen=True)
class ClientCommand:
    """A decoded client packet: the command number and its argument (None, int or bytes)."""

    number: int
    arg: int | bytes | None


def parse_command(data: bytes) -> ClientCommand:
    """Decode a client packet's data (checksum already verified)."""
    number, rest = data[0], data[1:]
    if not rest:
        return ClientCommand(number, None)
    kind = rest[0]
    if kind in (ARGINT, ARGNINT):
        if len(rest) == 1:  # p2os sends SETO as '07 3B' with no value
            return ClientCommand(number, None)
        if len(rest) < 3:
            raise PacketError(
                f"decode command {number}",
                f"int argument of {len(rest) - 1} bytes",
                "send 3B/1B and two bytes",
            )
        value = int.from_bytes(rest[1:3], "little")
        return ClientCommand(number, -value if kind == ARGNINT else value)
    if kind == ARGSTR:
        if len(rest) < 2 or len(rest) - 2 < rest[1]:
            raise PacketError(
                f"decode command {number}",
                "string argument shorter than its length byte",
                "send 2B, length, then the bytes",
            )
        return ClientCommand(number, bytes(rest[2 : 2 + rest[1]]))
    raise PacketError(
        f"decode command {number}",
        f"argument type 0x{kind:02X}",
        "use 3B (int), 1B (negative int) or 2B (string)",
    )


# -- server information packets ------------------------------------------------------------------


@dataclass(frozen=True)
class SipExtension:
    """The ARCOS tail after DIGOUT (section B6); wire units."""

    battery_dv: int = 0  # 0.1 V
    charge_state: int = 0
    rot_vel: int = 0  # 0.1 deg/s
    fault_flags: int = 0
    lat_vel: int = 0  # mm/s
    temperature: int = -127  # deg C, -127 unknown
    state_of_charge: int = 0  # percent


@dataclass(frozen=True)
class Sip:
    """One standard SIP in wire units: raw x/y (15-bit, wrapping, mm on the PeopleBot SH),
    heading in 4096ths of a turn, wheel speeds mm/s, battery 0.1 V, flag words as sent."""

    moving: bool
    x: int
    y: int
    th: int
    left_vel: int
    right_vel: int
    battery_dv: int
    stall_bumpers: int = 0
    control: int = 0
    flags: int = 0
    compass: int = 0
    sonar: tuple[tuple[int, int], ...] = ()
    grip: int = 0
    anport: int = 0
    analog: int = 0
    digin: int = 0
    digout: int = 0
    extension: SipExtension | None = field(default=None)

    # -- decoded views (API units) --
    @property
    def heading(self) -> float:
        """Heading in radians, wrapped to [-pi, pi)."""
        th = (self.th & 0xFFF) * RAD_PER_UNIT
        return (th + math.pi) % (2.0 * math.pi) - math.pi

    @property
    def battery(self) -> float:
        """Battery voltage, V."""
        return self.battery_dv / 10.0

    @property
    def left_stall(self) -> bool:
        return bool(self.stall_bumpers & 0x0001)

    @property
    def right_stall(self) -> bool:
        return bool(self.stall_bumpers & 0x0100)

    @property
    def rear_bumpers(self) -> int:
        """Bits of the rear bumper bank (first bank in ARIA/p2os)."""
        return (self.stall_bumpers >> 1) & 0x7F

    @property
    def front_bumpers(self) -> int:
        return (self.stall_bumpers >> 9) & 0x7F

    @property
    def motors_enabled(self) -> bool:
        return bool(self.flags & 0x0001)

    @property
    def estop(self) -> bool:
        return bool(self.flags & 0x0020)

    def fault(self) -> str | None:
        """A short description of a stall or bumper hit, or None."""
        parts = []
        if self.left_stall or self.right_stall:
            side = " and ".join(
                s for s, on in (("left", self.left_stall), ("right", self.right_stall)) if on
            )
            parts.append(f"{side} wheel stalled")
        if self.front_bumpers:
            parts.append(f"front bumpers 0b{self.front_bumpers:07b}")
        if self.rear_bumpers:
            parts.append(f"rear bumpers 0b{self.rear_bumpers:07b}")
        return ", ".join(parts) or None


def encode_sip(sip: Sip) -> bytes:
    """The full packet for ``sip`` (x/y sent as their low 15 bits, THPOS as given)."""
    data = struct.pack(
        "<BHHhhhBHhHBB",
        SIP_MOVING if sip.moving else SIP_STOPPED,
        sip.x & XY_BITS,
        sip.y & XY_BITS,
        sip.th,
        sip.left_vel,
        sip.right_vel,
        sip.battery_dv,
        sip.stall_bumpers,
        sip.control,
        sip.flags,
        sip.compass,
        len(sip.sonar),
    )
    for disc, rng in sip.sonar:
        data += struct.pack("<BH", disc, rng)
    data += bytes([sip.grip, sip.anport, sip.analog, sip.digin, sip.digout])
    ext = sip.extension
    if ext is not None:
        data += struct.pack(
            "<HBhHhbB",
            ext.battery_dv,
            ext.charge_state,
            ext.rot_vel,
            ext.fault_flags,
            ext.lat_vel,
            ext.temperature,
            ext.state_of_charge,
        )
    return frame(data)


_SIP_HEAD = struct.Struct("<BHHhhhBHhHBB")
_SIP_EXT = struct.Struct("<HBhHhbB")


def is_sip(data: bytes) -> bool:
    """True for any standard SIP type 0x3X (ARIA and p2os accept them all, section B6)."""
    return bool(data) and data[0] & 0xF0 == 0x30


def parse_sip(data: bytes) -> Sip:
    """Decode a SIP's data (type byte first, checksum removed); extra bytes beyond the ARCOS
    tail are ignored, as newer firmware appends fields."""
    if len(data) < _SIP_HEAD.size:
        raise PacketError(
            "decode a SIP",
            f"{len(data)} data bytes, fewer than {_SIP_HEAD.size}",
            "check the robot runs ARCOS/AROS firmware",
        )
    (kind, x, y, th, lv, rv, batt, stall, control, flags, compass, count) = _SIP_HEAD.unpack_from(
        data
    )
    pos = _SIP_HEAD.size
    need = pos + 3 * count + 5
    if len(data) < need:
        raise PacketError(
            "decode a SIP",
            f"{len(data)} data bytes for {count} sonar readings, need {need}",
            "check the serial line for lost bytes",
        )
    sonar = tuple(struct.unpack_from("<BH", data, pos + 3 * i) for i in range(count))
    pos += 3 * count
    grip, anport, analog, digin, digout = data[pos : pos + 5]
    pos += 5
    ext = None
    if len(data) >= pos + _SIP_EXT.size:
        ext = SipExtension(*_SIP_EXT.unpack_from(data, pos))
    return Sip(
        kind == SIP_MOVING,
        x,
        y,
        th,
        lv,
        rv,
        batt,
        stall,
        control,
        flags,
        compass,
        sonar,
        grip,
        anport,
        analog,
        digin,
        digout,
        ext,
    )


def xy_delta(old: int, new: int) -> int:
    """The shortest signed change between two 15-bit wrapped x (or y) readings, in wire units.

    ARIA's rule (section B7) with its +/-0x1000 threshold generalised to half the range: any
    real per-SIP motion (under 250 mm at 10 Hz) is far inside it.
    """
    return ((new - old + 0x4000) & XY_BITS) - 0x4000


def parse_sync2(data: bytes) -> tuple[str, str, str]:
    """SYNC2's reply: type 2 then three NUL-terminated strings (name, class, subclass)."""
    if not data or data[0] != 2:
        raise PacketError(
            "read the SYNC2 reply",
            f"packet type {data[:1].hex()}",
            "restart the handshake at SYNC0",
        )
    parts = bytes(data[1:]).split(b"\x00")
    if len(parts) < 4:
        raise PacketError(
            "read the SYNC2 reply",
            f"{len(parts) - 1} strings, not 3",
            "check the robot runs ARCOS/AROS firmware",
        )
    name, kind, subclass = (p.decode("latin-1") for p in parts[:3])
    return name, kind, subclass


def sync2_reply(name: str, kind: str, subclass: str) -> bytes:
    return frame(b"\x02" + b"".join(s.encode("latin-1") + b"\x00" for s in (name, kind, subclass)))


# -- incremental parser ----------------------------------------------------------------------------


class PacketParser:
    """Splits a byte stream into packet data (type/command byte first, checksum removed).

    Junk before ``FA FB`` is skipped silently (ARIA writes ``WMS2\\r`` before syncing). A bad
    checksum or an impossible byte count raises ``PacketError`` once, after dropping only
    the header, so the next call resynchronises on the following ``FA FB``; a packet cut short
    stays pending until ``expire_partial`` declares it truncated.
    """

    def __init__(self, max_count: int = 255) -> None:
        self.max_count = max_count
        self._buf = bytearray()

    def feed(self, data: bytes) -> None:
        self._buf += data

    @property
    def partial(self) -> bool:
        """True while bytes of an unfinished packet (after a header) wait for the rest."""
        start = self._buf.find(HEADER)
        return start >= 0 or self._buf[-1:] == HEADER[:1]

    def next(self) -> bytes | None:
        """The next complete packet's data, or None if no complete packet is buffered."""
        buf = self._buf
        start = buf.find(HEADER)
        if start < 0:
            # keep a trailing FA: it may be the first half of a header
            del buf[: len(buf) - 1 if buf[-1:] == HEADER[:1] else len(buf)]
            return None
        del buf[:start]
        if len(buf) < 3:
            return None
        count = buf[2]
        if count < 3 or count > self.max_count:
            del buf[:2]
            raise PacketError(
                "read a packet",
                f"byte count {count} (allowed 3..{self.max_count})",
                "check the baud rate and the cable",
            )
        if len(buf) < 3 + count:
            return None
        data = bytes(buf[3 : 1 + count])
        got = int.from_bytes(buf[1 + count : 3 + count], "big")
        if got != checksum(data):
            del buf[:2]
            raise PacketError(
                "read a packet",
                f"bad checksum 0x{got:04X} for a "
                f"type 0x{data[0]:02X} packet (expected 0x{checksum(data):04X})",
                "check the baud rate and the cable; the packet was dropped",
            )
        del buf[: 3 + count]
        return data

    def expire_partial(self) -> None:
        """Drop a pending unfinished packet's header, raising ``PacketError`` if there was
        one; bytes after it stay buffered (call ``next`` again: a whole packet may follow)."""
        start = self._buf.find(HEADER)
        if start < 0:
            self._buf.clear()
            return
        seen = len(self._buf) - start
        del self._buf[: start + 2]
        raise PacketError(
            "read a packet",
            f"truncated packet ({seen} bytes, then silence)",
            "check the cable; the packet was dropped",
        )
