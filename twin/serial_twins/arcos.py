"""An emulated ARCOS robot controller (PeopleBot SH) on a pseudo-terminal.

``ArcosEmulator`` is the firmware: it parses client packets, runs the SYNC handshake, streams
SIPs every 100 ms once open, and turns motion commands (VEL, RVEL, VEL2, HEAD, DHEAD, MOVE,
STOP, with the SETV/SETA/SETRV/SETRA limits) into body velocities for a ``DriveActuator``; a
2 s watchdog halts the wheels when the client falls silent and resumes the motion when it
speaks again (specs/protocols.md, B4.3 and part D). Bytes for AUX1 (TTY2) go to an optional
``ByteDevice`` (the emulated VC-C4) and its answers come back in SERAUX packets on GETAUX
(section A10).

The actuator is the emulator's only view of the robot: ``SimActuator`` drives the MuJoCo
robot's wheels (under its lock) and reads its wheel odometry; ``KinematicActuator`` integrates
ideal unicycle motion for unit tests. ``serve_arcos`` runs an emulator on a line (a
``PtyLink``, or a ``MemoryLink`` for tests in virtual time) in a thread timed by a ``Clock``
and returns a handle with ``.path`` (or ``.link.transport()``) for the driver.

Wire units (mm, mm/s, degrees, 4096ths of a turn) stay in this module and the codec; the
actuator speaks metres, radians and seconds.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from hardware.arcos_codec import (
    ANGLE_UNITS,
    SERAUX,
    Command,
    PacketError,
    PacketParser,
    Sip,
    SipExtension,
    encode_sip,
    frame,
    parse_command,
    sync2_reply,
    vel2_wheels,
)
from twin.core.clock import SYSTEM_CLOCK, Clock
from twin.core.geometry import wrap_angle
from twin.serial_twins.bytedevice import ByteDevice, DeviceLine, LineServer
from twin.serial_twins.pty import PtyLink

if TYPE_CHECKING:
    from twin.sim.robot import SimRobot

# ARCOS-like firmware defaults (mm, mm/s, mm/s^2, deg/s, deg/s^2): gentle indoor values.
DEFAULT_MAX_VEL = 750.0
DEFAULT_ACCEL = 300.0
DEFAULT_MAX_ROTVEL = 100.0
DEFAULT_ROT_ACCEL = 150.0
TOP_VEL = 2200.0  # PeopleBot MaxVelocity, mm/s (section B7)
TOP_ROTVEL = 500.0  # deg/s
PEOPLEBOT_TRACK = 0.333  # m: from DiffConvFactor 0.006 (rad/s per mm/s of half the difference)
MOVE_DONE_MM = 3.0
HEAD_DONE_DEG = 0.3


# -- the robot as the firmware sees it -----------------------------------------------------------


@dataclass(frozen=True)
class DriveFaults:
    """Motor stalls and bumper contacts (bit i of a bank = bumper segment i)."""

    left_stall: bool = False
    right_stall: bool = False
    front_bumpers: int = 0
    rear_bumpers: int = 0

    def word(self) -> int:
        """The SIP's STALL AND BUMPERS word (section B6)."""
        return (
            int(self.left_stall)
            | (self.rear_bumpers & 0x7F) << 1
            | int(self.right_stall) << 8
            | (self.front_bumpers & 0x7F) << 9
        )


class DriveActuator(Protocol):
    """What the firmware commands and reads. ``clock`` is the robot's time in seconds (sim
    time for the twin), ``odometry`` the wheel-odometry pose (m, m, rad) in the robot's own
    frame, which starts at (0, 0, 0) when the actuator is made."""

    track: float  # m between the wheels, for VEL2 and the SIP's wheel speeds

    def clock(self) -> float: ...

    def set_velocity(self, v: float, omega: float) -> None:
        """Body speed (m/s, forward positive) and turn rate (rad/s, CCW positive)."""
        ...

    def odometry(self) -> tuple[float, float, float]: ...

    def faults(self) -> DriveFaults: ...


