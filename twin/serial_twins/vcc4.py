"""An emulated Canon VC-C4 that moves the twin's pan-tilt head, and its pseudo-terminal server.

``VCC4Emulator`` is a ``ByteDevice``: it takes the host's bytes and produces the camera's
answers byte for byte (specs/protocols.md part A, emulator notes in part D): host/local control
mode, camera power, pedestal initialisation, busy while a move, initialisation or power change
runs, the error codes ``39 30`` (mode), ``31 30`` (busy), ``35 30`` (parameter), ``33 30``
(command), silence for other device numbers, answers ~10 ms after the command. The head it moves
is a ``HeadActuator``: the MuJoCo robot's head (``SimHeadActuator``) or a kinematic stand-in.

The same emulator sits on its own line (``serve_vcc4``: direct RS-232 wiring, a pseudo-terminal
or a ``MemoryLink``) or is handed to the ARCOS emulator as its AUX1 device (tunnelled wiring).
``VCC4Faults`` injects the line faults tests need: junk before answers, truncated or garbled
answers, silence. All times are seconds of the server's ``Clock``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from hardware import vcc4_codec as codec
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import VCC4_LIMITS, PanTiltLimits
from twin.serial_twins.bytedevice import DeviceLine, LineServer
from twin.serial_twins.pty import PtyLink


def _rad(counts: float) -> float:
    return math.radians(codec.count_to_degrees(counts))


class HeadActuator(Protocol):
    """What the emulator moves. Radians, pan positive LEFT (the API's convention), rad/s."""

    def command(self, pan: float, tilt: float, pan_speed: float, tilt_speed: float) -> None:
        """Start moving toward (pan, tilt) at up to the given speeds; return at once."""
        ...

    def position(self) -> tuple[float, float]: ...

    def settled(self) -> bool:
        """True once the head rests at its last commanded angles."""
        ...

    def stop(self) -> None: ...


class SimHeadActuator:
    """The MuJoCo robot's head, called under ``sim.lock`` (the world steps in another thread).

    The sim's servo takes one speed cap for both axes; when the camera's pan and tilt speeds
    cannot both be honoured, the slower-finishing axis gets its own speed."""

    def __init__(self, sim: Any) -> None:
        self.sim = sim
        self.limits: PanTiltLimits = sim.head_limits

    def command(self, pan: float, tilt: float, pan_speed: float, tilt_speed: float) -> None:
        lim = self.limits
        pan = min(max(pan, lim.pan_min), lim.pan_max)
        tilt = min(max(tilt, lim.tilt_min), lim.tilt_max)
        pan_speed, tilt_speed = min(pan_speed, lim.pan_speed), min(tilt_speed, lim.tilt_speed)
        with self.sim.lock:
            now_pan, now_tilt = self.sim.head()
            if abs(tilt_speed - min(pan_speed, lim.tilt_speed)) < _rad(1):
                speed = pan_speed  # the sim caps tilt at min(speed, its top): both exact
            elif abs(pan - now_pan) / pan_speed >= abs(tilt - now_tilt) / tilt_speed:
                speed = pan_speed
            else:
                speed = tilt_speed
            self.sim.command_head(pan, tilt, speed)

    def position(self) -> tuple[float, float]:
        with self.sim.lock:
            return self.sim.head()

    def settled(self) -> bool:
        with self.sim.lock:
            return bool(self.sim.head_settled())

    def stop(self) -> None:
        with self.sim.lock:
            self.sim.stop_head()


class KinematicHead:
    """A head that moves at constant speed per axis in ``clock`` time: for unit tests."""

    def __init__(self, clock: Clock = SYSTEM_CLOCK, limits: PanTiltLimits = VCC4_LIMITS) -> None:
        self.clock, self.limits = clock, limits
        self._start = (0.0, 0.0)
        self._goal = (0.0, 0.0)
        self._speed = (limits.pan_speed, limits.tilt_speed)
        self._t0 = clock.now()
        self.commands: list[tuple[float, float, float, float]] = []

    def _at(self, t: float) -> tuple[float, float]:
        out = []
        for s, g, v in zip(self._start, self._goal, self._speed, strict=True):
            step = v * max(0.0, t - self._t0)
            out.append(g if abs(g - s) <= step else s + math.copysign(step, g - s))
        return out[0], out[1]

    def command(self, pan: float, tilt: float, pan_speed: float, tilt_speed: float) -> None:
        now = self.clock.now()
        self._start, self._t0 = self._at(now), now
        self._goal, self._speed = (pan, tilt), (pan_speed, tilt_speed)
        self.commands.append((pan, tilt, pan_speed, tilt_speed))

    def position(self) -> tuple[float, float]:
        return self._at(self.clock.now())

    def settled(self) -> bool:
        return self.position() == self._goal

    def stop(self) -> None:
        here = self.position()
        self._start, self._goal, self._t0 = here, here, self.clock.now()


@dataclass
class VCC4Timing:
    """Seconds (the server's clock): answer latency (manual: 10 ms typical), how long camera power
    changes and pedestal initialisation keep the camera busy (A7), zoom speed in counts/s; an
    answer also takes its bytes' time on the line at ``baud`` (10 bits a byte; 0: instant)."""

    latency: float = 0.010
    baud: int = 9600
    power_seconds: float = 4.0
    init_seconds: float = 2.5
    zoom_rate: float = 1000.0


@dataclass
class VCC4Faults:
    """Line faults for tests, each applied to the next ``*_count`` answers."""

    junk: bytes = b"\x00\x13\xff junk"
    junk_count: int = 0  # answers preceded by ``junk``
    truncate_count: int = 0  # answers cut before their last status byte and end mark
    garble_count: int = 0  # answers with a non-ASCII byte in place of the error code
    silent: bool = False  # answer nothing and do nothing (camera unplugged)


# While a power change or initialisation runs everything else is busy; while the head moves,
# the motion commands (absolute move, home, initialise) are.
_ALWAYS = {codec.OPERATION_STATUS, codec.PRODUCT_NAME}  # answered even while busy
_LOCAL_OK = _ALWAYS | {codec.CONTROL_MODE}
_ZOOM_MAX = 0x085E  # the manual's example unit (A6)


class VCC4Emulator:
    """The camera's state machine. Thread-safe: ``receive``/``transmit`` may come from the pty
    server's thread or the ARCOS emulator's, settings and ``faults`` from a test."""

    def __init__(
        self,
        head: HeadActuator,
        *,
        device: int = 0,
        camera_on: bool = True,
        host_mode: bool = False,
        pedestal_ready: bool = False,
        zoom_max: int = _ZOOM_MAX,
        timing: VCC4Timing | None = None,
        faults: VCC4Faults | None = None,
    ) -> None:
        self.head, self.device = head, device
        self.camera_on, self.host_mode, self.pedestal_ready = camera_on, host_mode, pedestal_ready
        self.zoom_max = zoom_max
        self.timing = timing or VCC4Timing()
        self.faults = faults or VCC4Faults()
        self.pan_speed, self.tilt_speed = codec.PAN_SPEED_MAX, codec.TILT_SPEED_MAX
        self.pan_range = codec.PAN_RANGE
        self.tilt_range = codec.TILT_RANGE_DEFAULT
        self.zoom_speed = 7
        self._zoom = (0.0, 0.0, 0.0)  # from, to, start time
        self._busy_until = -math.inf  # power change or initialisation running until then
        self._after_busy: Callable[[], None] | None = None
        self._wait_head = False
        self._inbox = bytearray()
        self._outbox: list[tuple[float, bytes]] = []
        self._lock = threading.Lock()
        self.received: list[codec.Command] = []  # every frame addressed to us, for tests

    # -- ByteDevice -----------------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> None:
        with self._lock:
            if self.faults.silent:
                return
            self._inbox += data
            while True:
                start = self._inbox.find(codec.CMD_HEADER)
                if start < 0:
                    self._inbox.clear()
                    return
                del self._inbox[:start]
                end = self._inbox.find(codec.END)
                if end < 0:
                    if len(self._inbox) > 64:  # no end mark: line noise, not a command
                        del self._inbox[:1]
                        continue
                    return
                frame = bytes(self._inbox[: end + 1])
                del self._inbox[: end + 1]
                if self._outbox and self._outbox[-1][0] > now:
                    continue  # manual A7: a command before the last answer went out is dropped
                command = codec.parse_command(frame)
                if command is None or command.device != self.device:
                    continue  # wrong device number: silently ignored (A4)
                self.received.append(command)
                flags, status = self._execute(command, now)
                answer = self._faulty(codec.answer_frame(flags, status, self.device))
                on_line = 10 * len(answer) / self.timing.baud if self.timing.baud else 0.0
                self._outbox.append((now + self.timing.latency + on_line, answer))

    def transmit(self, now: float) -> bytes:
        with self._lock:
            ready = [data for due, data in self._outbox if due <= now]
            self._outbox = [(due, data) for due, data in self._outbox if due > now]
            return b"".join(ready)

    def next_wake(self, now: float) -> float | None:
        """When the next answer goes out (clock seconds), None if none is pending."""
        with self._lock:
            return min((due for due, _ in self._outbox), default=None)

    def _faulty(self, answer: bytes) -> bytes:
        f = self.faults
        if f.garble_count > 0:
            f.garble_count -= 1
            answer = answer[:3] + b"\xb0" + answer[4:]
        if f.truncate_count > 0:
            f.truncate_count -= 1
            answer = answer[:-2] if len(answer) > codec.MIN_ANSWER else answer[:-1]
        if f.junk_count > 0:
            f.junk_count -= 1
            answer = f.junk + answer
        return answer

    # -- state ----------------------------------------------------------------------------------
    def _busy(self, now: float) -> bool:
        """A power change or initialisation still running (it ends with the head at rest)."""
        if now < self._busy_until:
            return True
        if self._after_busy is not None:
            if self._wait_head and not self.head.settled():
                return True  # initialisation still driving the head home
            done, self._after_busy = self._after_busy, None
            done()
        return False

    def zoom_at(self, now: float) -> int:
        start, goal, t0 = self._zoom
        step = self.timing.zoom_rate * max(0.0, now - t0)
        if abs(goal - start) <= step:
            return round(goal)
        return round(start + math.copysign(step, goal - start))

    def _position_counts(self) -> tuple[int, int]:
        pan, tilt = self.head.position()
        # the wire's pan is positive right
        return (
            round(-math.degrees(pan) / codec.DEGREES_PER_COUNT),
            round(math.degrees(tilt) / codec.DEGREES_PER_COUNT),
        )

    def operation_status(self, now: float) -> int:
        bits = 0
        if not self.head.settled():
            bits |= codec.STATUS_PANNING | codec.STATUS_TILTING
        if self.zoom_at(now) != round(self._zoom[1]):
            bits |= codec.STATUS_ZOOMING
        if not self.camera_on:
            bits |= codec.STATUS_POWER_OFF
        if not self.pedestal_ready:
            bits |= codec.STATUS_NOT_INITIALISED
        if not self.host_mode:
            bits |= codec.STATUS_LOCAL_MODE
        return bits

    def _move(self, pan: int, tilt: int) -> None:
        self.head.command(-_rad(pan), _rad(tilt), _rad(self.pan_speed), _rad(self.tilt_speed))

    # -- commands -------------------------------------------------------------------------------
    def _execute(self, cmd: codec.Command, now: float) -> tuple[int, bytes]:
        code, p = cmd.code, cmd.params
        busy = codec.FLAG_BUSY
        running = self._busy(now)  # first: a finished initialisation shows in the status
        if not self.host_mode and code not in _LOCAL_OK:
            return codec.FLAG_MODE | busy, b""
        if code not in _ALWAYS and running:
            return busy, b""
        handler = _HANDLERS.get(code)
        if handler is None:
            return codec.FLAG_COMMAND | busy, b""
        try:
            return handler(self, p, now)
        except ValueError:  # wrong length, not hex, out of range
            return codec.FLAG_PARAMETER | busy, b""

    def _needs_pedestal(self, now: float) -> tuple[int, bytes] | None:
        if not self.camera_on:
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        if not self.pedestal_ready:
            # the manual (p30-52): a mode error, and the camera runs Pedestal Initialize 2
            self._start_init(now, home=False)
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        if not self.head.settled():
            return codec.FLAG_BUSY, b""
        return None

    def _cmd_power(self, p: bytes, now: float) -> tuple[int, bytes]:
        on = _choice(p, b"01") == 1
        self._busy_until = now + self.timing.power_seconds
        self._wait_head = False

        def done() -> None:
            self.camera_on = on

        self._after_busy = done
        return 0, b""

    def _cmd_mode(self, p: bytes, now: float) -> tuple[int, bytes]:
        self.host_mode = _choice(p, b"01") == 0
        return 0, b""

    def _cmd_init(self, p: bytes, now: float) -> tuple[int, bytes]:
        home = _choice(p, b"01") == 0
        if not self.camera_on:
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        if not self.head.settled():
            return codec.FLAG_BUSY, b""
        self._start_init(now, home)
        return 0, b""

    def _start_init(self, now: float, home: bool) -> None:
        back = self._position_counts()
        self.pedestal_ready = False
        self._busy_until = now + self.timing.init_seconds
        self._wait_head = True
        self._move(0, 0) if home else self._move(*back)

        def done() -> None:
            self.pedestal_ready = True

        self._after_busy = done

    def _cmd_home(self, p: bytes, now: float) -> tuple[int, bytes]:
        _length(p, 0)
        if (refused := self._needs_pedestal(now)) is not None:
            return refused
        self._move(0, 0)
        return 0, b""

    def _cmd_speed(self, p: bytes, now: float, pan: bool) -> tuple[int, bytes]:
        value = codec.parse_hex(_length(p, 3))
        top = codec.PAN_SPEED_MAX if pan else codec.TILT_SPEED_MAX
        if not codec.PAN_SPEED_MIN <= value <= top:
            raise ValueError(value)
        if pan:
            self.pan_speed = value
        else:
            self.tilt_speed = value
        return 0, b""

    def _cmd_speed_request(self, p: bytes, now: float) -> tuple[int, bytes]:
        value = self.tilt_speed if _choice(p, b"01") else self.pan_speed
        return 0, codec.hex_digits(value, 3)

    def _cmd_stop_or_start(self, p: bytes, now: float) -> tuple[int, bytes]:
        which = _choice(p, b"01234")
        if not self.camera_on or not self.pedestal_ready:
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        if which == 0:
            self.head.stop()
            return 0, b""
        pan, tilt = self._position_counts()
        pan = {1: self.pan_range[1], 2: self.pan_range[0]}.get(which, pan)
        tilt = {3: self.tilt_range[1], 4: self.tilt_range[0]}.get(which, tilt)
        self._move(pan, tilt)
        return 0, b""

    def _cmd_speed_limit(self, p: bytes, now: float) -> tuple[int, bytes]:
        values = (
            codec.PAN_SPEED_MIN,
            codec.PAN_SPEED_MAX,
            codec.TILT_SPEED_MIN,
            codec.TILT_SPEED_MAX,
        )
        return 0, codec.hex_digits(values[_choice(p, b"0123")], 3)

    def _cmd_pulse_ratio(self, p: bytes, now: float) -> tuple[int, bytes]:
        _choice(p, b"01")
        return 0, b"2BF2"

    def _cmd_angle_limit(self, p: bytes, now: float) -> tuple[int, bytes]:
        values = (*codec.PAN_RANGE, *codec.TILT_RANGE_MAX)
        return 0, codec.angle_digits(values[_choice(p, b"0123")])

    def _cmd_pan_tilt(self, p: bytes, now: float) -> tuple[int, bytes]:
        _length(p, 8)
        pan, tilt = codec.decode_pan_tilt(p)
        if (refused := self._needs_pedestal(now)) is not None:
            return refused
        if not (
            self.pan_range[0] <= pan <= self.pan_range[1]
            and self.tilt_range[0] <= tilt <= self.tilt_range[1]
        ):
            raise ValueError((pan, tilt))
        self._move(pan, tilt)
        return 0, b""

    def _cmd_position(self, p: bytes, now: float) -> tuple[int, bytes]:
        _length(p, 0)
        pan, tilt = self._position_counts()
        return 0, codec.angle_digits(pan) + codec.angle_digits(tilt)

    def _cmd_range(self, p: bytes, now: float) -> tuple[int, bytes]:
        _length(p, 9)
        tilt = _choice(p[:1], b"01") == 1
        low, high = codec.decode_pan_tilt(p[1:])
        bounds = codec.TILT_RANGE_MAX if tilt else codec.PAN_RANGE
        if not bounds[0] <= low <= high <= bounds[1]:
            raise ValueError((low, high))
        if tilt:
            self.tilt_range = (low, high)
        else:
            self.pan_range = (low, high)
        return 0, b""

    def _cmd_range_request(self, p: bytes, now: float) -> tuple[int, bytes]:
        low, high = self.tilt_range if _choice(p, b"01") else self.pan_range
        return 0, codec.angle_digits(low) + codec.angle_digits(high)

    def _cmd_status(self, p: bytes, now: float) -> tuple[int, bytes]:
        bits = self.operation_status(now)
        if p == b"":
            return 0, codec.hex_digits(bits & 0xFFF, 3)
        _choice(p, b"0")
        return 0, codec.hex_digits(bits, 5)

    def _cmd_product(self, p: bytes, now: float) -> tuple[int, bytes]:
        _length(p, 0)
        return 0, b"VC-C4"

    def _cmd_zoom_move(self, p: bytes, now: float) -> tuple[int, bytes]:
        which = _choice(p, b"01234")
        if not self.camera_on:
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        here = self.zoom_at(now)
        goal = {0: here, 1: 0, 3: 0, 2: self.zoom_max, 4: self.zoom_max}[which]
        self._zoom = (here, goal, now)
        return 0, b""

    def _cmd_zoom(self, p: bytes, now: float) -> tuple[int, bytes]:
        value = codec.parse_hex(_length(p, 4))
        if not self.camera_on:
            return codec.FLAG_MODE | codec.FLAG_BUSY, b""
        if self.zoom_at(now) != round(self._zoom[1]):
            return codec.FLAG_BUSY, b""
        if value > self.zoom_max:
            raise ValueError(value)
        self._zoom = (self.zoom_at(now), value, now)
        return 0, b""

    def _cmd_zoom_request(self, p: bytes, now: float) -> tuple[int, bytes]:
        if p[:1] == b"1":  # zoom speed set
            speed = codec.parse_hex(_length(p[1:], 1))
            if speed > 7:
                raise ValueError(speed)
            self.zoom_speed = speed
            return 0, b""
        which = _choice(p, b"023")
        if which == 0:
            return 0, codec.hex_digits(self.zoom_at(now), 4)
        if which == 1:
            return 0, codec.hex_digits(self.zoom_speed, 1)
        return 0, codec.hex_digits(self.zoom_max, 4)


def _length(p: bytes, n: int) -> bytes:
    if len(p) != n:
        raise ValueError(f"{len(p)} parameter bytes, not {n}")
    return p


def _choice(p: bytes, options: bytes) -> int:
    """The index of a one-digit parameter among ``options``; ValueError otherwise."""
    if len(p) != 1 or p[0] not in options:
        raise ValueError(p)
    return options.index(p[0])


_Handler = Callable[[VCC4Emulator, bytes, float], tuple[int, bytes]]
_HANDLERS: dict[int, _Handler] = {
    codec.POWER: VCC4Emulator._cmd_power,
    codec.CONTROL_MODE: VCC4Emulator._cmd_mode,
    codec.PEDESTAL_INIT: VCC4Emulator._cmd_init,
    codec.HOME: VCC4Emulator._cmd_home,
    codec.PAN_SPEED: lambda e, p, now: e._cmd_speed(p, now, True),
    codec.TILT_SPEED: lambda e, p, now: e._cmd_speed(p, now, False),
    codec.SPEED_REQUEST: VCC4Emulator._cmd_speed_request,
    codec.PAN_TILT_STOP: VCC4Emulator._cmd_stop_or_start,
    0x59: VCC4Emulator._cmd_speed_limit,
    0x5B: VCC4Emulator._cmd_pulse_ratio,
    0x5C: VCC4Emulator._cmd_angle_limit,
    codec.PAN_TILT: VCC4Emulator._cmd_pan_tilt,
    codec.PAN_TILT_REQUEST: VCC4Emulator._cmd_position,
    codec.RANGE_SET: VCC4Emulator._cmd_range,
    codec.RANGE_REQUEST: VCC4Emulator._cmd_range_request,
    codec.OPERATION_STATUS: VCC4Emulator._cmd_status,
    codec.PRODUCT_NAME: VCC4Emulator._cmd_product,
    codec.ZOOM_MOVE: VCC4Emulator._cmd_zoom_move,
    codec.ZOOM: VCC4Emulator._cmd_zoom,
    codec.ZOOM_REQUEST: VCC4Emulator._cmd_zoom_request,
}


# -- pseudo-terminal server ---------------------------------------------------------------------


def serve_vcc4(
    sim_or_head: Any,
    link: DeviceLine | None = None,
    *,
    clock: Clock = SYSTEM_CLOCK,
    **emulator_options: Any,
) -> LineServer:
    """Start an emulated VC-C4 on ``link`` (a new pseudo-terminal if None), moving
    ``sim_or_head``: a ``SimRobot`` (wrapped in ``SimHeadActuator``; keep a ``WorldRunner``
    stepping it) or a ``HeadActuator``. ``emulator_options`` go to ``VCC4Emulator``. Returns
    the running server (``.path`` for a pty, ``.link.transport()`` for a memory line)."""
    head = SimHeadActuator(sim_or_head) if hasattr(sim_or_head, "command_head") else sim_or_head
    line = link if link is not None else PtyLink()
    return LineServer(
        VCC4Emulator(head, **emulator_options), line, clock, name="vcc4-line", read_size=256
    )
