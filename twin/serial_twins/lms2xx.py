"""An emulated SICK LMS200 (or LMS291) laser scanner on a serial line, byte for byte.

``LMS2xxEmulator`` is the scanner's firmware as shared/specs/sick-lms2xx.md section 11 describes
it: power-on at 9600 baud in mode 25 with the 180 deg / 0.5 deg variant, mm and measuring mode
00; every good request answered with ``06`` at once and its reply ~10 ms later (50 ms for
``77``), a bad CRC with ``15``, an unknown or short request with ``92``; installation mode behind
the ``SICK_LMS`` password, ``77`` only there; baud changes answered at the old rate; continuous
``B0`` scans (mode 24), partial scans (2A) and subrange ``B7`` scans (27) at ``rate_hz``.

Its ranges come from a ``source``: ``source(angles_rad) -> ranges_m``, beam bearings in the
scanner's frame (counter-clockwise, value 0 rightmost), metres back with NaN for no return,
evaluated when a scan is emitted. ``square_room`` is the spec's test room; in the twin the
source is the MuJoCo laser's ``SimLaser.ranges_at`` (``twin serve-hardware --laser``, and a
config's ``[robot.laser] type = "lms2xx", port = "twin"``).

The line is modelled: every byte takes 10 bits at the current baud rate (``line_time``), so a
181-value scan takes 97 ms at 38400 baud and the stream runs at ~10 Hz, as on the robot. A scan
emitted while the previous one is still on the line is dropped whole (``scans_dropped``): the
scanner sends the newest complete scan. With ``enforce_baud`` the emulator ignores the host's
bytes and sends nothing while the host's port is set to another rate than the scanner's (read
from the pseudo-terminal's settings, or from a ``BaudMemoryLink``), so finding the rate works
as on a real line. Times are seconds of the server's ``Clock``.
"""

from __future__ import annotations

import contextlib
import math
import os
import termios
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hardware import lms2xx_codec as codec
from hardware.lms2xx_codec import Command, ConfigBlock, Mode, Reply, Telegram, Variant
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.serial_twins.bytedevice import DeviceLine, LineServer
from twin.serial_twins.memory import MemoryLink, MemoryTransport
from twin.serial_twins.pty import PtyLink

RangeSource = Callable[[np.ndarray], np.ndarray]

# model -> (type string, configuration block length), section 11.1
MODELS = {"LMS200": ("LMS200;30106;V02.30", 32), "LMS291": ("LMS291;S05;V02.10", 34)}
STREAMING = (Mode.CONTINUOUS, Mode.SUBRANGE, Mode.PARTIAL)
POWER_ON_VARIANT = Variant(180, 50)  # 361 values ([RL] restores it; [PLAYER]'s default)
CHUNK = 0.005  # s: how often bytes in flight are handed to the line (a UART's FIFO, roughly)


# -- range sources ------------------------------------------------------------------------------


def square_room(side: float = 4.0) -> RangeSource:
    """A square room ``side`` metres wide with the scanner in its centre, facing a wall: the
    spec's room (section 10's full scans: 2000 mm at -90, 0, +90 deg, 2828 mm at +-45 deg)."""
    half = side / 2.0

    def ranges(angles: np.ndarray) -> np.ndarray:
        return half / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))

    return ranges


# -- the host's line speed ------------------------------------------------------------------------


class BaudMemoryLink(MemoryLink):
    """A ``MemoryLink`` that knows the rate the host set its port to, as a pseudo-terminal does:
    the scanner's rate negotiation (section 1) in virtual time. ``transport()`` gives the driver
    a port opened at ``baudrate`` with ``set_baudrate``."""

    def __init__(self, clock: Clock = SYSTEM_CLOCK, name: str = "memory line") -> None:
        super().__init__(clock, name)
        self.host_baud: int | None = None  # None: no port open yet

    def transport(self, name: str, baudrate: int = 9600) -> BaudMemoryTransport:
        return BaudMemoryTransport(self, name, baudrate)