class KinematicActuator:
    """An ideal unicycle for unit tests, on its own clock: ``clock`` time x ``time_scale``
    since it was made; set ``stalled``/``front_bumpers`` to inject faults."""

    track = PEOPLEBOT_TRACK

    def __init__(
        self,
        time_scale: float = 1.0,
        start: tuple[float, float, float] = (0.0, 0.0, 0.0),
        clock: Clock = SYSTEM_CLOCK,
    ) -> None:
        self.time_scale, self._clock = time_scale, clock
        self._t0 = clock.now()
        self._last = 0.0
        self._pose = start  # m, m, rad: e.g. near the SIP's 32.767 m wrap for tests
        self._vel = (0.0, 0.0)
        self._lock = threading.Lock()
        self.stalled = False
        self.front_bumpers = 0

    def clock(self) -> float:
        return (self._clock.now() - self._t0) * self.time_scale

    def _advance(self) -> None:
        now = self.clock()
        dt, self._last = now - self._last, now
        v, w = self._vel
        x, y, th = self._pose
        if abs(w) < 1e-9:
            x, y = x + v * dt * math.cos(th), y + v * dt * math.sin(th)
        else:
            x += v / w * (math.sin(th + w * dt) - math.sin(th))
            y -= v / w * (math.cos(th + w * dt) - math.cos(th))
        self._pose = (x, y, th + w * dt)

    def set_velocity(self, v: float, omega: float) -> None:
        with self._lock:
            self._advance()
            self._vel = (0.0, 0.0) if self.stalled else (v, omega)

    def odometry(self) -> tuple[float, float, float]:
        with self._lock:
            self._advance()
            return self._pose

    @property
    def velocity(self) -> tuple[float, float]:
        """The commanded (m/s, rad/s)."""
        return self._vel

    def faults(self) -> DriveFaults:
        return DriveFaults(self.stalled, self.stalled, self.front_bumpers, 0)


class SimActuator:
    """The MuJoCo robot's wheels and wheel odometry, touched only under ``sim.lock``.

    A wheel stalls as the sim base's own check decides (``drive.StallMonitor`` on the motor
    torque: the wheels slip against furniture, so odometry alone would not tell), and a contact
    between the robot and the scene presses the bumper segment facing it, as on the Peoplebot.
    """

    def __init__(self, sim: SimRobot) -> None:
        import mujoco

        from twin.sim.drive import StallMonitor
        from twin.sim.robot import STALL_DUTY, STALL_TIME, STALL_TORQUE

        self.sim = sim
        self.track = sim.geometry.track
        self._stall = StallMonitor(STALL_TORQUE, STALL_TIME, STALL_DUTY)
        model = sim.world.model
        self._wheel_act = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n)
            for n in ("left_wheel", "right_wheel")
        ]
        with sim.lock:
            self._origin = sim.odometry_pose()

    def clock(self) -> float:
        with self.sim.lock:
            return self.sim.world.time

    def set_velocity(self, v: float, omega: float) -> None:
        with self.sim.lock:
            self.sim.set_wheel_speeds(v, omega)

    def odometry(self) -> tuple[float, float, float]:
        with self.sim.lock:
            pose = self.sim.odometry_pose()
        o = self._origin
        dx, dy = pose.x - o.x, pose.y - o.y
        c, s = math.cos(o.yaw), math.sin(o.yaw)
        return c * dx + s * dy, -s * dx + c * dy, pose.yaw - o.yaw

    def faults(self) -> DriveFaults:
        with self.sim.lock:
            now = self.sim.world.time
            torque = [float(self.sim.world.data.actuator_force[a]) for a in self._wheel_act]
            contacts = self.sim.contacts()
            truth = self.sim.truth_pose()
        left, right = self._stall.update(now, *torque)
        front = rear = 0
        for contact in contacts:
            x, y, _ = contact.position
            bearing = float(wrap_angle(math.atan2(y - truth.y, x - truth.x) - truth.yaw))
            if abs(bearing) <= math.pi / 2:  # five front segments, right to left
                front |= 1 << _segment(bearing)
            else:  # five rear segments, left to right as seen from behind
                rear |= 1 << _segment(float(wrap_angle(bearing - math.pi)))
        return DriveFaults(left, right, front, rear)


def _segment(bearing: float) -> int:
    """Which of a bumper's five segments (0 = rightmost) faces ``bearing`` (rad, -pi/2..pi/2)."""
    return max(0, min(4, int((bearing + math.pi / 2) / (math.pi / 5))))


# -- the firmware ---------------------------------------------------------------------------------


def _approach(error: float, vmax: float, decel: float, gain: float) -> float:
    """Speed toward zero error: capped, able to stop in time, proportional at the end."""
    mag = min(vmax, math.sqrt(2.0 * decel * abs(error)), gain * abs(error))
    return math.copysign(mag, error)


def _ramp(current: float, target: float, accel: float, decel: float, dt: float) -> float:
    speeding_up = abs(target) > abs(current) and target * current >= 0.0
    step = (accel if speeding_up else decel) * dt
    return min(max(target, current - step), current + step)


