"""The PeopleBot's base over its ARCOS serial protocol, as a ``twin.core.devices.Base``.

``ArcosBase.open("/dev/ttyS0")`` returns an unconnected base; ``connect()`` (or ``with``) runs
the SYNC0/1/2 handshake (closing a robot left open by a crashed client first), OPENs the
servers, enables the motors and sends the motion limits. One background thread then reads
SIPs into odometry (x/y unwrapped from their 15-bit wrap, heading from 4096ths of a turn),
collects AUX bytes, and sends a PULSE whenever the line has been quiet for half a second, so
the robot's 2 s watchdog never trips while we are connected (specs/protocols.md, part B).

Motion is done by the firmware's own servos and checked on the SIP odometry: ``go_to`` turns
with HEAD, drives with MOVE and turns again, re-planning from the reported pose until it is
within 3 cm and 1 degree (the promise is 5 cm / 3 degrees); ``drive`` holds VEL and RVEL for a
duration on the driver's clock. A stall or bumper bit during motion stops the robot and raises
``DeviceFaultError``; a robot that stops sending SIPs is a ``DeviceTimeoutError`` within
``sip_timeout``; a vanished line is a ``ConnectionLostError`` unless ``auto_reconnect`` brings
it back. ``close()`` sends STOP, ENABLE 0 and CLOSE.

API units: metres, radians, seconds, map frame (``set_pose`` anchors the odometry to it; the
start pose given at construction anchors the first connection). Wire units (mm, mm/s, degrees)
are converted here. Every timeout, the keep-alive and the reader thread run on the injected
``clock`` (``twin.core.clock``), so tests drive them in virtual time.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable
from typing import TypeVar

from hardware.arcos_codec import (
    MAX_STRING,
    Command,
    PacketError,
    PacketParser,
    Sip,
    command,
    is_sip,
    parse_sip,
    parse_sync2,
    xy_delta,
)
from hardware.transport import FrameReader, SerialTransport, Transport
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.devices import (
    PIONEER_LIMITS,
    Base,
    BaseLimits,
    BumpedError,
    ConnectionLostError,
    DeviceError,
    DeviceFaultError,
    DeviceTimeoutError,
    OutOfRangeError,
    ProtocolError,
)
from twin.core.geometry import Pose2D, wrap_angle

INTER_BYTE_LIMIT = 0.1  # s of silence inside a packet before it counts as truncated (ARIA)
XY_TOLERANCE = 0.03  # m: closer than this, go_to only turns (as the sim's controller does)
YAW_TOLERANCE = math.radians(1.0)
ORIGIN = Pose2D(0.0, 0.0, 0.0)
AUX_PORTS = {1: (Command.TTY2, Command.GETAUX, 0xB0), 2: (66, 67, 0xB8), 3: (60, 61, 0xC8)}

T = TypeVar("T")


def _fmt(pose: Pose2D) -> str:
    return f"({pose.x:.3f}, {pose.y:.3f}) m, {math.degrees(pose.yaw):.1f} deg"


class _Odometry:
    """Continuous odometry (m, m, rad) from the SIP's wrapping x/y: only deltas are trusted."""

    def __init__(self, sip: Sip) -> None:
        self._raw = (sip.x, sip.y)
        self.x_mm = float(sip.x)
        self.y_mm = float(sip.y)
        self.yaw = sip.heading

    def update(self, sip: Sip) -> None:
        self.x_mm += xy_delta(self._raw[0], sip.x)
        self.y_mm += xy_delta(self._raw[1], sip.y)
        self._raw = (sip.x, sip.y)
        self.yaw = sip.heading

    @property
    def pose(self) -> Pose2D:
        return Pose2D(self.x_mm / 1000.0, self.y_mm / 1000.0, self.yaw)