class BaudMemoryTransport(MemoryTransport):
    """The driver's end of a ``BaudMemoryLink``: a transport whose rate can be changed."""

    def __init__(self, link: BaudMemoryLink, name: str, baudrate: int) -> None:
        super().__init__(link, name)
        self.set_baudrate(baudrate)

    def set_baudrate(self, baudrate: int) -> None:
        link = self.link
        assert isinstance(link, BaudMemoryLink)
        with link._cond:
            self._check(f"set {link.name} to {baudrate} baud")
            link.host_baud = baudrate


_SPEEDS = {
    getattr(termios, f"B{rate}"): rate
    for rate in (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 500000)
    if hasattr(termios, f"B{rate}")
}


class _PtySpeed:
    """The host's rate on a ``PtyLink``, read from the terminal settings through a handle of
    our own on the pseudo-terminal (it follows the link to a new one after a hangup)."""

    def __init__(self, link: PtyLink) -> None:
        self.link = link
        self._fd = -1
        self._device = ""

    def __call__(self) -> int | None:
        for _ in range(2):
            if self._device != self.link.device or self._fd < 0:
                self.close()
                try:
                    self._fd = os.open(self.link.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
                except OSError:
                    return None
                self._device = self.link.device
            try:
                return _SPEEDS.get(termios.tcgetattr(self._fd)[5])
            except (OSError, termios.error):
                self.close()
        return None

    def close(self) -> None:
        if self._fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self._fd)
        self._fd, self._device = -1, ""


def host_line_speed(link: DeviceLine) -> Callable[[], int | None]:
    """What tells the emulator the host's rate on ``link`` (None: cannot tell)."""
    if isinstance(link, BaudMemoryLink):
        return lambda: link.host_baud
    if isinstance(link, PtyLink):
        return _PtySpeed(link)
    return lambda: None


# -- the scanner ----------------------------------------------------------------------------------


@dataclass
class LmsTiming:
    """Seconds (the server's clock): reply latency after the ACK, the longer one of the EEPROM
    write ``77``, the scan rate, how long after a reset the ``90`` comes, and how long a
    partial request may pause before it is dropped (emulator choices, section 11)."""

    latency: float = 0.010
    config_latency: float = 0.050
    rate_hz: float = 10.0
    power_on_delay: float = 0.2
    partial_timeout: float = 0.1
    line_time: bool = True  # every byte takes 10 bits at the current rate


@dataclass
class LmsFaults:
    """Faults for tests, each applied to the next ``*_count`` telegrams."""

    junk: bytes = b"\x00\xff\x02\x80\x05junk\x06"  # a stray STX and an ACK-like byte
    junk_count: int = 0  # replies and scans preceded by ``junk``
    nak_count: int = 0  # good requests answered with NAK (and dropped)
    corrupt_scans: int = 0  # scans sent with a broken CRC
    silent: bool = False  # answer nothing and send nothing (the scanner has no power)
    scan_status: int | None = None  # status byte of the scans (None: the normal 10)


@dataclass
class _Out:
    """Bytes waiting for the line: not before ``not_before``, then one byte per byte time."""

    not_before: float
    data: bytes
    kind: str  # "signal", "reply" or "scan"
    then: Callable[[], None] | None = None
    start: float | None = None
    byte_time: float = 0.0
    sent: int = 0


@dataclass
class _Records:
    telegrams: list[Telegram] = field(default_factory=list)  # good requests, in order
    bad_telegrams: int = 0  # requests dropped for a bad CRC, length or a silent pause
    replies: list[bytes] = field(default_factory=list)  # reply bodies (code + data) sent
    scans_sent: int = 0
    scans_dropped: int = 0