def _wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


@dataclass
class Faults:
    """Fault-injection knobs for tests: applied to the next packets the emulator sends."""

    junk: bytes = b""  # sent once, before the next packet
    bad_checksum: int = 0  # this many next packets carry a wrong checksum
    truncate: int = 0  # this many next packets are cut in half
    mute: bool = False  # stop answering: ignore the client and send nothing


class ArcosEmulator:
    """The firmware state machine; feed it bytes with ``receive``, call ``tick`` often, and
    send what ``transmit`` returns. Times ``now`` are the server's clock seconds (SIP cycle and
    watchdog run on it, like a real controller's on its crystal; motion runs on the actuator's
    clock, which for the twin is the simulated world's)."""

    def __init__(
        self,
        actuator: DriveActuator,
        aux1: ByteDevice | None = None,
        *,
        name: str = "twin",
        robot_class: str = "Pioneer",
        subclass: str = "peoplebot-sh",
        sip_period: float = 0.1,
        watchdog: float = 2.0,
        battery: float = 12.6,
    ) -> None:
        self.actuator, self.aux1 = actuator, aux1
        self.identity = (name, robot_class, subclass)
        self.sip_period, self.watchdog, self.battery = sip_period, watchdog, battery
        self.faults = Faults()
        self._parser = PacketParser(max_count=204)
        self._out = bytearray()
        self.state = "waiting"  # waiting, sync0, sync1, synced, open
        self.motors_enabled = False
        self.sonar_on = False
        self.max_vel, self.accel, self.decel = DEFAULT_MAX_VEL, DEFAULT_ACCEL, DEFAULT_ACCEL
        self.max_rotvel = DEFAULT_MAX_ROTVEL
        self.rot_accel = self.rot_decel = DEFAULT_ROT_ACCEL
        self._trans: tuple[str, float] = ("vel", 0.0)  # ("vel", mm/s) or ("move", target mm)
        self._rot: tuple[str, float] = ("vel", 0.0)  # ("vel", deg/s) or ("head", deg)
        self._move_from = (0.0, 0.0, 0.0)
        self._head_settled = True
        self._v = self._w = 0.0  # commanded body speeds now, mm/s and deg/s
        self._origin = (0.0, 0.0, 0.0)  # SETO: the odometry frame's origin in actuator frame
        self._last_clock = actuator.clock()
        self._last_command = 0.0  # set by OPEN before the watchdog can look at it
        self._next_sip = 0.0
        self.watchdog_tripped = False
        self._aux_in = bytearray()
        self._aux_want = 0
        # counters for tests and benchmarks
        self.sips_sent = 0
        self.bad_packets = 0
        self.commands: list[tuple[int, int | bytes | None]] = []

    # -- byte interface --
    def receive(self, data: bytes, now: float) -> None:
        if self.faults.mute or not data:
            return
        self._parser.feed(data)
        while True:
            try:
                packet = self._parser.next()
            except PacketError:
                self.bad_packets += 1  # ARCOS ignores bad packets (section B2)
                continue
            if packet is None:
                return
            try:
                cmd = parse_command(packet)
            except PacketError:
                self.bad_packets += 1
                continue
            self._last_command = now
            self.commands.append((cmd.number, cmd.arg))
            del self.commands[:-200]
            self._handle(cmd.number, cmd.arg, now)

    def transmit(self, now: float) -> bytes:
        if self.faults.mute:
            self._out.clear()
            return b""
        out, self._out = bytes(self._out), bytearray()
        return out

    def _send(self, packet: bytes) -> None:
        f = self.faults
        if f.junk:
            self._out += f.junk
            f.junk = b""
        if f.bad_checksum > 0:
            f.bad_checksum -= 1
            packet = packet[:-1] + bytes([packet[-1] ^ 0x5A])
        elif f.truncate > 0:
            f.truncate -= 1
            packet = packet[: len(packet) // 2]
        self._out += packet

    # -- commands --
    def _handle(self, number: int, arg: int | bytes | None, now: float) -> None:
        if self.state != "open":
            self._handle_sync(number, arg, now)
            return
        value = arg if isinstance(arg, int) else 0
        match number:
            case Command.PULSE | Command.OPEN:
                pass  # a SYNC0 while open is a PULSE: the SIPs tell the client we are open
            case Command.CLOSE:
                self._close()
            case Command.ENABLE:
                self.motors_enabled = bool(value)
                if not self.motors_enabled:
                    self._halt()
            case Command.SETA:
                if value > 0:
                    self.accel = float(value)
                elif value < 0:
                    self.decel = float(-value)
            case Command.SETV:
                self.max_vel = float(min(max(value, 0), TOP_VEL))
            case Command.SETRV:
                self.max_rotvel = float(min(max(value, 0), TOP_ROTVEL))
            case Command.SETRA:
                if value > 0:
                    self.rot_accel = float(value)
                elif value < 0:
                    self.rot_decel = float(-value)
            case Command.SETO:
                self._origin = self.actuator.odometry()
            case Command.STOP:
                self._trans, self._rot = ("vel", 0.0), ("vel", 0.0)
            case Command.ESTOP:
                self._halt()
            case Command.SONAR:
                self.sonar_on = bool(value)
            case Command.TTY2:
                if self.aux1 is not None and isinstance(arg, bytes):
                    self.aux1.receive(arg, now)
            case Command.GETAUX:
                if value == 0:
                    self._pump_aux(now)
                    self._aux_in.clear()
                self._aux_want = max(0, min(value, 200))
            case _ if self.motors_enabled:
                self._motion(number, value)

    def _motion(self, number: int, value: int) -> None:
        match number:
            case Command.VEL:
                self._trans = ("vel", float(value))
            case Command.MOVE:
                self._move_from = self._pose()
                self._trans = ("move", float(value))
            case Command.RVEL | Command.ROTATE:
                self._rot = ("vel", float(value))
            case Command.HEAD:
                self._rot, self._head_settled = ("head", float(value)), False
            case Command.DHEAD:
                self._rot = ("head", math.degrees(self._pose()[2]) + value)
                self._head_settled = False
            case Command.VEL2:
                left, right = vel2_wheels(value)
                track_mm = self.actuator.track * 1000.0
                self._trans = ("vel", 0.5 * (left + right))
                self._rot = ("vel", math.degrees((right - left) / track_mm))

    def _handle_sync(self, number: int, arg: int | bytes | None, now: float) -> None:
        # SYNC1 and OPEN share a number, as do SYNC2 and CLOSE: the state tells them apart,
        # and out-of-order SYNCs are followed like MobileSim does.
        if number == Command.SYNC0:
            self.state = "sync0"
            self._send(frame(b"\x00"))
        elif number == 1 and (self.state == "synced" or arg is not None):
            self._open(now)
        elif number == Command.SYNC1:
            self.state = "sync1"
            self._send(frame(b"\x01"))
        elif number == 2 and self.state in ("sync1", "synced") and arg is None:
            self.state = "synced"
            self._send(sync2_reply(*self.identity))
        elif number == Command.CLOSE:
            self.state = "waiting"

    def _open(self, now: float) -> None:
        self.state = "open"
        self.motors_enabled = False
        self._halt()
        self._next_sip = now + self.sip_period

    def _close(self) -> None:
        self.state = "waiting"
        self.motors_enabled = False
        self._halt()

    def _halt(self) -> None:
        self._trans, self._rot = ("vel", 0.0), ("vel", 0.0)
        self._v = self._w = 0.0
        self.actuator.set_velocity(0.0, 0.0)

    # -- time --
    def _pose(self) -> tuple[float, float, float]:
        """Odometry in the SETO frame: mm, mm, rad."""
        x, y, th = self.actuator.odometry()
        ox, oy, oth = self._origin
        c, s = math.cos(oth), math.sin(oth)
        dx, dy = x - ox, y - oy
        return 1000.0 * (c * dx + s * dy), 1000.0 * (-s * dx + c * dy), th - oth

    def tick(self, now: float) -> None:
        """Run the motion servos, the watchdog, the AUX pump and the SIP clock."""
        clock = self.actuator.clock()
        dt, self._last_clock = max(0.0, clock - self._last_clock), clock
        if self.state == "open":
            silent = now - self._last_command > self.watchdog
            if silent and not self.watchdog_tripped:
                self.watchdog_tripped = True
                self._v = self._w = 0.0
                self.actuator.set_velocity(0.0, 0.0)
            elif not silent:
                self.watchdog_tripped = False  # traffic is back: resume the old motion
                if self.motors_enabled:
                    self._servo(dt)
            self._pump_aux(now)
            if now >= self._next_sip:
                self._next_sip = max(self._next_sip + self.sip_period, now - self.sip_period)
                self._send(encode_sip(self.sip()))
                self.sips_sent += 1

    def _servo(self, dt: float) -> None:
        x, y, th = self._pose()
        kind, target = self._trans
        if kind == "move":
            x0, y0, th0 = self._move_from
            remaining = target - ((x - x0) * math.cos(th0) + (y - y0) * math.sin(th0))
            if abs(remaining) < MOVE_DONE_MM and abs(self._v) < 20.0:
                self._trans, want_v = ("vel", 0.0), 0.0
            else:
                want_v = _approach(remaining, self.max_vel, 0.8 * self.decel, 3.0)
        else:
            want_v = max(-self.max_vel, min(self.max_vel, target))
        kind, target = self._rot
        if kind == "head":
            err = _wrap_deg(target - math.degrees(th))
            self._head_settled = abs(err) < HEAD_DONE_DEG and abs(self._w) < 5.0
            if self._head_settled:
                want_w = 0.0
            else:
                want_w = _approach(err, self.max_rotvel, 0.8 * self.rot_decel, 4.0)
        else:
            want_w = max(-self.max_rotvel, min(self.max_rotvel, target))
        self._v = _ramp(self._v, want_v, self.accel, self.decel, dt)
        self._w = _ramp(self._w, want_w, self.rot_accel, self.rot_decel, dt)
        self.actuator.set_velocity(self._v / 1000.0, math.radians(self._w))

    def _pump_aux(self, now: float) -> None:
        if self.aux1 is None:
            return
        self._aux_in += self.aux1.transmit(now)
        # ARCOS answers GETAUX n once n bytes are there (section A10)
        if self._aux_want and len(self._aux_in) >= self._aux_want:
            n, self._aux_want = self._aux_want, 0
            self._send(frame(bytes([SERAUX]) + bytes(self._aux_in[:n])))
            del self._aux_in[:n]

    def moving(self) -> bool:
        return (
            abs(self._v) > 0.5
            or abs(self._w) > 0.05
            or self._trans[0] == "move"
            or (self._rot[0] == "head" and not self._head_settled)
        )

    def sip(self) -> Sip:
        x, y, th = self._pose()
        track_mm = self.actuator.track * 1000.0
        half = 0.5 * track_mm * math.radians(self._w)
        flags = int(self.motors_enabled) | (0x1E if self.sonar_on else 0)
        th_units = round(th / (2.0 * math.pi) * ANGLE_UNITS) % ANGLE_UNITS
        control = th_units
        if self._rot[0] == "head":
            control = round(self._rot[1] / 360.0 * ANGLE_UNITS) % ANGLE_UNITS
        battery_dv = round(self.battery * 10)
        return Sip(
            moving=self.moving(),
            x=round(x),
            y=round(y),
            th=th_units,
            left_vel=round(self._v - half),
            right_vel=round(self._v + half),
            battery_dv=battery_dv,
            stall_bumpers=self.actuator.faults().word(),
            control=control,
            flags=flags,
            extension=SipExtension(battery_dv=battery_dv, rot_vel=round(self._w * 10)),
        )


# -- on a pseudo-terminal ----------------------------------------------------------------------


def serve_arcos(
    sim_or_actuator: SimRobot | DriveActuator,
    link: DeviceLine | None = None,
    aux1: ByteDevice | None = None,
    *,
    clock: Clock = SYSTEM_CLOCK,
    **options: object,
) -> LineServer:
    """Start an emulated ARCOS base on ``link`` (a new pseudo-terminal if None) driving a
    ``SimRobot`` (through ``SimActuator``) or any ``DriveActuator``; ``aux1`` is the device on
    the robot's AUX1 port; ``clock`` times the SIP cycle and the watchdog; ``options`` go to
    ``ArcosEmulator`` (name, sip_period, watchdog...).
    """
    actuator: DriveActuator
    if hasattr(sim_or_actuator, "set_velocity"):
        actuator = sim_or_actuator  # type: ignore[assignment]
    else:
        actuator = SimActuator(sim_or_actuator)  # type: ignore[arg-type]
    emulator = ArcosEmulator(actuator, aux1, **options)  # type: ignore[arg-type]
    line = link if link is not None else PtyLink()
    stop_wheels = lambda: emulator.actuator.set_velocity(0.0, 0.0)  # noqa: E731
    # a fixed 4 ms round: the firmware's SIP cycle and motion control tick on their own
    return LineServer(emulator, line, clock, name="arcos-emulator", max_wait=0.004,
                      read_size=512, on_stop=stop_wheels)  # fmt: skip
