"""The SICK LMS200 (and its LMS2xx kin) over RS-232, as a ``twin.core.devices.Laser``.

``LMS2xx.open("/dev/ttyUSB0")`` returns an unconnected scanner; ``connect()`` (or ``with``) opens
the port at 9600 baud and configures the scanner the way shared/specs/sick-lms2xx.md section 13
recommends: ``20 25`` (stop a stream left running) at 9600 and, if nothing answers, at the other
rates (a scanner left at 38400 by an earlier client, section 1); ``20 40`` and the port switched
to 38400 only after the ``A0 00`` came (at the old rate); ``3A`` type, ``31`` status; ``3B`` if the
variant differs (180 deg at 1 deg: 181 beams, or 0.5 deg: 361); ``74``, and installation mode
plus ``77`` only if the units or the measuring mode differ (the block as long as the scanner's,
taken from LEN); then ``20 24``: continuous scans. One background thread decodes the ``B0``s;
``scan()`` returns the newest complete scan that began after the call, like ``Camera.grab``.

Every request waits for the ACK byte (``06``) and its reply (code + 0x80); a NAK (``15``) makes
it resend, at most ``MAX_NAK_RESENDS`` times; ``92`` (incorrect command) is a typed error. Reply
timeouts follow section 4 (1 s ordinary, 3 s mode changes, 15 s for the EEPROM write ``77``).
A line lost while streaming (a cable pulled, a pty replaced) is reopened and the scanner
configured again on the next call (``auto_reconnect``); a scan that does not come in time is a
``DeviceTimeoutError`` within ``scan``'s timeout, and the next call configures the scanner again
(it may have been power-cycled back to 9600). ``close()`` sends ``20 25`` and puts the scanner
back at 9600 (``20 42``), as every driver of the spec leaves it.

Scan timestamps are on the driver's ``clock``: the time the telegram's last byte arrived less
its time on the line (10 bits a byte), i.e. when the scanner finished the sweep and began to
send; a scan "began" one mirror turn per 1 deg of resolution (13.3 ms) before that. Angles are
radians counter-clockwise, value 0 rightmost (-pi/2 for 180 deg); ranges metres, NaN for no echo
and every other special code.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np
import serial

from hardware import lms2xx_codec as codec
from hardware.lms2xx_codec import (
    ConfigBlock,
    LmsCodecError,
    Reply,
    Signal,
    Status,
    Telegram,
    TelegramError,
    Units,
    Variant,
)
from hardware.transport import FrameReader, SerialTransport, Transport
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import (
    ConnectionLostError,
    DeviceError,
    DeviceFaultError,
    DeviceTimeoutError,
    Laser,
    LaserMount,
    ProtocolError,
    Scan,
)
from twin.core.errors import InputError

try:
    from termios import error as _TermiosError
except ImportError:  # no termios (Windows): pyserial raises SerialException there
    _TermiosError = OSError

NAME = "SICK LMS2xx"
PROBE_RATES = (9600, 38400, 19200, 500000)
MAX_NAK_RESENDS = 3  # resends of a telegram the scanner NAKed ([MRPT]: 3 sends, [RL]: until ACK)
INTER_BYTE_LIMIT = 0.1  # s of silence inside a telegram before it counts as cut off (ARIA)
UNITS = {"mm": Units.MM, "cm": Units.CM}
ORIGIN_MOUNT = LaserMount()
T = TypeVar("T")


class BaudTransport(Transport, Protocol):
    """A ``Transport`` whose line rate can change: the scanner is found at 9600 and moved up."""

    def set_baudrate(self, baudrate: int) -> None: ...


class SerialLine(SerialTransport):
    """A pyserial port (8N1, no flow control) that can change its rate while open."""

    def set_baudrate(self, baudrate: int) -> None:
        try:
            self._serial.baudrate = baudrate
        except (ValueError, OSError, serial.SerialException, _TermiosError) as exc:
            raise DeviceError(
                self.name,
                f"set {self.port} to {baudrate} baud",
                str(exc).splitlines()[0] if str(exc) else "refused",
                "use a rate the port supports (38400 works everywhere)",
            ) from None


@dataclass(frozen=True)
class LmsInfo:
    """What ``connect`` learnt: the type string, the status read before streaming began, the
    rate the scanner was found at, and the configuration block in force."""

    type: str
    status: Status
    found_baud: int
    config: ConfigBlock


@dataclass(frozen=True)
class _Received:
    scan: Scan
    began: float  # clock time the sweep began (estimated)
    status: int  # the telegram's status byte


class LMS2xx(Laser):
    """An LMS2xx on any ``BaudTransport`` (made by ``open_transport`` at connect, again at a
    reconnect). Timeouts, pauses and the reader thread run on ``clock`` (seconds).

    ``resolution`` (deg: 1, 0.5; 0.25 only with ``angle=100``) and ``angle`` (180 or 100 deg)
    choose the variant; ``units`` ("mm": 8.18 m at most in measuring mode 00, or "cm": 81.8 m)
    and ``measuring_mode`` (00 .. 06, 0F; 00 is the scanner's default) are written only if the
    scanner's differ; ``baud`` is the streaming rate (38400: 10 scans/s at 1 deg). ``mount``
    says where the scanner sits on the base.
    """

    def __init__(
        self,
        open_transport: Callable[[], BaudTransport],
        *,
        name: str = NAME,
        resolution: float = 1.0,
        angle: int = 180,
        units: str = "mm",
        measuring_mode: int = 0x00,
        baud: int = 38400,
        mount: LaserMount = ORIGIN_MOUNT,
        reply_timeout: float = 1.0,
        mode_timeout: float = 3.0,
        config_timeout: float = 15.0,
        probe_timeout: float = 1.0,
        probe_tries: int = 2,
        probe_rates: Sequence[int] = PROBE_RATES,
        retries: int = 2,
        switch_pause: float = 0.25,
        restore_baud: bool = True,
        auto_reconnect: bool = True,
        reconnect_timeout: float = 10.0,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        variant = Variant(int(angle), round(resolution * 100))
        if variant not in codec.VARIANTS:
            raise InputError(
                f"{name}: no variant {angle} deg at {resolution:g} deg; use 180 deg at 1 or "
                "0.5 deg, or 100 deg at 1, 0.5 or 0.25 deg"
            )
        if units not in UNITS:
            raise InputError(f"{name}: units {units!r}; use 'mm' or 'cm'")
        if measuring_mode not in codec.RANGE_BITS:
            raise InputError(
                f"{name}: measuring mode {measuring_mode:#04x} does not report ranges; use one of "
                + ", ".join(f"{m:02X}" for m in codec.RANGE_BITS)
            )
        if baud not in codec.BAUD_MODES:
            raise InputError(f"{name}: {baud} baud; use one of {sorted(codec.BAUD_MODES)}")
        self.name, self.clock = name, clock
        self.variant, self.units, self.measuring_mode = variant, UNITS[units], measuring_mode
        self.baud, self._mount = baud, mount
        self.reply_timeout, self.mode_timeout = reply_timeout, mode_timeout
        self.config_timeout, self.retries = config_timeout, retries
        self.probe_timeout, self.probe_tries = probe_timeout, probe_tries
        self.probe_rates = tuple(dict.fromkeys(probe_rates))
        self.switch_pause, self.restore_baud = switch_pause, restore_baud
        self.auto_reconnect, self.reconnect_timeout = auto_reconnect, reconnect_timeout
        self._open_transport = open_transport
        self._angles = variant.angles_rad()
        self._angles.setflags(write=False)
        self.max_range = codec.max_range(self.units, measuring_mode)
        self._transport: BaudTransport | None = None
        self._parser = codec.TelegramParser()
        self._rate = 9600  # the rate the port is at now
        self._cond = clock.condition()
        self._call_lock = threading.RLock()  # one scan / reconnect / close at a time
        self._stop_io = threading.Event()
        self._io: threading.Thread | None = None
        self._connected = False
        self._lost: DeviceError | None = None  # the line died: reopen before the next use
        self._stale = False  # scans stopped coming: configure the scanner again
        self._latest: _Received | None = None
        self.info: LmsInfo | None = None
        self.scans_received = 0
        self.protocol_errors = 0
        self.last_protocol_error: ProtocolError | None = None
        self.naks = 0
        self.stray_telegrams = 0
        self.reconnects = 0
        self.bytes_received = 0
        self.last_status: int | None = None  # status byte of the last scan returned

    @classmethod
    def open(cls, port: str, **options: object) -> LMS2xx:
        """A scanner on serial ``port`` (opened at 9600 8N1 on ``connect``); ``options`` as for
        the constructor. Nothing is opened until ``connect()``."""
        name = str(options.pop("name", NAME))
        clock: Clock = options.get("clock", SYSTEM_CLOCK)  # type: ignore[assignment]
        return cls(
            lambda: SerialLine(port, 9600, name, clock=clock),
            name=name,
            **options,  # type: ignore[arg-type]
        )

    # -- Laser ----------------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def mount(self) -> LaserMount:
        return self._mount

    @property
    def angles(self) -> np.ndarray:
        """The beams' bearings (rad), value 0 rightmost: the same array in every scan."""
        return self._angles

    def connect(self) -> None:
        with self._call_lock:
            if self._connected:
                return
            self._start_link()
            self._connected = True

    def close(self) -> None:
        """``20 25`` and back to 9600 (``20 42``), best effort, then release the port."""
        with self._call_lock:
            if self._transport is not None and self._lost is None:
                self._stop_reader()
                with contextlib.suppress(DeviceError):
                    self._request(
                        codec.stream_request(False), "stop the stream", self.mode_timeout, 0
                    )
                    if self.restore_baud and self._rate != 9600:
                        self._request(
                            codec.baud_request(9600), "return to 9600 baud", self.mode_timeout, 0
                        )
                        self._set_rate(9600)
            self._stop_link()
            self._connected = False

    def scan(self, timeout: float = 2.0) -> Scan:
        asked = "read a scan"
        with self._call_lock:
            self.require_connected(asked)
            self._recover(asked)
            try:
                return self._await_scan(timeout, asked)
            except ConnectionLostError:
                if not self.auto_reconnect:
                    raise
            # the line died while we waited: open it again and wait once more, a full timeout
            self._recover(asked)
            return self._await_scan(timeout, asked)

    # -- waiting for scans ----------------------------------------------------------------------
    def _recover(self, asked: str) -> None:
        """Reopen a lost line, or configure a scanner whose stream stopped, before using it."""
        if self._lost is None and not self._stale:
            return
        if not self.auto_reconnect:
            if self._lost is not None:
                raise self._lost
            return  # a stream that stopped, no recovery wanted: wait for scans as they come
        what = "the line was lost" if self._lost is not None else "the scans had stopped"
        try:
            self.reconnect()
        except DeviceError as exc:
            raise type(exc)(
                self.name, asked, f"{what} and configuring it again failed ({exc.seen})", exc.remedy
            ) from None

    def _await_scan(self, timeout: float, asked: str) -> Scan:
        """The first scan whose sweep began after now, within ``timeout`` seconds."""
        called = self.clock.now()
        deadline = called + timeout
        with self._cond:
            while True:
                got = self._latest
                if got is not None and got.began > called:
                    self._check_status(got.status, asked)
                    return got.scan
                if self._lost is not None:
                    raise self._lost
                now = self.clock.now()
                if now >= deadline:
                    self._stale = True
                    last = (
                        f"the last one {now - got.scan.timestamp:.2f} s ago"
                        if got is not None
                        else "none since connecting"
                    )
                    raise DeviceTimeoutError(
                        self.name,
                        asked,
                        f"no scan within {timeout:g} s ({last})",
                        "check the scanner's power and cable"
                        + ("; the next call configures it again" if self.auto_reconnect else ""),
                    )
                self._cond.wait(min(deadline - now, 0.05))

    def _check_status(self, status: int, asked: str) -> None:
        """Raise on a scan whose status byte reports an error (3) or a fatal error (4) in bits
        0-2 (section 7). Bits 3-4 (``10`` in every normal telegram) are undocumented and
        ignored; so is the pollution bit 7, since the ranges still come (GBX and RL fail on
        it): ``last_status`` keeps the byte for whoever wants to warn."""
        self.last_status = status
        level = status & 0x07
        if level >= 3:
            raise DeviceFaultError(
                self.name,
                asked,
                f"the scanner reports {'a fatal error' if level == 4 else 'an error'} "
                f"(status byte {status:02X})",
                "clean the front screen, check its LEDs and power-cycle it",
            )

    # -- link -----------------------------------------------------------------------------------
    def _start_link(self) -> None:
        transport = self._open_transport()
        self._transport, self._lost, self._stale = transport, None, False
        self._rate = 9600
        self._parser = codec.TelegramParser()
        try:
            self._configure()
            with self._cond:
                self._latest = None
            self._stop_io.clear()
            self._io = self.clock.start_thread(
                lambda: self._io_loop(transport), name=f"{self.name} reader"
            )
        except BaseException:
            self._stop_link()
            raise

    def _stop_reader(self) -> None:
        self._stop_io.set()
        if self._io is not None and self._io is not threading.current_thread():
            self.clock.join(self._io, 1.0)
        self._io = None

    def _stop_link(self) -> None:
        self._stop_reader()
        if self._transport is not None:
            with contextlib.suppress(Exception):
                self._transport.close()
        self._transport = None

    def reconnect(self) -> None:
        """Open the line again and configure the scanner again (wherever its rate is now)."""
        with self._call_lock:
            self._stop_link()
            end = self.clock.now() + self.reconnect_timeout
            while True:
                try:
                    self._start_link()
                    break
                except DeviceError:  # the port may not be back yet (a replugged adapter)
                    if self.clock.now() > end:
                        raise
                self.clock.sleep(0.2)
            self.reconnects += 1

    def _set_rate(self, rate: int) -> None:
        assert self._transport is not None
        self._transport.set_baudrate(rate)
        self._rate = rate

    # -- configuration --------------------------------------------------------------------------
    def _configure(self) -> None:
        found = self._find_rate()
        if found != self.baud:
            asked = f"switch from {found} to {self.baud} baud"
            reply = self._request(codec.baud_request(self.baud), asked, self.mode_timeout)
            self._mode_result(reply, asked)
            self._set_rate(self.baud)  # only now: the scanner answered at the old rate
            self.clock.sleep(self.switch_pause)
        kind = self._decode(
            codec.decode_type, self._request(codec.type_request(), "read the type"), "read the type"
        )
        status = self._decode(
            codec.decode_status,
            self._request(codec.status_request(), "read the status"),
            "read the status",
        )
        if status.variant != self.variant:
            asked = f"switch the variant to {self.variant}"
            reply = self._request(codec.variant_request(self.variant), asked, self.mode_timeout)
            ok, now = self._decode(codec.decode_variant_reply, reply, asked)
            if not ok or now != self.variant:
                raise DeviceFaultError(
                    self.name,
                    asked,
                    f"the scanner refused it and keeps {now}",
                    "choose a variant this model supports (180 deg at 1 or 0.5 deg)",
                )
        block = self._decode(
            codec.decode_config,
            self._request(codec.read_config_request(), "read the configuration"),
            "read the configuration",
        )
        if block.units != self.units or block.measuring_mode != self.measuring_mode:
            block = self._write_config(block)
        reply = self._request(codec.stream_request(True), "start the stream", self.mode_timeout)
        self._mode_result(reply, "start the stream")
        self.info = LmsInfo(kind, status, found, block)

    def _write_config(self, block: ConfigBlock) -> ConfigBlock:
        asked = "enter installation mode"
        reply = self._request(codec.installation_mode_request(), asked, self.mode_timeout)
        self._mode_result(reply, asked)
        wanted = block.with_settings(units=self.units, measuring_mode=self.measuring_mode)
        asked = (
            f"write the configuration (units {self.units.name.lower()}, measuring mode "
            f"{self.measuring_mode:02X})"
        )
        request = codec.write_config_request(wanted.raw)
        reply = self._request(request, asked, self.config_timeout)
        ok, now = self._decode(codec.decode_config_written, reply, asked)
        if not ok or now.units != self.units or now.measuring_mode != self.measuring_mode:
            raise DeviceFaultError(
                self.name,
                asked,
                f"the scanner refused it (units {now.units}, mode {now.measuring_mode:02X} "
                "still in force)",
                "choose units and a measuring mode this model supports",
            )
        return now

    def _find_rate(self) -> int:
        """The rate the scanner answers ``20 25`` at (which also stops a stream left running):
        9600 first (power-on), then the wanted rate, then the others."""
        rates = list(dict.fromkeys((9600, self.baud, *self.probe_rates)))
        self.bytes_received = 0
        tried = []
        for rate in rates:
            try:
                self._set_rate(rate)
            except DeviceError:
                continue  # this port cannot run at that rate: the scanner cannot be there
            tried.append(str(rate))
            try:
                reply = self._request(
                    codec.stream_request(False),
                    f"stop the stream at {rate} baud",
                    self.probe_timeout,
                    self.probe_tries - 1,
                )
            except DeviceTimeoutError:
                continue
            self._mode_result(reply, "stop the stream")
            return rate
        heard = (
            f"{self.bytes_received} bytes came, none of them an LMS telegram"
            if self.bytes_received
            else "nothing came back"
        )
        raise DeviceTimeoutError(
            self.name,
            "find the scanner's baud rate",
            f"no answer to 20 25 at {', '.join(tried)} baud ({heard})",
            "check the scanner's power and cable and that this is its port "
            "('twin hw probe' says what answers where)",
        )

    def _mode_result(self, reply: Telegram, asked: str) -> None:
        result = self._decode(codec.decode_mode_reply, reply, asked)
        if result != 0:
            raise DeviceFaultError(
                self.name,
                asked,
                f"the scanner answered A0 {result:02X} "
                f"({codec.MODE_RESULTS.get(result, 'refused')})",
                "power-cycle the scanner" if result == 2 else "check the password (SICK_LMS)",
            )

    def _decode(self, decoder: Callable[[Telegram], T], reply: Telegram, asked: str) -> T:
        try:
            return decoder(reply)
        except LmsCodecError as exc:
            raise ProtocolError(
                self.name, asked, str(exc), "check the scanner model (LMS200/211/221/291)"
            ) from None

    # -- one request, one reply -----------------------------------------------------------------
    def _request(
        self, frame: bytes, asked: str, timeout: float | None = None, retries: int | None = None
    ) -> Telegram:
        """Send ``frame`` and return its reply (code + 0x80), waiting out the optional ACK: a
        NAK resends at once (at most ``MAX_NAK_RESENDS`` times), silence after ``timeout``
        seconds resends ``retries`` times. Only while no reader thread runs (configuring,
        closing, probing): the caller reads the line itself."""
        transport = self._transport
        if transport is None:
            raise ConnectionLostError(self.name, asked, "the port is closed", "connect first")
        timeout = self.reply_timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        naks = silences = 0
        while True:
            transport.reset_input()  # a late reply to an earlier request is not this one's
            self._parser.clear()
            transport.write(frame)
            outcome, acked = self._await_reply(transport, frame[4] | 0x80, timeout, asked)
            if isinstance(outcome, Telegram):
                return outcome
            if outcome is Signal.NAK:
                naks += 1
                self.naks += 1
                if naks > MAX_NAK_RESENDS:
                    raise ProtocolError(
                        self.name,
                        asked,
                        f"the scanner answered NAK {naks} times (it receives the telegram garbled)",
                        "check the cable and that nothing else writes to the port",
                    )
                continue
            silences += 1
            if silences > retries:
                raise DeviceTimeoutError(
                    self.name,
                    asked,
                    f"no reply within {timeout:g} s"
                    + (" (the ACK came)" if acked else "")
                    + (f", {silences} tries" if silences > 1 else ""),
                    "check the scanner's power and cable",
                )

    def _await_reply(
        self, transport: Transport, want: int, timeout: float, asked: str
    ) -> tuple[Telegram | Signal | None, bool]:
        """(the reply, NAK or None for silence; whether an ACK came) within ``timeout``."""
        deadline = self.clock.now() + timeout
        acked = False
        while True:
            item = self._next_item(transport, deadline)
            if item is None or item is Signal.NAK:
                return item, acked
            if item is Signal.ACK:
                acked = True
            elif isinstance(item, Telegram):
                if item.command == want:
                    return item, acked
                if item.command == Reply.INCORRECT:
                    raise ProtocolError(
                        self.name,
                        asked,
                        "the scanner answered 92 (incorrect command)",
                        "check the scanner model: it does not take this request",
                    )
                self.stray_telegrams += 1  # a scan of a stream, a late reply

    def _next_item(self, transport: Transport, deadline: float) -> Telegram | Signal | None:
        """The next telegram or ACK/NAK byte before ``deadline`` (None: none came)."""
        reader = FrameReader(
            self._parser, self.clock.now, (TelegramError,), self._note, INTER_BYTE_LIMIT
        )
        item = reader.next_before(transport, deadline)
        self.bytes_received += reader.bytes_received
        return item  # type: ignore[return-value]

    def _note(self, exc: LmsCodecError) -> None:
        """Count a telegram the line garbled: they happen, and the parser has resynchronised."""
        self.protocol_errors += 1
        self.last_protocol_error = ProtocolError(
            self.name, "read a telegram", str(exc), "check the cable (this one was skipped)"
        )

    # -- the reader thread ----------------------------------------------------------------------
    def _io_loop(self, transport: BaudTransport) -> None:
        reader = FrameReader(
            self._parser, self.clock.now, (TelegramError,), self._note, INTER_BYTE_LIMIT
        )
        while not self._stop_io.is_set():
            try:
                data = reader.read(transport)
            except DeviceError as exc:
                with self._cond:
                    self._lost = ConnectionLostError(
                        self.name,
                        "read the scans",
                        exc.seen,
                        "check the cable; the next call opens the line again",
                    )
                    self._cond.notify_all()
                return
            self.bytes_received += len(data)
            now = self.clock.now()
            for item in reader.frames():
                if isinstance(item, Telegram):
                    self._dispatch(item, now)

    def _dispatch(self, telegram: Telegram, now: float) -> None:
        if telegram.command in (Reply.POWER_ON, Reply.RESET_CONFIRM):
            with self._cond:
                self._stale = True  # restarted: back at 9600 in mode 25, configure it again
                self._cond.notify_all()
            return
        if telegram.command != Reply.SCAN:
            self.stray_telegrams += 1
            return
        try:
            data = codec.decode_scan(telegram)
            if data.partial or data.count != self.variant.count or data.units != self.units:
                raise codec.ReplyError(
                    f"a {'partial ' if data.partial else ''}scan of {data.count} values in "
                    f"{data.units.name.lower()}, not {self.variant.count} in "
                    f"{self.units.name.lower()} (another program reconfigured the scanner?)"
                )
            ranges = data.ranges(self.measuring_mode)
        except LmsCodecError as exc:
            self._note(exc)
            return
        done = now - telegram.size * 10.0 / self._rate  # the sweep ended as sending began
        began = done - self.variant.mirror_turns / codec.MIRROR_HZ
        ranges.setflags(write=False)
        scan = Scan(self._angles, ranges, done, self.max_range)
        with self._cond:
            self._latest = _Received(scan, began, data.status)
            self.scans_received += 1
            self._cond.notify_all()

    # -- probing --------------------------------------------------------------------------------
    def identify(self, rates: Sequence[int] = (9600, 38400), timeout: float = 0.5) -> str:
        """Ask for the type and status at each of ``rates``, changing nothing (``twin hw
        probe``); one line describing the scanner, or ``DeviceTimeoutError`` if none answers."""
        with self._call_lock:
            if self._connected:
                assert self.info is not None
                return self._describe(self.info.type, self.info.status, self._rate)
            self._transport = self._open_transport()
            self._parser = codec.TelegramParser()
            try:
                for rate in rates:
                    try:
                        self._set_rate(rate)
                        reply = self._request(codec.type_request(), "read the type", timeout, 0)
                        kind = self._decode(codec.decode_type, reply, "read the type")
                        reply = self._request(codec.status_request(), "read the status", timeout)
                        status = self._decode(codec.decode_status, reply, "read the status")
                    except (DeviceTimeoutError, ProtocolError):
                        continue
                    return self._describe(kind, status, rate)
            finally:
                self._stop_link()
            raise DeviceTimeoutError(
                self.name,
                "identify the scanner",
                f"no answer to 3A at {', '.join(map(str, rates))} baud",
                "check the scanner's power and cable",
            )

    def _describe(self, kind: str, status: Status, rate: int) -> str:
        mode = codec.MODE_NAMES.get(status.operating_mode, "unknown mode")
        units = {0: "cm", 1: "mm", 2: "10 cm"}.get(status.units, f"units {status.units}")
        return (
            f"SICK {kind} at {rate} baud ({mode} {status.operating_mode:02X}, "
            f"{status.variant}, {units})"
        )
