"""Canon VC-C4 pan-tilt-zoom head over RS-232, directly or tunnelled through the robot's AUX port.

One command at a time, each waiting for its answer (the camera drops a command that arrives
before its previous answer went out, specs/protocols.md A7). Every read has a deadline, so a
silent camera is a ``DeviceTimeoutError``, never a hang; answers are read until their ``EF``
end mark, so a transport that hands over partial data (the AUX tunnel asks ARCOS for 6 bytes
first, then the rest, A10) works too. Busy answers are retried within a bound; every other
error code becomes a typed ``DeviceError``.

Units at the API: radians, pan positive LEFT, tilt positive up, seconds, radians per second.
The wire is counts of 0.1125 degrees, pan positive RIGHT; zoom is the camera's "position 2"
count (0 = wide end).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

from hardware import vcc4_codec as codec
from hardware.transport import SerialTransport, Transport
from hardware.vcc4_codec import AnswerError
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import (
    VCC4_LIMITS,
    ConnectionLostError,
    DeviceBusyError,
    DeviceError,
    DeviceFaultError,
    DeviceTimeoutError,
    OutOfRangeError,
    PanTilt,
    PanTiltLimits,
    ProtocolError,
)

try:
    from termios import error as _TermiosError
except ImportError:  # no termios (Windows): pyserial raises only SerialException there
    _TermiosError = OSError

NAME = "VC-C4"
# Tilt range sent at initialisation: the camera keeps +-30 degrees until told (A6); this is the
# manual's full -30..+90 degrees, so the API's limits are the camera's (ARIA stops at +88).
INIT_TILT_RANGE = codec.TILT_RANGE_MAX
LIMITS = VCC4_LIMITS
BUSY_RETRY = 0.02  # s between resends of a command the camera answered busy


class ModeError(DeviceFaultError):
    """The camera refused a command for its mode: local mode, camera off, or not initialised."""


def error_for(flags: int, device: str, asked: str) -> DeviceError | None:
    """The typed error an answer's flag byte means (``codec.answer_error``), or None for an ACK:
    one line with the code on the wire, what it means here, and what to do."""
    error = codec.answer_error(flags)
    if error is None:
        return None
    code = codec.hex_digits(flags, 2).decode()
    if error is AnswerError.MODE:
        return ModeError(
            device,
            asked,
            f"mode error (answer code {code}): not in host control "
            "mode, camera off or pedestal not initialised",
            "initialise the camera (twin hw vcc4 init, or reconnect)",
        )
    if error is AnswerError.COMMAND:
        return ProtocolError(
            device,
            asked,
            f"command error (answer code {code}): the camera does not know this command",
            "check the camera model (VC-C4)",
        )
    if error is AnswerError.PARAMETER:
        return OutOfRangeError(
            device,
            asked,
            f"parameter error (answer code {code}): value outside the movable range",
            "stay within the camera's limits",
        )
    if error is AnswerError.SYSTEM:
        return DeviceFaultError(
            device, asked, f"system error (answer code {code})", "power-cycle the camera"
        )
    if error is AnswerError.BUSY:
        return DeviceBusyError(
            device,
            asked,
            f"busy (answer code {code}): an earlier motion, "
            "initialisation or power change is still running",
            "wait for it to finish or stop the head",
        )
    return ProtocolError(device, asked, f"unknown answer code {code}", "check the cable")


class VCC4(PanTilt):
    """The camera head as a ``twin.core.devices.PanTilt``.

    ``VCC4(transport)`` talks over any ``Transport`` (e.g. ``ArcosBase.aux_transport(1)``);
    ``VCC4.open(port)`` opens a serial line (9600 8N1, RTS asserted) on ``connect`` and reopens
    it once if it vanishes mid-use (a cable replugged). ``connect`` brings the camera into host
    control with the pedestal initialised, the top speeds and the full tilt range.

    Timing knobs (seconds): ``answer_timeout`` per answer (the manual's 300 ms plus margin, as
    ARIA), ``busy_timeout`` for retrying ordinary busy answers, ``power_timeout`` and
    ``init_timeout`` for the busy spells after camera-on and pedestal initialisation,
    ``poll_interval`` between status polls while moving; ``retries`` resends after a lost,
    truncated or garbled answer; ``tolerance`` (rad) how close a finished move must be. All of
    them run on ``clock`` (a test's ``ManualClock`` makes them virtual seconds).
    """

    name = NAME

    def __init__(
        self,
        transport: Transport | None = None,
        *,
        opener: Callable[[], Transport] | None = None,
        name: str = NAME,
        answer_timeout: float = 0.4,
        retries: int = 1,
        busy_timeout: float = 2.0,
        power_timeout: float = 6.0,
        init_timeout: float = 15.0,
        poll_interval: float = 0.03,
        tolerance: float = math.radians(0.25),
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        if transport is None and opener is None:
            raise ValueError("give a transport or an opener")
        self.name, self.clock = name, clock
        self._transport = transport
        self._opener = opener
        self._owns_transport = transport is None
        self.answer_timeout, self.retries = answer_timeout, retries
        self.busy_timeout, self.power_timeout = busy_timeout, power_timeout
        self.init_timeout, self.poll_interval = init_timeout, poll_interval
        self.tolerance = tolerance
        self._parser = codec.AnswerParser()
        self._lock = threading.RLock()  # one command in flight, whichever thread asks
        self._connected = False
        self._speeds: tuple[int, int] | None = None  # pan, tilt counts/s last set
        self.zoom_max: int | None = None

    @classmethod
    def open(cls, port: str, baudrate: int = 9600, **options: object) -> VCC4:
        """A driver for a camera wired straight to serial ``port`` (opened on ``connect``)."""
        name = str(options.pop("name", NAME))
        clock: Clock = options.get("clock", SYSTEM_CLOCK)  # type: ignore[assignment]

        def opener() -> Transport:
            return SerialTransport(port, baudrate, name, rts=True, clock=clock)

        return cls(opener=opener, name=name, **options)  # type: ignore[arg-type]

    # -- lifecycle ------------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def limits(self) -> PanTiltLimits:
        return LIMITS

    def connect(self) -> None:
        if self._connected:
            return
        if self._transport is None:
            assert self._opener is not None
            self._transport = self._opener()
        try:
            self.initialize(pedestal=None)
        except BaseException:
            self._release()
            raise
        self._connected = True

    def close(self) -> None:
        if self._transport is None:
            return
        try:
            if self._connected:
                self._exchange(codec.pan_tilt_stop(), "stop on close", retries=0)
        except DeviceError:
            pass  # closing anyway; the camera stops by itself at its target
        finally:
            self._connected = False
            self._release()

    def _release(self) -> None:
        if self._owns_transport and self._transport is not None:
            self._transport.close()
            self._transport = None

    def identify(self) -> str:
        """Ask for the camera's operation status without changing anything (``twin hw probe``).

        Any well-formed answer, even a mode error from a camera in local mode, proves a VC-C4
        (or a compatible head) is on the line; returns a one-line description of it."""
        if self._transport is None:
            assert self._opener is not None
            self._transport = self._opener()
        try:
            with self._lock:
                answer = self._round_trip(codec.operation_status(), "identify", 0)
        finally:
            if not self._connected:
                self._release()
        mode = "error flags " + f"{answer.flags:02X}" if answer.flags else "ready"
        return f"VC-C4 answers ({mode}, status {codec.describe(answer.status) or 'none'})"

    # -- initialisation -------------------------------------------------------------------------
    def initialize(self, pedestal: bool | None = True) -> None:
        """Host control, camera on, pedestal initialisation, top speeds, full tilt range.

        ``pedestal=None`` initialises the pedestal only if the camera says it has not been
        (saving a calibration on reconnect); True always does, like ARIA at start-up."""
        status = self._status()
        if status & codec.STATUS_LOCAL_MODE:
            self._exchange(codec.host_control(), "enter host control mode")
        if status & codec.STATUS_POWER_OFF:
            self._exchange(codec.power(True), "switch the camera on")
        if pedestal or (pedestal is None and status & codec.STATUS_NOT_INITIALISED):
            # after camera-on the camera answers busy for seconds (A7)
            self._exchange(
                codec.pedestal_init(), "initialise the pedestal", busy_timeout=self.power_timeout
            )
        self._speeds = None
        self._set_speeds(codec.PAN_SPEED_MAX, codec.TILT_SPEED_MAX, busy_timeout=self.init_timeout)
        self._exchange(codec.tilt_range(*INIT_TILT_RANGE), "set the tilt range -30..+90 deg")

    def _status(self) -> int:
        """The extended operation status (20 bits, A5)."""
        answer = self._exchange(
            codec.operation_status(extended=True),
            "read the operation status",
            expected=5,
            busy_timeout=self.init_timeout,
        )
        return self._number(answer, 5, "read the operation status")

    # -- motion ---------------------------------------------------------------------------------
    def move_to(
        self, pan: float, tilt: float = 0.0, *, speed: float | None = None, timeout: float = 10.0
    ) -> tuple[float, float]:
        asked = f"move to pan {math.degrees(pan):.1f} deg, tilt {math.degrees(tilt):.1f} deg"
        self.require_connected(asked)
        LIMITS.check(self.name, pan, tilt, speed)
        deadline = self.clock.now() + timeout
        pan_pps, tilt_pps = codec.PAN_SPEED_MAX, codec.TILT_SPEED_MAX
        if speed is not None:
            pps = codec.degrees_to_count(math.degrees(speed))
            if pps < codec.PAN_SPEED_MIN:
                raise OutOfRangeError(
                    self.name,
                    f"{asked} at {math.degrees(speed):.2f} deg/s",
                    "slower than the camera's slowest 0.9 deg/s",
                    "use at least 0.9 deg/s",
                )
            pan_pps, tilt_pps = min(pps, pan_pps), min(pps, tilt_pps)
        self._set_speeds(pan_pps, tilt_pps)
        # API pan is positive left, the wire's positive right
        target = (
            codec.degrees_to_count(-math.degrees(pan)),
            codec.degrees_to_count(math.degrees(tilt)),
        )
        self._move_command(target, (pan_pps, tilt_pps), asked)
        return self._wait_until_there(target, asked, deadline, timeout)

    def _move_command(self, target: tuple[int, int], speeds: tuple[int, int], asked: str) -> None:
        try:
            self._exchange(codec.pan_tilt(*target), asked, busy_timeout=0.0)
        except DeviceBusyError:
            # an earlier move still running (say, after a timeout): stop it, then go
            self._exchange(codec.pan_tilt_stop(), f"stop before: {asked}")
            self._exchange(codec.pan_tilt(*target), asked)
        except ModeError:
            # the camera lost host mode or its calibration (power blip): initialise, retry once
            self.initialize(pedestal=None)
            self._set_speeds(*speeds)
            self._exchange(codec.pan_tilt(*target), asked)

    def _wait_until_there(
        self, target: tuple[int, int], asked: str, deadline: float, timeout: float
    ) -> tuple[float, float]:
        """Poll the operation status until pan and tilt have stopped, then check the position."""
        tolerance = self.tolerance
        while True:
            status = self._number(
                self._exchange(codec.operation_status(), asked, expected=3), 3, asked
            )
            if not status & (codec.STATUS_PANNING | codec.STATUS_TILTING):
                pan, tilt = self._position(asked)
                want = (
                    -math.radians(codec.count_to_degrees(target[0])),
                    math.radians(codec.count_to_degrees(target[1])),
                )
                if abs(pan - want[0]) <= tolerance and abs(tilt - want[1]) <= tolerance:
                    return pan, tilt
                if self.clock.now() > deadline:
                    raise DeviceFaultError(
                        self.name,
                        asked,
                        f"the head stopped at pan {math.degrees(pan):.2f} deg, "
                        f"tilt {math.degrees(tilt):.2f} deg",
                        "check nothing blocks the head",
                    )
            if self.clock.now() > deadline:
                pan, tilt = self._position(asked)
                raise DeviceTimeoutError(
                    self.name,
                    asked,
                    f"still moving after {timeout:g} s (at pan "
                    f"{math.degrees(pan):.1f} deg, tilt {math.degrees(tilt):.1f} deg)",
                    "allow more time or a higher speed",
                )
            self.clock.sleep(self.poll_interval)

    def position(self) -> tuple[float, float]:
        self.require_connected("read the position")
        return self._position("read the position")

    def _position(self, asked: str) -> tuple[float, float]:
        answer = self._exchange(codec.pan_tilt_request(), asked, expected=8)
        try:
            pan, tilt = codec.decode_pan_tilt(answer.status)
        except ValueError:
            raise self._bad_status(asked, answer.status, "8 hex digits") from None
        return (
            -math.radians(codec.count_to_degrees(pan)),
            math.radians(codec.count_to_degrees(tilt)),
        )

    def stop(self) -> None:
        self.require_connected("stop")
        self._exchange(codec.pan_tilt_stop(), "stop")

    def set_speeds(self, pan_speed: float, tilt_speed: float) -> None:
        """Top pan and tilt speeds (rad/s) for the next moves, within 0.9..90 / 0.9..70 deg/s."""
        self.require_connected("set speeds")
        pps = [codec.degrees_to_count(math.degrees(s)) for s in (pan_speed, tilt_speed)]
        if not (
            codec.PAN_SPEED_MIN <= pps[0] <= codec.PAN_SPEED_MAX
            and codec.TILT_SPEED_MIN <= pps[1] <= codec.TILT_SPEED_MAX
        ):
            raise OutOfRangeError(
                self.name,
                f"set speeds {math.degrees(pan_speed):.2f}, {math.degrees(tilt_speed):.2f} deg/s",
                "outside 0.9..90 deg/s (pan) or 0.9..70 deg/s (tilt)",
                "choose speeds within the camera's range",
            )
        self._set_speeds(pps[0], pps[1])

    def _set_speeds(self, pan_pps: int, tilt_pps: int, busy_timeout: float | None = None) -> None:
        if self._speeds == (pan_pps, tilt_pps):
            return  # each command costs a round trip; the camera keeps what it was told
        self._exchange(
            codec.pan_speed(pan_pps),
            f"set the pan speed to {pan_pps} counts/s",
            busy_timeout=busy_timeout,
        )
        self._exchange(
            codec.tilt_speed(tilt_pps),
            f"set the tilt speed to {tilt_pps} counts/s",
            busy_timeout=busy_timeout,
        )
        self._speeds = (pan_pps, tilt_pps)

    # -- zoom -----------------------------------------------------------------------------------
    def zoom_to(self, position: int, *, timeout: float = 5.0) -> int:
        """Zoom to ``position`` (0 = wide end .. the camera's maximum) and wait until there."""
        asked = f"zoom to {position}"
        self.require_connected(asked)
        top = self.max_zoom()
        if not 0 <= position <= top:
            raise OutOfRangeError(
                self.name, asked, f"outside 0..{top}", "choose a zoom within the camera's range"
            )
        self._exchange(codec.zoom(position), asked)
        deadline = self.clock.now() + timeout
        while (now := self._zoom(asked)) != position:
            if self.clock.now() > deadline:
                raise DeviceTimeoutError(
                    self.name, asked, f"at {now} after {timeout:g} s", "allow more time"
                )
            self.clock.sleep(self.poll_interval)
        return now

    def zoom(self) -> int:
        """The current zoom position (0 = wide end)."""
        self.require_connected("read the zoom")
        return self._zoom("read the zoom")

    def max_zoom(self) -> int:
        """The unit's telephoto end, asked once (it differs between units, A6)."""
        if self.zoom_max is None:
            answer = self._exchange(codec.zoom_max_request(), "read the zoom maximum", expected=4)
            self.zoom_max = self._number(answer, 4, "read the zoom maximum")
        return self.zoom_max

    def _zoom(self, asked: str) -> int:
        return self._number(self._exchange(codec.zoom_request(), asked, expected=4), 4, asked)

    # -- one command, one answer ----------------------------------------------------------------
    def _exchange(
        self,
        frame: bytes,
        asked: str,
        *,
        expected: int = 0,
        busy_timeout: float | None = None,
        retries: int | None = None,
    ) -> codec.Answer:
        """Send ``frame`` and return its successful answer carrying ``expected`` status bytes.

        Busy answers are resent for up to ``busy_timeout`` seconds; a lost, truncated or
        garbled answer is resent ``retries`` times (every command we send is idempotent), then
        raised. A vanished serial port is reopened once if this driver opened it."""
        with self._lock:
            return self._exchange_locked(frame, asked, expected, busy_timeout, retries)

    def _exchange_locked(
        self,
        frame: bytes,
        asked: str,
        expected: int,
        busy_timeout: float | None,
        retries: int | None,
    ) -> codec.Answer:
        busy_until = self.clock.now() + (
            self.busy_timeout if busy_timeout is None else busy_timeout
        )
        attempts = self.retries if retries is None else retries
        reopened = False
        while True:
            try:
                answer = self._round_trip(frame, asked, expected)
            except (ProtocolError, DeviceTimeoutError):
                if attempts <= 0:
                    raise
                attempts -= 1
                continue
            except ConnectionLostError:
                if reopened or self._opener is None or not self._owns_transport:
                    raise
                self._reopen(asked)
                reopened = True
                continue
            error = error_for(answer.flags, self.name, asked)
            if error is None:
                if len(answer.status) != expected:
                    raise self._bad_status(asked, answer.status, f"{expected} status bytes")
                return answer
            if isinstance(error, DeviceBusyError) and self.clock.now() < busy_until:
                self.clock.sleep(BUSY_RETRY)
                continue
            raise error

    def _round_trip(self, frame: bytes, asked: str, expected: int) -> codec.Answer:
        transport = self._transport
        if transport is None:
            raise ConnectionLostError(self.name, asked, "the port is closed", "connect again")
        try:
            transport.reset_input()  # a late answer to an earlier command is not this one's
        except _TermiosError as exc:
            # pyserial lets tcflush's termios.error through when the line went away (a pty
            # whose other end closed): that is a lost connection, not a crash
            raise ConnectionLostError(
                self.name,
                asked,
                f"the line went away ({exc})",
                "check that the camera is plugged in",
            ) from None
        self._parser.clear()
        transport.write(frame)
        deadline = self.clock.now() + self.answer_timeout
        want = codec.MIN_ANSWER + expected
        while True:
            try:
                answer = self._parser.next_answer()
            except codec.FrameError as exc:
                raise ProtocolError(
                    self.name, asked, str(exc), "check the cable and the baud rate (9600 8N1)"
                ) from None
            if answer is not None:
                if answer.device != 0:
                    raise ProtocolError(
                        self.name,
                        asked,
                        f"an answer from device {answer.device}, not 0",
                        "check the cascade setting",
                    )
                return answer
            left = deadline - self.clock.now()
            if left <= 0:
                partial = self._parser.partial
                if partial:
                    raise ProtocolError(
                        self.name,
                        asked,
                        f"truncated answer "
                        f"{codec.describe(partial)} (no end mark within "
                        f"{self.answer_timeout:g} s)",
                        "check the cable",
                    )
                raise DeviceTimeoutError(
                    self.name,
                    asked,
                    f"no answer within {self.answer_timeout:g} s",
                    "check the camera is powered, the cable is null-modem and RTS is wired",
                )
            self._parser.feed(transport.read(self._parser.wanted(want), left))

    def _reopen(self, asked: str) -> None:
        assert self._opener is not None
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        try:
            self._transport = self._opener()
        except DeviceError as exc:
            raise ConnectionLostError(
                self.name, asked, f"the port vanished and reopening failed ({exc.seen})", exc.remedy
            ) from None

    def _number(self, answer: codec.Answer, digits: int, asked: str) -> int:
        try:
            if len(answer.status) != digits:
                raise ValueError
            return codec.parse_hex(answer.status)
        except ValueError:
            raise self._bad_status(asked, answer.status, f"{digits} hex digits") from None

    def _bad_status(self, asked: str, status: bytes, wanted: str) -> ProtocolError:
        return ProtocolError(
            self.name,
            asked,
            f"answer status {status!r}, not {wanted}",
            "check the camera model (VC-C4) and the cable",
        )
