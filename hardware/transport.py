"""Byte links to devices: a serial port through pyserial, behind one small interface.

Drivers speak their wire protocol over a ``Transport``; what carries the bytes (a serial line,
a pseudo-terminal, the robot's AUX port tunnelled through ARCOS packets) is not their concern.
Every read has a timeout, so a device that stops answering is an error, never a hang. Opening a
port turns the usual failures into one-line ``DeviceError``s that name the device and the remedy.
"""

from __future__ import annotations

import errno
import termios
from collections.abc import Callable, Iterator
from typing import Protocol

import serial

from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import ConnectionLostError, DeviceError

# Longest real-time block inside one pyserial read (s): a read's timeout is kept on the
# driver's clock, so it is waited out in slices short enough to re-check that clock.
MAX_BLOCK = 0.05


class Transport(Protocol):
    """A byte link with timeouts. ``name`` names the device in errors."""

    name: str

    def write(self, data: bytes) -> None: ...

    def read(self, size: int, timeout: float) -> bytes:
        """Up to ``size`` bytes, returning early only when ``size`` arrived; fewer (maybe none)
        when ``timeout`` seconds (of the driver's clock) pass first."""
        ...

    def reset_input(self) -> None:
        """Drop whatever has been received and not read (stale answers)."""
        ...

    def close(self) -> None: ...


class SerialTransport:
    """A serial port (or pseudo-terminal) opened with pyserial, 8N1, no flow control.

    ``rts=True`` asserts RTS after opening (the VC-C4 answers only while its CTS is high); a
    pseudo-terminal has no modem lines and refuses the ioctl, which is taken as "nothing to
    assert", not as a failure (specs/protocols.md, part D). Read timeouts run on ``clock``.
    """

    def __init__(
        self, port: str, baudrate: int, name: str, rts: bool = False, clock: Clock = SYSTEM_CLOCK
    ) -> None:
        self.port, self.name, self.clock = port, name, clock
        try:
            self._serial = serial.Serial(
                port,
                baudrate=baudrate,
                bytesize=8,
                parity="N",
                stopbits=1,
                timeout=0,
                rtscts=False,
                dsrdtr=False,
            )
        except serial.SerialException as exc:
            raise _open_error(name, port, exc) from None
        if rts:
            try:
                self._serial.rts = True
            except (OSError, serial.SerialException) as exc:
                if getattr(exc, "errno", None) != errno.ENOTTY and "Inappropriate" not in str(exc):
                    raise DeviceError(
                        name,
                        f"assert RTS on {port}",
                        str(exc),
                        "check the cable (null-modem, RTS wired)",
                    ) from None

    def write(self, data: bytes) -> None:
        try:
            self._serial.write(data)
            self._serial.flush()
        except (OSError, serial.SerialException, termios.error) as exc:
            raise ConnectionLostError(
                self.name,
                f"write {len(data)} bytes to {self.port}",
                str(exc),
                "check that the device is plugged in",
            ) from None

    def read(self, size: int, timeout: float) -> bytes:
        clock = self.clock
        end = clock.now() + timeout
        out = b""
        try:
            while True:
                self._serial.timeout = min(max(end - clock.now(), 0.0), MAX_BLOCK)
                out += self._serial.read(size - len(out))
                if len(out) >= size or clock.now() >= end:
                    return out
        except (OSError, serial.SerialException, termios.error, TypeError) as exc:
            # pyserial raises TypeError from a closed port's internal state on some versions.
            raise ConnectionLostError(
                self.name, f"read from {self.port}", str(exc), "check that the device is plugged in"
            ) from None

    def reset_input(self) -> None:
        try:
            self._serial.reset_input_buffer()
        except (OSError, serial.SerialException, termios.error) as exc:
            # A hung-up pty makes tcflush raise termios.error, which pyserial lets through.
            raise ConnectionLostError(
                self.name, f"flush {self.port}", str(exc), "check that the device is plugged in"
            ) from None

    def close(self) -> None:
        self._serial.close()


def _open_error(name: str, port: str, exc: serial.SerialException) -> DeviceError:
    number = getattr(exc, "errno", None)
    text = str(exc)
    if number == errno.ENOENT or "No such file" in text:
        return DeviceError(
            name,
            f"open {port}",
            "no such port",
            "check the path; 'twin hw probe' lists the serial ports",
        )
    if number == errno.EACCES or "Permission denied" in text:
        return DeviceError(
            name,
            f"open {port}",
            "permission denied",
            "add your user to the 'dialout' group and log in again",
        )
    if number == errno.EBUSY or "busy" in text.lower():
        return DeviceError(
            name,
            f"open {port}",
            "the port is busy",
            "close the other program using it (another driver, minicom, ARIA)",
        )
    return DeviceError(
        name,
        f"open {port}",
        text.splitlines()[0] if text else "failed",
        "check the port and the cable",
    )


class FrameParser(Protocol):
    """An incremental parser of a wire protocol's frames (the codecs' ``PacketParser`` and
    ``TelegramParser``): bytes in, frames out, a frame cut off by silence given up."""

    def feed(self, data: bytes) -> None: ...

    @property
    def partial(self) -> object:
        """Truthy while a frame has begun but not ended."""
        ...

    def next(self) -> object | None:
        """The next complete frame, or None; a garbled one raises the codec's error."""
        ...

    def expire_partial(self) -> None:
        """Give up the frame under way (raises the codec's error describing it)."""
        ...


class FrameReader:
    """A driver's reader thread's round: read what the line has, feed the parser, and hand out
    the frames. A read waits for one byte at most ``poll`` seconds, then takes whatever else is
    there (low latency without spinning); a frame silent for more than ``inter_byte_limit``
    seconds mid-way is given up (the line cut it off); a frame the line garbled is passed to
    ``note`` (drivers count them: a serial line drops one now and then) rather than raised."""

    def __init__(
        self,
        parser: FrameParser,
        now: Callable[[], float],
        codec_errors: tuple[type[Exception], ...],
        note: Callable[[Exception], None],
        inter_byte_limit: float = 0.1,
        poll: float = 0.02,
    ) -> None:
        self.parser, self.now, self.codec_errors, self.note = parser, now, codec_errors, note
        self.inter_byte_limit, self.poll = inter_byte_limit, poll
        self._last_byte = now()
        self.bytes_received = 0

    def read(self, transport: Transport, wait: float | None = None) -> bytes:
        """One read from the line, waiting at most ``wait`` seconds (default ``poll``) for its
        first byte (``DeviceError`` if the line is lost); the bytes go to the parser."""
        data = transport.read(1, self.poll if wait is None else wait)
        if data:
            data += transport.read(4096, 0.0)
        now = self.now()
        if data:
            self._last_byte = now
            self.bytes_received += len(data)
            self.parser.feed(data)
        elif self.parser.partial and now - self._last_byte > self.inter_byte_limit:
            try:
                self.parser.expire_partial()
            except self.codec_errors as exc:
                self.note(exc)
        return data

    def frames(self) -> Iterator[object]:
        """Every complete frame the parser holds now."""
        while True:
            try:
                frame = self.parser.next()
            except self.codec_errors as exc:
                self.note(exc)
                continue
            if frame is None:
                return
            yield frame

    def next_before(self, transport: Transport, deadline: float) -> object | None:
        """The next frame, reading the line until ``deadline`` on the clock (None: none came);
        for the request-and-reply exchanges before a reader thread runs."""
        while True:
            for frame in self.frames():
                return frame
            left = deadline - self.now()
            if left <= 0:
                return None
            self.read(transport, min(left, self.poll))