class LMS2xxEmulator:
    """The scanner's state machine (a ``ByteDevice`` with a clock tick). Thread-safe: the
    server's thread feeds and drains it, a test reads its state and sets ``faults``.

    ``model`` is ``LMS200`` (32-byte configuration block) or ``LMS291`` (34 bytes); ``baud``,
    ``mode`` and ``variant`` the state at power-on (a scanner left streaming at 38400 by an
    earlier client: ``baud=38400, mode=Mode.CONTINUOUS``). ``line_speed`` says what rate the host's
    port is at (the server sets it from the line); ``variant_stops_stream`` follows [TBX]'s note
    that a variant change ends the stream (the spec marks it)."""

    def __init__(
        self,
        source: RangeSource,
        *,
        model: str = "LMS200",
        baud: int = 9600,
        mode: int = Mode.ON_REQUEST,
        variant: Variant = POWER_ON_VARIANT,
        config: ConfigBlock | None = None,
        enforce_baud: bool = True,
        variant_stops_stream: bool = True,
        line_speed: Callable[[], int | None] | None = None,
        timing: LmsTiming | None = None,
        faults: LmsFaults | None = None,
    ) -> None:
        if model not in MODELS:
            raise ValueError(f"model must be one of {sorted(MODELS)}, got {model!r}")
        if baud not in codec.BAUD_MODES:
            raise ValueError(f"baud must be one of {sorted(codec.BAUD_MODES)}, got {baud}")
        self.source, self.model = source, model
        self.type_string, block_size = MODELS[model]
        self.baud, self.mode, self.variant = baud, int(mode), variant
        self.config = config or codec.default_config(block_size)
        self.enforce_baud, self.variant_stops_stream = enforce_baud, variant_stops_stream
        self.line_speed: Callable[[], int | None] = line_speed or (lambda: None)
        self.timing = timing or LmsTiming()
        self.faults = faults or LmsFaults()
        self.records = _Records()
        self.subrange = (1, variant.count)
        self.switch_ons = 10
        self._parser = codec.TelegramParser(codec.LMS_ADDRESS, signals=False, discard_bad=True)
        self._last_rx = -math.inf
        self._queue: deque[_Out] = deque()
        self._line_free = -math.inf
        self._next_scan: float | None = None
        self._partial_k = 0
        self._rti = 0
        self._lock = threading.RLock()
        if self.mode in STREAMING:
            self._next_scan = -math.inf  # streaming from the start: the first scan at once

    # -- what a test reads ----------------------------------------------------------------------
    @property
    def telegrams(self) -> list[Telegram]:
        return self.records.telegrams

    def commands(self) -> list[bytes]:
        """CMD + DATA of every good request, in order (``20 24`` as ``b"\\x20\\x24"``)."""
        return [t.payload for t in self.records.telegrams]

    @property
    def scans_sent(self) -> int:
        return self.records.scans_sent

    @property
    def scans_dropped(self) -> int:
        return self.records.scans_dropped

    def line_ok(self) -> bool:
        """False while the host's port runs at another rate (and ``enforce_baud``)."""
        if not self.enforce_baud:
            return True
        host = self.line_speed()
        return host is None or host == self.baud

    # -- ByteDevice -----------------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> None:
        with self._lock:
            if self.faults.silent or not data:
                return
            if not self.line_ok():
                return  # at the wrong rate the scanner hears noise, not telegrams
            self._last_rx = now
            self._parser.feed(data)
            self._pump(now)

    def _pump(self, now: float) -> None:
        while True:
            try:
                telegram = self._parser.next()
            except codec.CrcError:
                self.records.bad_telegrams += 1
                self._send(now, bytes([codec.NAK]), "signal")
                continue
            except codec.TelegramError:  # a bad length: line noise, not a telegram
                self.records.bad_telegrams += 1
                continue
            if not isinstance(telegram, Telegram):
                return
            self.records.telegrams.append(telegram)
            if self.faults.nak_count > 0:
                self.faults.nak_count -= 1
                self._send(now, bytes([codec.NAK]), "signal")
                continue
            self._send(now, bytes([codec.ACK]), "signal")
            self._execute(telegram, now)

    def tick(self, now: float) -> None:
        """Time-driven work: drop a request that stopped arriving, emit the next scan."""
        with self._lock:
            if self._parser.partial and now - self._last_rx > self.timing.partial_timeout:
                with contextlib.suppress(codec.TelegramError):
                    self._parser.expire_partial()
                self.records.bad_telegrams += 1
            if self.mode in STREAMING and self._next_scan is not None and now >= self._next_scan:
                period = 1.0 / self.timing.rate_hz
                self._emit_scan(now)
                self._next_scan = max(self._next_scan + period, now - period / 2)
                if self._next_scan <= now:
                    self._next_scan = now + period

    def transmit(self, now: float) -> bytes:
        """The bytes whose time on the line has come by ``now``: a telegram's bytes leave one
        byte time apart, at the rate in force when it started."""
        with self._lock:
            out = bytearray()
            ok = self.line_ok() and not self.faults.silent
            while self._queue:
                item = self._queue[0]
                if item.start is None:
                    if now < item.not_before:
                        break
                    item.start = max(item.not_before, self._line_free)
                    item.byte_time = 10.0 / self.baud if self.timing.line_time else 0.0
                due = len(item.data)
                if item.byte_time:
                    due = min(due, int((now - item.start) / item.byte_time + 1e-6))
                if ok:
                    out += item.data[item.sent : due]
                item.sent = max(item.sent, due)
                if item.sent < len(item.data):
                    break
                self._line_free = item.start + len(item.data) * item.byte_time
                self._queue.popleft()
                if item.kind == "scan" and ok:
                    self.records.scans_sent += 1
                if item.then is not None:
                    item.then()
            return bytes(out)

    def next_wake(self, now: float) -> float:
        """When something is next due (clock seconds; ``inf`` when idle)."""
        with self._lock:
            wake = math.inf
            if self.mode in STREAMING and self._next_scan is not None:
                wake = self._next_scan
            if self._queue:
                head = self._queue[0]
                if head.start is None:
                    wake = min(wake, max(head.not_before, self._line_free))
                else:
                    end = head.start + len(head.data) * head.byte_time
                    wake = min(wake, now + CHUNK, end)
            if self._parser.partial:
                wake = min(wake, self._last_rx + self.timing.partial_timeout)
            return wake

    def power_cycle(self, now: float) -> None:
        """Power lost and back: 9600 baud, mode 25, nothing in flight, ``90`` when ready. The
        variant and the configuration stay (they are in EEPROM)."""
        with self._lock:
            self._queue.clear()
            self._parser.clear()
            self.baud, self.mode, self._next_scan = 9600, Mode.ON_REQUEST, None
            self._line_free = -math.inf
            self.switch_ons += 1
            self._reply(now + self.timing.power_on_delay, self._power_on_body(), 0.0)

    # -- output ---------------------------------------------------------------------------------
    def _send(
        self, at: float, data: bytes, kind: str, then: Callable[[], None] | None = None
    ) -> None:
        if kind != "signal" and self.faults.junk_count > 0:
            self.faults.junk_count -= 1
            data = self.faults.junk + data
        self._queue.append(_Out(at, data, kind, then))

    def _reply(
        self,
        now: float,
        body: bytes,
        latency: float | None = None,
        then: Callable[[], None] | None = None,
    ) -> None:
        self.records.replies.append(body)
        delay = self.timing.latency if latency is None else latency
        self._send(now + delay, codec.reply(body), "reply", then)

    def _incorrect(self, now: float) -> None:
        self._reply(now, bytes([Reply.INCORRECT]))

    def _power_on_body(self) -> bytes:
        # the 21 bytes of 90 are undocumented (section 5.7): the type string's, as a choice
        return bytes([Reply.POWER_ON]) + codec.encode_type(self.type_string)[1:]

    def _scan_words(self, angles: np.ndarray) -> np.ndarray:
        block = self.config
        if block.measuring_mode == codec.REFLECTIVITY_MODE:
            return np.zeros(len(angles), dtype=np.uint16)  # no reflectivity model: all dark
        ranges = np.asarray(self.source(angles), dtype=float)
        if ranges.shape != angles.shape:
            raise ValueError(f"the range source returned shape {ranges.shape} for {angles.shape}")
        return codec.words_from_ranges(ranges, block.units, block.measuring_mode)

    def _next_rti(self) -> int | None:
        if not self.config.availability & ConfigBlock.REAL_TIME_INDICES:
            return None
        rti, self._rti = self._rti, (self._rti + 1) & 0xFF
        return rti

    def _scan_body(self) -> bytes:
        """The telegram body of the scan due now in the current mode, its ranges read now."""
        units = self.config.units
        if self.mode == Mode.PARTIAL:
            # interlaced: always 180 deg; k cycles 0, 2 (0.5 deg) or 0..3 (0.25 deg) or stays
            # 0 (1 deg); the order of k is not documented (the spec marks it)
            ks = {100: (0,), 50: (0, 2), 25: (0, 1, 2, 3)}[self.variant.resolution]
            k = ks[self._partial_k % len(ks)]
            self._partial_k += 1
            count = 181 if k == 0 else 180
            angles = np.radians(-90.0 + 0.25 * k + np.arange(count))
            words = self._scan_words(angles)
            return codec.encode_scan(words, units, partial=True, index=k, rti=self._next_rti())
        words = self._scan_words(self.variant.angles_rad())
        if self.mode == Mode.SUBRANGE:
            first, last = self.subrange
            return codec.encode_subrange_scan(
                first, last, words[first - 1 : last], units, self._next_rti()
            )
        return codec.encode_scan(words, units, rti=self._next_rti())

    def _emit_scan(self, now: float) -> None:
        if self.faults.silent or any(item.kind == "scan" for item in self._queue):
            self.records.scans_dropped += 1  # the line is still busy with the last one
            return
        body = self._scan_body()
        status = self.faults.scan_status if self.faults.scan_status is not None else 0x10
        data = codec.reply(body, status)
        if self.faults.corrupt_scans > 0:
            self.faults.corrupt_scans -= 1
            data = data[:-1] + bytes([data[-1] ^ 0x5A])
        self._send(now, data, "scan")

    # -- requests -------------------------------------------------------------------------------
    def _execute(self, t: Telegram, now: float) -> None:
        handler = _HANDLERS.get(t.command)
        if handler is None:
            self._incorrect(now)  # unknown code: ACK + 92 (emulator choice, section 11.8)
            return
        handler(self, t.data, now)

    def _cmd_mode(self, data: bytes, now: float) -> None:
        if not data:
            self._incorrect(now)
            return
        mode, params = data[0], data[1:]
        if mode == Mode.INSTALLATION:
            ok = params == codec.PASSWORD
            if ok:
                self._set_mode(Mode.INSTALLATION, now)
            self._reply(now, bytes([Reply.MODE, 0 if ok else 1]))
        elif mode in (Mode.CONTINUOUS, Mode.ON_REQUEST, Mode.PARTIAL):
            self._set_mode(mode, now)
            self._reply(now, bytes([Reply.MODE, 0]))
        elif mode == Mode.SUBRANGE:
            if len(params) < 4:
                self._incorrect(now)
                return
            first, last = (
                int.from_bytes(params[:2], "little"),
                int.from_bytes(params[2:4], "little"),
            )
            if not 1 <= first <= last <= self.variant.count:
                self._reply(now, bytes([Reply.MODE, 2]))
                return
            self.subrange = (first, last)
            self._set_mode(Mode.SUBRANGE, now)
            self._reply(now, bytes([Reply.MODE, 0]))
        elif mode in codec.BAUD_MODES.values():
            rate = next(r for r, m in codec.BAUD_MODES.items() if m == mode)

            def switch() -> None:  # once the reply has left at the old rate
                self.baud = rate

            self._reply(now, bytes([Reply.MODE, 0]), then=switch)
        else:
            self._incorrect(now)  # a mode this emulator does not offer

    def _set_mode(self, mode: int, now: float) -> None:
        was_streaming = self.mode in STREAMING
        self.mode = int(mode)
        if mode in STREAMING and not was_streaming:
            self._next_scan = now + 1.0 / self.timing.rate_hz
            self._partial_k = 0
        elif mode not in STREAMING:
            self._next_scan = None

    def _cmd_scan(self, data: bytes, now: float) -> None:
        if data != b"\x01":
            self._incorrect(now)
            return
        words = self._scan_words(self.variant.angles_rad())
        self._reply(now, codec.encode_scan(words, self.config.units, rti=self._next_rti()))

    def _cmd_status(self, data: bytes, now: float) -> None:
        block = self.config
        status = codec.Status(
            software_version=self.type_string.rsplit(";", 1)[-1],
            operating_mode=self.mode,
            device_status=0,
            serial="TWIN0001",
            variant_type=0,
            measuring_mode=block.measuring_mode,
            variant=self.variant,
            baud_word=codec.BAUD_WORDS[self.baud],
            permanent_baud=False,
            address=0,
            units=block.units,
            boot_version="V01.10",
        )
        self._reply(now, codec.encode_status(status))

    def _cmd_errors(self, data: bytes, now: float) -> None:
        self._reply(now, bytes([Reply.ERRORS]))

    def _cmd_counters(self, data: bytes, now: float) -> None:
        body = (100).to_bytes(2, "little") + self.switch_ons.to_bytes(2, "little")
        self._reply(now, bytes([Reply.COUNTERS]) + body)

    def _cmd_type(self, data: bytes, now: float) -> None:
        self._reply(now, codec.encode_type(self.type_string))

    def _cmd_variant(self, data: bytes, now: float) -> None:
        if len(data) != 4:
            self._incorrect(now)
            return
        wanted = codec.parse_variant(data)
        ok = wanted in codec.VARIANTS
        if ok:
            self.variant = wanted
            self.subrange = (1, wanted.count)
            if self.variant_stops_stream and self.mode in STREAMING:
                self._set_mode(Mode.ON_REQUEST, now)
        body = bytes([Reply.VARIANT, int(ok)]) + codec.variant_request(self.variant)[5:-2]
        self._reply(now, body)

    def _cmd_read_config(self, data: bytes, now: float) -> None:
        self._reply(now, bytes([Reply.CONFIG]) + self.config.raw)

    def _cmd_write_config(self, data: bytes, now: float) -> None:
        """Only in installation mode (otherwise ``92``, after ARIA's reaction). A shorter block
        overwrites that many leading bytes and bytes past the model's block are ignored (both
        emulator choices: Player writes 7 bytes, [TBX] 34 to any model)."""
        if self.mode != Mode.INSTALLATION or not data:
            self._incorrect(now)
            return
        old = self.config.raw
        raw = data[: len(old)] + old[len(data) :]
        mode = raw[ConfigBlock.MEASURING_MODE]
        ok = raw[ConfigBlock.UNITS] in (0, 1, 2) and (
            mode in codec.RANGE_BITS or mode == codec.REFLECTIVITY_MODE
        )
        if ok:
            self.config = ConfigBlock(raw)
        body = bytes([Reply.CONFIG_WRITTEN, int(ok)]) + self.config.raw
        self._reply(now, body, self.timing.config_latency)

    def _cmd_reset(self, data: bytes, now: float) -> None:
        self._set_mode(Mode.ON_REQUEST, now)

        def restarted() -> None:  # after 91 has left: back at 9600, 90 once ready
            self.baud = 9600
            self.switch_ons += 1
            self._reply(self._line_free + self.timing.power_on_delay, self._power_on_body(), 0.0)

        self._reply(now, bytes([Reply.RESET_CONFIRM]), then=restarted)