class ArcosBase(Base):
    """An ARCOS/AROS robot base on any ``Transport`` (made by ``open_transport`` at connect,
    again at a reconnect). Timeouts, the keep-alive and ``drive``'s duration run on ``clock``
    (seconds), and so does the reader thread's waiting."""

    def __init__(
        self,
        open_transport: Callable[[], Transport],
        *,
        name: str = "ARCOS base",
        start: Pose2D = ORIGIN,
        limits: BaseLimits = PIONEER_LIMITS,
        reply_timeout: float = 1.0,
        sync_attempts: int = 6,
        sip_timeout: float = 2.0,
        pulse_period: float = 0.5,
        auto_reconnect: bool = True,
        reconnect_timeout: float = 5.0,
        enable_motors: bool = True,
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        self.name, self.clock = name, clock
        self.enable_motors = enable_motors
        self._open_transport = open_transport
        self.limits = limits
        self.reply_timeout, self.sync_attempts = reply_timeout, sync_attempts
        self.sip_timeout, self.pulse_period = sip_timeout, pulse_period
        self.sip_period_limit = 0.3  # s: a pose older than three SIP cycles is refreshed first
        self.auto_reconnect, self.reconnect_timeout = auto_reconnect, reconnect_timeout
        self._transport: Transport | None = None
        self._cond = clock.condition()
        self._write_lock = threading.Lock()
        self._stop_io = threading.Event()
        self._io: threading.Thread | None = None
        self._connected = False
        self._lost: DeviceError | None = None
        self._map_pose = start  # pose to anchor on the next first SIP
        self._anchor: tuple[Pose2D, Pose2D] | None = None  # (map pose, odometry pose)
        self._odometry: _Odometry | None = None
        self._aux: dict[int, bytearray] = {port: bytearray() for port in AUX_PORTS}
        self._last_write = 0.0
        self.identity: tuple[str, str, str] | None = None  # SYNC2: name, class, subclass
        self.last_sip: Sip | None = None
        self.sip_count = 0
        self._sip_time = 0.0
        self.protocol_errors = 0
        self.last_protocol_error: ProtocolError | None = None
        self.still_open_recoveries = 0
        self.reconnects = 0
        self._settle_from = 0

    @classmethod
    def open(cls, port: str, baudrate: int = 9600, **options: object) -> ArcosBase:
        """A base on serial port ``port`` (8N1, no flow control); ``options`` as for the
        constructor. Nothing is opened until ``connect()``."""
        name = str(options.pop("name", "ARCOS base"))
        clock: Clock = options.get("clock", SYSTEM_CLOCK)  # type: ignore[assignment]
        return cls(
            lambda: SerialTransport(port, baudrate, name, clock=clock),
            name=name,
            **options,  # type: ignore[arg-type]
        )

    # -- lifecycle ---------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self) -> None:
        if self._connected:
            return
        self._start_link()
        self._connected = True

    def identify(self) -> tuple[str, str, str]:
        """(name, class, subclass) from the SYNC handshake alone: the robot is not opened, so
        nothing moves and its firmware returns to waiting for a client (``twin hw probe``)."""
        if self._connected:
            assert self.identity is not None
            return self.identity
        transport = self._transport = self._open_transport()
        try:
            self._handshake(transport)
        finally:
            self._transport = None
            transport.close()
        assert self.identity is not None
        return self.identity

    def _start_link(self) -> None:
        transport = self._open_transport()
        self._transport, self._lost = transport, None
        opened = False
        try:
            self._handshake(transport)
            self._write(command(Command.OPEN, 1))
            opened = True
            with self._cond:
                self._odometry = None
                first, self._sip_time = self.sip_count, self.clock.now()
            self._stop_io.clear()
            self._io = self.clock.start_thread(
                lambda: self._io_loop(transport), name=f"{self.name} io"
            )
            self._await_sip(first, self.clock.now() + 2.0 * self.reply_timeout, "open the robot")
            lim = self.limits
            for cmd, value in (
                (Command.ENABLE, int(self.enable_motors)),
                (Command.SETV, lim.speed * 1000.0),
                (Command.SETA, lim.accel * 1000.0),
                (Command.SETA, -lim.accel * 1000.0),
                (Command.SETRV, math.degrees(lim.turn_rate)),
                (Command.SETRA, math.degrees(lim.turn_accel)),
                (Command.SETRA, -math.degrees(lim.turn_accel)),
            ):
                self._write(command(cmd, round(value)))
            if self.enable_motors:
                self._await_motors(self.clock.now() + 2.0 * self.reply_timeout)
        except BaseException:
            if opened and self._lost is None:  # leave no robot open behind a failed connect
                with contextlib.suppress(DeviceError):
                    self._write(command(Command.STOP))
                    self._write(command(Command.CLOSE, 1))
            self._stop_link()
            raise

    def _await_motors(self, deadline: float) -> None:
        """Wait for a SIP showing the motors enabled: ENABLE is not acknowledged otherwise."""
        with self._cond:
            seq = first = self.sip_count
        while True:
            try:
                sip = self._await_sip(seq, deadline, "enable the motors")
            except DeviceTimeoutError:
                if self.sip_count > first:  # SIPs come, but the motors stay off
                    raise DeviceFaultError(
                        self.name,
                        "enable the motors",
                        "the SIPs still show them off",
                        "release the robot's STOP button and check the motor power switch",
                    ) from None
                raise
            seq = self.sip_count
            if sip.motors_enabled:
                return

    def _stop_link(self) -> None:
        self._stop_io.set()
        if self._io is not None and self._io is not threading.current_thread():
            self.clock.join(self._io, 1.0)
        self._io = None
        if self._transport is not None:
            with contextlib.suppress(Exception):
                self._transport.close()
        self._transport = None

    def close(self) -> None:
        """STOP, ENABLE 0 and CLOSE (best effort: the line may be gone), then release it."""
        if self._transport is not None and self._lost is None:
            with contextlib.suppress(DeviceError):
                self._write(command(Command.STOP))
                self._write(command(Command.ENABLE, 0))
                self.clock.sleep(0.05)
                self._write(command(Command.CLOSE, 1))
                self.clock.sleep(0.05)
        self._stop_link()
        self._connected = False

    def reconnect(self) -> None:
        """Open the line again and redo the handshake (a robot still open from before is
        closed first); odometry continues from the last pose."""
        with self._cond:
            if self._anchor is not None and self._odometry is not None:
                self._map_pose = self._map_pose_now()
        self._stop_link()
        end = self.clock.now() + self.reconnect_timeout
        while True:
            try:
                self._start_link()
                break
            except (ConnectionLostError, DeviceTimeoutError, ProtocolError):
                if self.clock.now() > end:
                    raise
            except DeviceError:  # the port is not back yet (replugged device, new pty)
                if self.clock.now() > end:
                    raise
            self.clock.sleep(0.2)
        self.reconnects += 1

    # -- wire --------------------------------------------------------------------------------
    def _write(self, packet: bytes) -> None:
        transport = self._transport
        if transport is None:
            raise ConnectionLostError(
                self.name, "send a command", "the line is closed", "connect first"
            )
        with self._write_lock:
            try:
                transport.write(packet)
            except ConnectionLostError as exc:
                # the caller may notice a vanished line before the reader thread does: record
                # it here too, so the next call reconnects instead of writing into the void
                with self._cond:
                    if self._lost is None and transport is self._transport:
                        self._lost = ConnectionLostError(
                            self.name,
                            "send a command",
                            exc.seen,
                            "check the cable; reconnect() opens the line again",
                        )
                    self._cond.notify_all()
                raise
            self._last_write = self.clock.now()

    def send(self, cmd: int, arg: int | bytes | None = None) -> None:
        """Send one raw ARCOS command (number from ``Command``; int in wire units)."""
        self._require_link(f"send command {cmd}")
        self._write(command(cmd, arg))

    def _frame_reader(self) -> FrameReader:
        """A reader of the line's packets from scratch (a new parser)."""
        return FrameReader(
            PacketParser(), self.clock.now, (PacketError,), self._note_error, INTER_BYTE_LIMIT
        )

    def _protocol_error(self, exc: PacketError) -> ProtocolError:
        return ProtocolError(self.name, exc.doing, exc.seen, exc.remedy)

    def _note_error(self, exc: PacketError) -> None:
        """Count a packet the line garbled: ARCOS links drop one now and then, so it is kept
        for ``hw arcos status`` and tests rather than raised."""
        self.protocol_errors += 1
        self.last_protocol_error = self._protocol_error(exc)

    def _handshake(self, transport: Transport) -> None:
        """SYNC0, SYNC1, SYNC2 with replies echoed; any surprise restarts at SYNC0. SIPs in
        reply mean a robot still open from an earlier client: CLOSE it, wait, resync."""
        reader = self._frame_reader()
        transport.reset_input()
        step = attempts = 0
        while step < 3:
            if attempts >= self.sync_attempts:
                raise DeviceTimeoutError(
                    self.name,
                    f"SYNC{step} handshake",
                    f"no proper reply in {attempts} tries of {self.reply_timeout:g} s",
                    "check power, cable and baud rate (9600)",
                )
            attempts += 1
            self._write(command(step))
            reply = reader.next_before(transport, self.clock.now() + self.reply_timeout)
            if reply is None:
                step = 0
            elif is_sip(reply):
                self.still_open_recoveries += 1
                self._write(command(Command.CLOSE, 1))
                self.clock.sleep(0.4)
                transport.reset_input()
                reader = self._frame_reader()
                step = 0
            elif reply[0] == step:
                if step == 2:
                    try:
                        self.identity = parse_sync2(reply)
                    except PacketError as exc:
                        raise self._protocol_error(exc) from None
                step += 1
            else:
                step = 0

    def _io_loop(self, transport: Transport) -> None:
        reader = self._frame_reader()
        while not self._stop_io.is_set():
            try:
                reader.read(transport)
                if self.clock.now() - self._last_write >= self.pulse_period:
                    self._write(command(Command.PULSE))
            except DeviceError as exc:
                with self._cond:
                    self._lost = ConnectionLostError(
                        self.name,
                        "read the robot's packets",
                        exc.seen,
                        "check the cable; reconnect() opens the line again",
                    )
                    self._cond.notify_all()
                return
            now = self.clock.now()
            for packet in reader.frames():
                self._dispatch(packet, now)

    def _dispatch(self, packet: bytes, now: float) -> None:
        if is_sip(packet):
            try:
                sip = parse_sip(packet)
            except PacketError as exc:
                self._note_error(exc)
                return
            with self._cond:
                if self._odometry is None:
                    self._odometry = _Odometry(sip)
                    self._anchor = (self._map_pose, self._odometry.pose)
                else:
                    self._odometry.update(sip)
                self.last_sip, self._sip_time = sip, now
                self.sip_count += 1
                self._cond.notify_all()
            return
        for port, (_, _, kind) in AUX_PORTS.items():
            if packet[0] == kind:
                with self._cond:
                    self._aux[port] += packet[1:]
                    self._cond.notify_all()

    # -- waiting on SIPs -----------------------------------------------------------------------
    def _require_link(self, asked: str) -> None:
        self.require_connected(asked)
        if self._lost is not None:
            if not self.auto_reconnect:
                raise self._lost
            try:
                self.reconnect()
            except DeviceError as exc:
                raise ConnectionLostError(
                    self.name,
                    asked,
                    f"the line was lost and reconnecting failed ({exc.seen})",
                    "check the cable and the robot's power",
                ) from None

    def _await_sip(self, after: int, deadline: float, asked: str) -> Sip:
        """The first SIP numbered above ``after``; typed errors on silence or a lost line."""
        began = self.clock.now()
        with self._cond:
            while self.sip_count <= after or self.last_sip is None:
                if self._lost is not None:
                    raise self._lost
                now = self.clock.now()
                # silence counts from when we began waiting too: a reader thread starved of
                # the GIL by a long computation gets a full timeout to catch up
                if now - max(self._sip_time, began) > self.sip_timeout:
                    raise DeviceTimeoutError(
                        self.name,
                        asked,
                        f"no SIP from the robot for {self.sip_timeout:g} s",
                        "check the cable, the robot's power and that nothing else holds the line",
                    )
                if now >= deadline:
                    raise DeviceTimeoutError(
                        self.name,
                        asked,
                        "not finished in time",
                        "allow more time or check the path",
                    )
                self._cond.wait(min(deadline - now, 0.05))
            return self.last_sip

    def _map_pose_now(self) -> Pose2D:
        assert self._anchor is not None and self._odometry is not None
        map_anchor, odom_anchor = self._anchor
        return map_anchor.compose(odom_anchor.relative(self._odometry.pose))

    def _odometry_heading(self, map_yaw: float) -> float:
        """A map-frame yaw as a heading in the robot's odometry frame (rad)."""
        assert self._anchor is not None
        map_anchor, odom_anchor = self._anchor
        return float(wrap_angle(map_yaw - map_anchor.yaw + odom_anchor.yaw))

    # -- Base ---------------------------------------------------------------------------------
    def pose(self) -> Pose2D:
        self._require_link("read the pose")
        with self._cond:
            stale = self.clock.now() - self._sip_time > self.sip_period_limit
            seq = self.sip_count
        if stale:  # the pose must be current: wait for the next SIP (or a typed error)
            self._await_sip(seq, self.clock.now() + self.sip_timeout, "read the pose")
        with self._cond:
            if self._lost is not None:
                raise self._lost
            return self._map_pose_now()

    def set_pose(self, pose: Pose2D) -> None:
        self._require_link(f"set the pose to {_fmt(pose)}")
        with self._cond:
            assert self._odometry is not None
            self._anchor = (pose, self._odometry.pose)
            self._map_pose = pose

    def stop(self) -> None:
        self._require_link("stop")
        self._write(command(Command.STOP))

    def _check_fault(self, sip: Sip, asked: str) -> None:
        fault = sip.fault()
        if fault is not None:
            with contextlib.suppress(DeviceError):
                self._write(command(Command.STOP))
            args = (
                self.name,
                asked,
                f"{fault} at odometry {_fmt(self._map_pose_now())}",
                "clear the obstacle; choose a stop with a free path",
            )
            front, rear = bool(sip.front_bumpers), bool(sip.rear_bumpers)
            if front != rear:  # one bank pressed: the obstacle is ahead, or behind
                raise BumpedError(*args, bearing=0.0 if front else math.pi)
            raise DeviceFaultError(*args)  # a stall, or both banks: no side to tell

    def _settle(self, deadline: float, asked: str) -> Pose2D:
        """Wait until the firmware reports the motion done (a 'stopped' SIP generated after
        the command), raising on faults, silence or the deadline."""
        with self._cond:
            seq = self.sip_count
        while True:
            sip = self._await_sip(seq, deadline, asked)
            seq = self.sip_count
            self._check_fault(sip, asked)
            if seq >= self._settle_from and not sip.moving:
                with self._cond:
                    return self._map_pose_now()

    def _command_then_settle(self, packet: bytes, deadline: float, asked: str) -> Pose2D:
        with self._cond:
            # SIPs in flight when the command goes out may predate it: skip two
            self._settle_from = self.sip_count + 2
        self._write(packet)
        return self._settle(deadline, asked)

    def _turn_to(self, map_yaw: float, deadline: float, asked: str) -> Pose2D:
        degrees = round(math.degrees(self._odometry_heading(map_yaw))) % 360
        return self._command_then_settle(command(Command.HEAD, degrees), deadline, asked)

    def go_to(self, goal: Pose2D, *, timeout: float = 60.0) -> Pose2D:
        asked = f"go to {_fmt(goal)}"
        deadline = self.clock.now() + timeout
        reconnects = 0
        for _ in range(12):
            self._require_link(asked)
            try:
                pose = self.pose()
                dist = pose.distance_to(goal)
                if dist > XY_TOLERANCE:
                    bearing = math.atan2(goal.y - pose.y, goal.x - pose.x)
                    if abs(wrap_angle(bearing - pose.yaw)) > YAW_TOLERANCE:
                        pose = self._turn_to(bearing, deadline, asked)
                    along = (goal.x - pose.x) * math.cos(pose.yaw) + (goal.y - pose.y) * math.sin(
                        pose.yaw
                    )
                    mm = max(-30000, min(30000, round(along * 1000.0)))
                    self._command_then_settle(command(Command.MOVE, mm), deadline, asked)
                elif abs(pose.heading_error_to(goal)) > YAW_TOLERANCE:
                    self._turn_to(goal.yaw, deadline, asked)
                else:
                    return pose
            except ConnectionLostError:
                reconnects += 1
                if not self.auto_reconnect or reconnects > 2:
                    raise
                self._require_link(asked)
            except DeviceTimeoutError:
                with contextlib.suppress(DeviceError):
                    self._write(command(Command.STOP))
                raise
        pose = self.pose()
        raise DeviceTimeoutError(
            self.name,
            asked,
            f"still {100 * pose.distance_to(goal):.1f} cm"
            f" and {abs(math.degrees(pose.heading_error_to(goal))):.1f} deg "
            "away after 12 corrections",
            "check wheel slip and the path",
        )

    def drive(self, speed: float, turn_rate: float, duration: float) -> Pose2D:
        asked = f"drive {speed:.3f} m/s, {turn_rate:.3f} rad/s for {duration:g} s"
        self.limits.check_drive(self.name, speed, turn_rate, duration)
        self._require_link(asked)
        clock = self.clock
        start = clock.now()
        end = start + duration
        with self._cond:
            seq = self.sip_count
        try:
            self._write(command(Command.VEL, round(speed * 1000.0)))
            self._write(command(Command.RVEL, round(math.degrees(turn_rate))))
            while clock.now() < end:
                sip = self._await_sip(seq, end + self.sip_timeout, asked)
                seq = self.sip_count
                if clock.now() - start > 0.25:  # SIPs from before VEL may still show a stall
                    self._check_fault(sip, asked)
        finally:
            with contextlib.suppress(DeviceError):
                self._write(command(Command.STOP))
        return self._command_then_settle(command(Command.STOP), clock.now() + 5.0, asked)

    # -- AUX port ------------------------------------------------------------------------------
    def aux_transport(self, port: int = 1) -> ArcosAuxTransport:
        """A ``Transport`` to the device on the robot's AUX ``port`` (1..3): writes go out in
        TTY2 (TTY3/TTY4) packets, reads ask with GETAUX and collect SERAUX answers."""
        if port not in AUX_PORTS:
            raise OutOfRangeError(self.name, f"open AUX{port}", "no such port", "use 1, 2 or 3")
        return ArcosAuxTransport(self, port)


class ArcosAuxTransport:
    """Bytes through the robot's AUX port. ARCOS answers GETAUX n only once n bytes have come
    in (section A10), so a read asks for what it still needs and, when that goes unanswered
    for ``probe`` seconds, for one byte at a time: short answers still get through."""

    def __init__(self, base: ArcosBase, port: int, probe: float = 0.15) -> None:
        self.base, self.port, self.probe = base, port, probe
        self.name = f"{base.name} AUX{port}"
        self._tty, self._getaux, _ = AUX_PORTS[port]
        self._closed = False

    def _check(self, asked: str) -> None:
        if self._closed:
            raise ConnectionLostError(
                self.name,
                asked,
                "the AUX transport is closed",
                "take a new one from ArcosBase.aux_transport()",
            )
        self.base._require_link(asked)

    def _recovering(self, operation: Callable[[], T]) -> T:
        """Run ``operation``; if the base's line was lost meanwhile, reconnect it (when the base
        does so for its own calls) and run it once more, so a device on the AUX port rides
        through a replugged cable exactly as the base does."""
        try:
            return operation()
        except ConnectionLostError:
            if self._closed or not self.base.auto_reconnect:
                raise
            self.base._lost = self.base._lost or ConnectionLostError(
                self.name, "use the AUX port", "the line went away", "reconnecting"
            )
            self.base._require_link("reconnect for the AUX port")
            return operation()

    def write(self, data: bytes) -> None:
        self._check(f"write {len(data)} bytes")

        def send() -> None:
            for i in range(0, len(data), MAX_STRING):
                self.base._write(command(self._tty, bytes(data[i : i + MAX_STRING])))

        self._recovering(send)

    def _take(self, size: int) -> bytes:
        buf = self.base._aux[self.port]
        out = bytes(buf[:size])
        del buf[:size]
        return out

    def read(self, size: int, timeout: float) -> bytes:
        self._check(f"read {size} bytes")
        return self._recovering(lambda: self._read(size, timeout))

    def _read(self, size: int, timeout: float) -> bytes:
        base = self.base
        clock = base.clock
        end = clock.now() + timeout
        with base._cond:
            out = self._take(size)
        one_at_a_time = False
        while len(out) < size:
            now = clock.now()
            if now >= end:
                break
            want = 1 if one_at_a_time else min(size - len(out), MAX_STRING)
            base._write(command(self._getaux, want))
            with base._cond:
                wait_end = min(end, now + self.probe)
                while not base._aux[self.port] and base._lost is None:
                    left = wait_end - clock.now()
                    if left <= 0:
                        break
                    base._cond.wait(left)
                if base._lost is not None:
                    raise base._lost
                got = self._take(size - len(out))
            if got:
                out += got
            else:
                one_at_a_time = True
        return out

    def reset_input(self) -> None:
        self._check("flush")

        def flush() -> None:
            self.base._write(command(self._getaux, 0))
            with self.base._cond:
                self.base._aux[self.port].clear()

        self._recovering(flush)

    def close(self) -> None:
        self._closed = True