_Handler = Callable[[LMS2xxEmulator, bytes, float], None]
_HANDLERS: dict[int, _Handler] = {
    Command.RESET: LMS2xxEmulator._cmd_reset,
    Command.MODE: LMS2xxEmulator._cmd_mode,
    Command.SCAN: LMS2xxEmulator._cmd_scan,
    Command.STATUS: LMS2xxEmulator._cmd_status,
    Command.ERRORS: LMS2xxEmulator._cmd_errors,
    Command.COUNTERS: LMS2xxEmulator._cmd_counters,
    Command.TYPE: LMS2xxEmulator._cmd_type,
    Command.VARIANT: LMS2xxEmulator._cmd_variant,
    Command.READ_CONFIG: LMS2xxEmulator._cmd_read_config,
    Command.WRITE_CONFIG: LMS2xxEmulator._cmd_write_config,
}


# -- the line server ------------------------------------------------------------------------------


def serve_lms2xx(
    source: RangeSource,
    link: DeviceLine | None = None,
    *,
    clock: Clock = SYSTEM_CLOCK,
    **emulator_options: object,
) -> LineServer:
    """Start an emulated LMS2xx on ``link`` (a new pseudo-terminal if None) whose ranges come
    from ``source``; ``emulator_options`` go to ``LMS2xxEmulator``. Returns the running server
    (``.path`` for a pty, ``.link.transport(name)`` for a ``BaudMemoryLink``)."""
    emulator = LMS2xxEmulator(source, **emulator_options)  # type: ignore[arg-type]
    line = link if link is not None else PtyLink()
    speed = host_line_speed(line)  # the emulator honours the host's rate, as the real line does
    emulator.line_speed = speed
    close = speed.close if isinstance(speed, _PtySpeed) else None
    return LineServer(emulator, line, clock, name="lms2xx-line", on_stop=close)
